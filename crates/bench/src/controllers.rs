//! Controllers by name, as the command line names them.

use rlnav_sim::{Controller, GreedyGoal, StraightAhead};

/// The controller names [`by_name`] knows.
pub const CONTROLLER_NAMES: &[&str] = &["greedy", "straight"];

/// An unknown controller name.
#[derive(Debug, thiserror::Error)]
#[error("unknown controller `{0}`: expected one of {names}", names = CONTROLLER_NAMES.join(", "))]
pub struct UnknownController(pub String);

/// A controller by name: `greedy` (turn towards the goal and drive, blind) or `straight`.
pub fn by_name(name: &str) -> Result<Box<dyn Controller>, UnknownController> {
    match name {
        "greedy" => Ok(Box::new(GreedyGoal::default())),
        "straight" => Ok(Box::new(StraightAhead { speed: 0.3 })),
        other => Err(UnknownController(other.to_string())),
    }
}

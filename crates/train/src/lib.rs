//! `rlnav-train`: PPO for navigation policies: rollouts, GAE, the update, curriculum,
//! evaluation, checkpoints, training logs, and the trained policy as an ONNX file.

pub mod config;
pub mod eval;
pub mod export;
pub mod fast;
pub mod gae;
pub mod plots;
pub mod ppo;
pub mod rollout;
pub mod run;
pub mod teacher;
pub mod tensorboard;

pub use config::{RunConfig, load_run_config};
pub use run::{EpochReport, Summary, TrainError, TrainOptions, train};

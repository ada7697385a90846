//! `rlnav-bench`: running any [`Controller`](rlnav_sim::Controller) through episodes and
//! showing what happened.
//!
//! - [`controllers`]: controllers by name (`greedy`, `straight`);
//! - [`episode`]: one episode run and recorded frame by frame;
//! - [`render`]: pictures of a scene or an episode (PNG, SVG) and animations (GIF).

pub mod controllers;
pub mod episode;
pub mod render;

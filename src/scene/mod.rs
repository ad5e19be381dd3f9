//! Cameras and scripted camera paths.

pub mod camera;
pub mod scenario;

pub use camera::{Camera, ViewOffset};
pub use scenario::Scenario;

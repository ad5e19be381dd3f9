//! Cameras and scripted camera paths.

pub mod camera;
pub mod earth;
pub mod scenario;

pub use camera::{Camera, ViewOffset};
pub use earth::Earth;
pub use scenario::Scenario;

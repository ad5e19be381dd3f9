//! The view (camera and viewport) one view slot of a frame is drawn for.

use crate::scene::Camera;

/// The view a frame is rendered for.
#[derive(Clone, Copy, Debug)]
pub struct ViewState {
    pub camera: Camera,
    /// Where LOD distances are measured from (the camera's position unless a test separates
    /// them).
    pub lod_viewer: glam::DVec3,
    pub width: u32,
    pub height: u32,
    /// Terrain height under the LOD viewer as the clipmap samples it this frame (metres), when
    /// heights come through one: methods then need no level-0 read (possibly from disk) on the
    /// render thread. While nodes stream it comes from the best resident ancestor.
    pub ground_m: Option<f64>,
}

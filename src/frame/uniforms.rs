//! The per-view frame uniforms (`Frame` in `shaders/include/terrain_common.wgsl`).

use super::TerrainInfo;
use crate::scene::Camera;

/// `Frame` in `terrain_common.wgsl`, byte for byte (std140: every member 16-byte aligned).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FrameUniforms {
    pub view_proj: [f32; 16],
    pub camera_cell: [i32; 4],
    pub camera_offset: [f32; 4],
    pub sun_dir: [f32; 4],
    pub data_size: [u32; 4],
}

impl FrameUniforms {
    /// Splits the camera position into an integer sample cell and a small metric offset, so the
    /// shader works with camera-relative coordinates at full f32 precision anywhere.
    pub fn new(camera: &Camera, aspect: f64, data: &TerrainInfo, sun_dir: [f32; 3]) -> Self {
        let spacing = data.spacing;
        let cell_x = (camera.position.x / spacing).floor();
        let cell_y = (camera.position.y / spacing).floor();
        let view_proj = camera.projection(aspect) * camera.view_rotation();
        FrameUniforms {
            view_proj: view_proj.to_cols_array(),
            camera_cell: [cell_x as i32, cell_y as i32, 0, 0],
            camera_offset: [
                (camera.position.x - cell_x * spacing) as f32,
                (camera.position.y - cell_y * spacing) as f32,
                camera.position.z as f32,
                spacing as f32,
            ],
            sun_dir: [sun_dir[0], sun_dir[1], sun_dir[2], 0.0],
            data_size: [data.width, data.height, 0, 0],
        }
    }
}

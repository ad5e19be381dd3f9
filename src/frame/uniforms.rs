//! The per-view frame uniforms (`Frame` in `shaders/include/terrain_common.wgsl`).

use super::TerrainInfo;
use crate::scene::Camera;

/// The light of a scene: the sun, and the sky that distant terrain fades into.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    /// Unit vector towards the sun.
    pub sun_dir: [f32; 3],
    /// Linear RGB of the sky (the clear colour and the haze colour).
    pub sky: [f32; 3],
    /// View depth over which terrain fades to `1 - 1/e` haze (aerial perspective), metres;
    /// 0: no haze.
    pub haze_distance_m: f32,
}

/// `Frame` in `terrain_common.wgsl`, byte for byte (std140: every member 16-byte aligned).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FrameUniforms {
    pub view_proj: [f32; 16],
    pub camera_cell: [i32; 4],
    pub camera_offset: [f32; 4],
    pub sun_dir: [f32; 4],
    pub data_size: [u32; 4],
    /// rgb: the haze colour (linear); w: 1 / haze distance in metres (0: no haze).
    pub haze: [f32; 4],
    /// The geolocation lattice (src/geo/lattice.rs): x samples per node (0: no lattice, the
    /// flat world), y/z nodes per row/column, w the f32 bits of its curve radius (culling).
    pub lattice: [u32; 4],
    /// The camera's world position split into f32 `hi` and `lo` parts (xyz).
    pub camera_hi: [f32; 4],
    pub camera_lo: [f32; 4],
}

impl FrameUniforms {
    /// Splits the camera position into an integer sample cell and a small metric offset, so the
    /// shader works with camera-relative coordinates at full f32 precision anywhere.
    pub fn new(camera: &Camera, aspect: f64, data: &TerrainInfo, light: &Lighting) -> Self {
        let spacing = data.spacing;
        let cell_x = (camera.position.x / spacing).floor();
        let cell_y = (camera.position.y / spacing).floor();
        let view_proj = camera.projection(aspect) * camera.view_rotation();
        let (hi, lo) = crate::geo::lattice::split(camera.position);
        let lattice = data.lattice.unwrap_or([0; 4]);
        FrameUniforms {
            view_proj: view_proj.to_cols_array(),
            camera_cell: [cell_x as i32, cell_y as i32, 0, 0],
            camera_offset: [
                (camera.position.x - cell_x * spacing) as f32,
                (camera.position.y - cell_y * spacing) as f32,
                camera.position.z as f32,
                spacing as f32,
            ],
            sun_dir: [light.sun_dir[0], light.sun_dir[1], light.sun_dir[2], 0.0],
            data_size: [data.width, data.height, 0, 0],
            haze: [
                light.sky[0],
                light.sky[1],
                light.sky[2],
                if light.haze_distance_m > 0.0 {
                    1.0 / light.haze_distance_m
                } else {
                    0.0
                },
            ],
            lattice,
            camera_hi: [hi[0], hi[1], hi[2], 0.0],
            camera_lo: [lo[0], lo[1], lo[2], 0.0],
        }
    }
}

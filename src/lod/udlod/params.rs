//! The per-frame inputs of UDLOD's selection, exactly as the GPU gets them: the frustum, the
//! camera and LOD viewer relative to the grid, the split field and the switches. Read by the
//! selection ([`super::select`]) and the morph ([`super::morph`]) alike.

use std::sync::Arc;

use glam::DVec3;

use super::field::{FieldKey, SplitField};
use super::levels::Levels;
use super::settings::UdlodSettings;
use crate::dataset::Heightmap;
use crate::geo::{EarthCull, Lattice};
use crate::scene::Camera;

/// Frustum planes in camera-relative world space (metres), `(normal, offset)` with
/// `dot(normal, p) + offset >= 0` inside: left, right, bottom, top, near, far.
pub fn frustum_planes(camera: &Camera, aspect: f64) -> [[f32; 4]; 6] {
    let (right, up, forward) = camera.basis();
    let tan_y = (camera.vfov_deg.to_radians() / 2.0).tan();
    let tan_x = tan_y * aspect;
    let side = |edge: DVec3, axis: DVec3| -> [f32; 4] {
        // Plane through the origin containing `axis` and the edge direction; normal inwards.
        let n = edge.cross(axis).normalize();
        let n = if n.dot(forward) < 0.0 { -n } else { n };
        [n.x as f32, n.y as f32, n.z as f32, 0.0]
    };
    [
        side(forward - right * tan_x, up),
        side(forward + right * tan_x, up),
        side(forward - up * tan_y, right),
        side(forward + up * tan_y, right),
        {
            let f = forward.as_vec3();
            [f.x, f.y, f.z, -(camera.near as f32)]
        },
        {
            let f = -forward.as_vec3();
            [f.x, f.y, f.z, camera.far as f32]
        },
    ]
}

/// Per-frame inputs of the selection, exactly as the GPU gets them.
#[derive(Clone, Debug)]
pub struct SelectionParams {
    pub camera_cell: [i32; 2],
    /// Camera position inside its cell (metres) and its height.
    pub camera_offset: [f32; 2],
    pub camera_z: f32,
    /// The LOD viewer (whose distances choose levels and morphs; normally the camera)
    /// relative to the camera in x and y, and `z`: the reference height (terrain under the
    /// LOD viewer) minus the LOD viewer's height.
    pub viewer: [f32; 3],
    pub spacing: f32,
    /// The LOD metric's stretch of the grid frame per axis ([`Levels::stretch`]).
    pub stretch: [f32; 2],
    /// Per-tile split distances (split table and field as uploaded).
    pub field: Arc<SplitField>,
    pub frustum: [[f32; 4]; 6],
    pub cull: bool,
    /// With `cull`: quadrants of drawn tiles outside the frustum are not drawn
    /// ([`super::select::quadrants_culled`]).
    pub cull_quadrants: bool,
    /// On the earth: the lattice and the camera's world position, for the curved boxes
    /// (None: the flat world's boxes).
    pub earth: Option<EarthCull>,
    /// Fraction of each level's range over which vertices morph.
    pub morph_range: f32,
    /// Vertex morphing on (off: every morph factor is 0).
    pub morph: bool,
}

impl SelectionParams {
    /// The inputs for `camera` (frustum, camera-relative coordinates) with levels and morphs
    /// chosen for `lod_viewer` (the camera's position except in tests that separate the two).
    pub fn new(
        levels: &Levels,
        data: &Heightmap,
        settings: &UdlodSettings,
        camera: &Camera,
        lod_viewer: DVec3,
        width: u32,
        height: u32,
    ) -> Self {
        let z_ref = data.height_at(lod_viewer.x, lod_viewer.y);
        let key = FieldKey::new(settings, camera.focal_px(height));
        let field = Arc::new(SplitField::new(levels, key));
        Self::with_reference(
            levels, field, z_ref, settings, camera, lod_viewer, width, height,
        )
    }

    /// [`SelectionParams::new`] with the split field (built for this camera's focal length
    /// and `settings`) and the reference height `z_ref` (terrain under the LOD viewer, metres)
    /// given.
    #[allow(clippy::too_many_arguments)]
    pub fn with_reference(
        levels: &Levels,
        field: Arc<SplitField>,
        z_ref: f64,
        settings: &UdlodSettings,
        camera: &Camera,
        lod_viewer: DVec3,
        width: u32,
        height: u32,
    ) -> Self {
        let s = levels.spacing;
        let (cx, cy) = (
            (camera.position.x / s).floor(),
            (camera.position.y / s).floor(),
        );
        SelectionParams {
            camera_cell: [cx as i32, cy as i32],
            camera_offset: [
                (camera.position.x - cx * s) as f32,
                (camera.position.y - cy * s) as f32,
            ],
            camera_z: camera.position.z as f32,
            viewer: [
                (lod_viewer.x - camera.position.x) as f32,
                (lod_viewer.y - camera.position.y) as f32,
                (z_ref - lod_viewer.z) as f32,
            ],
            spacing: s as f32,
            stretch: levels.stretch(),
            field,
            frustum: frustum_planes(camera, width as f64 / height as f64),
            cull: settings.cull,
            cull_quadrants: settings.cull_quadrants,
            earth: None,
            morph_range: settings.morph_range as f32,
            morph: settings.morph,
        }
    }

    /// These inputs on the earth: tiles are culled with the curved boxes of `lattice`
    /// (`camera`: the camera's world position, as the frame uniforms carry it). On a native
    /// non-square grid the per-axis stretch is also lowered to the lattice's spacing at the
    /// LOD viewer where that is smaller ([`Lattice::stretch_at`]; the GPU gets the lowered
    /// one). The split field keeps the tile diagonals of `levels`' stretch: a smaller metric
    /// only shortens every distance the split field's reach term bounds. Square grids keep `[1, 1]`.
    pub fn on_earth(mut self, levels: &Levels, lattice: Arc<Lattice>, camera: DVec3) -> Self {
        self.stretch = stretch_at_viewer(levels, &lattice, self.stretch, camera, self.viewer);
        self.earth = Some(EarthCull::new(lattice, camera));
        self
    }

    /// Camera-relative metres of a sample position (integer cell, as the shaders compute it).
    pub fn relative(&self, sample: [i32; 2]) -> [f32; 2] {
        [
            (sample[0] - self.camera_cell[0]) as f32 * self.spacing - self.camera_offset[0],
            (sample[1] - self.camera_cell[1]) as f32 * self.spacing - self.camera_offset[1],
        ]
    }

    /// LOD-viewer-relative metres of a sample position (`viewer_xy` in the shaders).
    pub fn from_viewer(&self, sample: [i32; 2]) -> [f32; 2] {
        let r = self.relative(sample);
        [r[0] - self.viewer[0], r[1] - self.viewer[1]]
    }
}

/// `stretch` (f32, as the GPU gets it) lowered to `lattice`'s spacing at the LOD viewer
/// ([`Lattice::stretch_at`]): the viewer at `viewer` (x, y) from the camera's world position
/// `camera`, as [`SelectionParams::viewer`] holds it. UDLOD's and chunked LOD's per-frame metric.
pub fn stretch_at_viewer(
    levels: &Levels,
    lattice: &Lattice,
    stretch: [f32; 2],
    camera: DVec3,
    viewer: [f32; 3],
) -> [f32; 2] {
    let v = camera + DVec3::new(viewer[0] as f64, viewer[1] as f64, 0.0);
    let s = glam::DVec2::new(v.x, v.y) / levels.spacing;
    let lowered = lattice.stretch_at(
        stretch.map(|k| k as f64),
        levels.spacing,
        s,
        levels.lowest() as f64,
    );
    [0, 1].map(|k| stretch[k].min(lowered[k] as f32))
}

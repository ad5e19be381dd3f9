//! The host side of `shaders/eval_metrics.wgsl`'s structs, byte for byte (naga reflection
//! proves the layouts equal: `tests/shader_interface.rs`).

use glam::DVec3;

use crate::geo::Lattice;
use crate::geo::lattice::split;
use crate::gpu_constants::EVAL_MAX_VIEWS;
use crate::scene::Camera;

const _: () = assert!(EVAL_MAX_VIEWS as usize == crate::render::MAX_VIEWS);

/// `EvalView`: one camera of the frame, camera-relative like the renderer's uniforms (an
/// integer sample cell plus a small metric offset; the height as f32 high and low parts). On
/// the earth the cell, offset and height are the camera's place in the grid's frame (the
/// sample under it and its height above the lattice surface, [`Lattice::sample_at`]: where
/// the shader's lattice inverse starts) and `cam_hi` / `cam_lo` its split world position.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct EvalView {
    pub right: [f32; 4],
    pub up: [f32; 4],
    pub forward: [f32; 4],
    pub cell: [i32; 4],
    pub offset: [f32; 4],
    pub cam_hi: [f32; 4],
    pub cam_lo: [f32; 4],
}

impl EvalView {
    /// `camera` drawn into columns `(first, count)` of a frame `height` pixels tall, over data
    /// of `spacing` metres, placed by `lattice` on the earth (None: the flat world).
    pub fn new(
        camera: &Camera,
        (first, count): (u32, u32),
        height: u32,
        spacing: f64,
        lattice: Option<&Lattice>,
    ) -> Self {
        let (right, up, forward) = camera.basis();
        let p = match lattice {
            None => camera.position,
            Some(l) => {
                let (s, h) = l.sample_at(camera.position);
                DVec3::new(s.x * spacing, s.y * spacing, h)
            }
        };
        let cell = ((p.x / spacing).floor(), (p.y / spacing).floor());
        let z_hi = p.z as f32;
        let z_lo = (p.z - z_hi as f64) as f32;
        let v4 = |v: DVec3, w: f64| [v.x as f32, v.y as f32, v.z as f32, w as f32];
        let (hi, lo) = split(camera.position);
        EvalView {
            right: v4(right, camera.focal_px(height)),
            up: v4(up, camera.near),
            forward: v4(forward, camera.far),
            cell: [cell.0 as i32, cell.1 as i32, first as i32, count as i32],
            offset: [
                (p.x - cell.0 * spacing) as f32,
                (p.y - cell.1 * spacing) as f32,
                z_hi,
                z_lo,
            ],
            cam_hi: [hi[0], hi[1], hi[2], 0.0],
            cam_lo: [lo[0], lo[1], lo[2], 0.0],
        }
    }
}

/// `EvalFrame`: the uniforms of one analysed frame.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct EvalFrame {
    pub views: [EvalView; EVAL_MAX_VIEWS as usize],
    /// Frame width, height (px), views, 1 when popping has a previous frame.
    pub size: [u32; 4],
    /// Level-0 samples per side, reference tiles per side.
    pub data: [u32; 4],
    /// Sample spacing (m).
    pub params: [f32; 4],
    /// Tracked points, first seed written this frame, seeds written this frame, pixel
    /// workgroups.
    pub points: [u32; 4],
    /// Seed grid columns and rows, pixel workgroups per row.
    pub grid: [u32; 4],
    /// The geolocation lattice's samples per node (0: flat world), nodes per row and column.
    pub lattice: [u32; 4],
}

/// `Totals`: the sums the reducing workgroup writes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Totals {
    pub metres_sum: f32,
    pub pixels_sum: f32,
    pub metres_max: f32,
    pub pixels_max: f32,
    pub ssim_sum: f32,
    /// The silhouette's largest drop in pixels (`metrics::Holes::silhouette_px`; a whole
    /// number, a float so the reduction's maxima stay one vector).
    pub silhouette_px: f32,
    pub error_count: u32,
    pub holes: u32,
    pub sq_lo: u32,
    pub sq_hi: u32,
    pub ssim_windows: u32,
    /// The holes with the method's terrain above them in their column (`metrics::Holes`).
    pub cracks: u32,
    pub missing: u32,
    pub pad1: u32,
    pub pad2: u32,
    pub pad3: u32,
}

/// `Seed`: a tracked world point (sample cell + fraction) and the exact height there.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Seed {
    pub cell: [i32; 2],
    pub valid: u32,
    pub pad0: u32,
    pub frac: [f32; 2],
    pub z: f32,
    pub pad1: f32,
}

/// Bytes of one `Partial` (three vec4s).
pub const PARTIAL_BYTES: u64 = 48;

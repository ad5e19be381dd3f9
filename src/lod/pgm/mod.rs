//! Persistent grid mapping (PGM): a fixed grid of `cols` x `rows` vertices in the screen space
//! of an **auxiliary camera** is projected onto a horizontal reference plane every frame; each
//! vertex takes the height of the data at its projected point, read with `textureSampleLevel`
//! from a mip chain of the heights at the level of the longest projected cell edge in texels.
//!
//! Cheap (constant triangle count, no preprocessing beyond the mips, no per-frame CPU work but a
//! few vectors) and watertight by construction (one grid, every vertex a pure function of its
//! grid index), but the vertices slide over the terrain when the camera moves: it **swims**, and
//! it has no error bound. It is the baseline the evaluator shows failing.
//!
//! Auxiliary camera (Improved-PGM style, see `docs/pgm.md`): the main camera's position and
//! heading, no roll; height above the reference plane (the terrain under the camera) clamped to
//! at least `min_height_m`; field of view at least `fov_deg` (>= 90) both ways and
//! widened where the main frustum needs more; pitch at most `-fov_deg / 2`, so the top row
//! of the grid is at or below the horizon and every grid ray meets the plane (rays at the
//! horizon are cut at `max_distance`).

pub mod earth;
#[cfg(feature = "test-support")]
pub mod probe;
pub mod settings;

use std::sync::Arc;

use ash::vk;
use glam::{DVec2, DVec3};
use gpu_allocator::MemoryLocation;

use super::{LodMethod, MethodContext};
use crate::dataset::Heightmap;
use crate::driver::Gpu;
use crate::driver::barrier::{Barriers, MemoryAccess};
use crate::driver::descriptors::{Binding, DescriptorSets, Resource, stages};
use crate::driver::memory::{Buffer, Image};
use crate::driver::pipeline::{Pipeline, TerrainPipelineDesc, compute_pipeline, terrain_pipeline};
use crate::driver::sampler::{Sampler, SamplerInfo};
use crate::error::{Error, Result};
use crate::frame::ViewState;
use crate::gpu_constants::PGM_EARTH_TILE;
use crate::scene::Camera;
use crate::slots::ViewSlot;
use earth::{AuxEarth, Sphere};
use settings::PgmSettings;

/// One grid vertex placed on the earth (`EarthVertex` in `shaders/include/pgm_grid.wgsl`,
/// written by `shaders/pgm_earth.wgsl`; `tests/shader_interface.rs` proves the layouts
/// equal). Only its size is used on the host.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct EarthVertex {
    pub cell: [i32; 2],
    pub frac: [f32; 2],
    /// Mip level of the heights.
    pub level: f32,
    pub _pad: f32,
}

/// Per-frame uniforms of set 1 (`Pgm` in `shaders/pgm.wgsl`; `tests/shader_interface.rs`
/// proves the layouts equal).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PgmUniforms {
    /// xyz: world direction (camera-relative, unnormalised) of grid vertex (0, 0), the bottom
    /// left of the auxiliary view; w: auxiliary camera height above the reference plane (m).
    pub dir0: [f32; 4],
    /// xyz: direction change from the first to the last column; w: largest ground distance (m).
    pub dcol: [f32; 4],
    /// xyz: direction change from the first to the last row; w: unused.
    pub drow: [f32; 4],
    /// x: columns, y: rows, z: rows per instanced band, w: mip levels of the height texture.
    pub grid: [u32; 4],
    /// On the earth (docs/pgm.md, "On the earth"; all zero on the flat world): xyz: the up
    /// vector at the camera's sample (world axes; the directions above are world axes too);
    /// w: radius of the reference sphere (m), 0 on the flat world.
    pub earth: [f32; 4],
    /// xyz: columns per world metre at the camera (`AuxEarth::to_sample`); w: the reference
    /// height (m).
    pub to_col: [f32; 4],
    /// xyz: rows per world metre at the camera; w: sine of the sphere's horizon depression.
    pub to_row: [f32; 4],
    /// xy: the sample cell under the camera.
    pub cam_cell: [i32; 4],
    /// xy: the camera's sample position within that cell; z: the surface distance of the
    /// sphere's horizon (m); w: its depression angle (rad).
    pub cam_frac: [f32; 4],
}

/// The auxiliary camera of one frame: where the grid comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AuxCamera {
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    /// Height above the reference plane (m), at least `min_height_m`.
    pub height: f64,
    /// Image-plane extents (tangents) of the view: `[left, right]`, `[bottom, top]`.
    pub tan_x: [f64; 2],
    pub tan_y: [f64; 2],
    /// Ground distance at which rays at (or numerically above) the horizon are cut (m).
    pub max_distance: f64,
    /// On the earth: the local frame its angles are in, and the reference sphere (None: the
    /// flat world's reference plane, world axes).
    pub earth: Option<AuxEarth>,
}

/// Widest image-plane tangent of the auxiliary view (about 83 degrees off its axis): keeps
/// the grid finite when the main camera looks up or sideways past what a plane can show.
pub const PGM_MAX_TAN: f64 = 8.0;
/// Samples per main-frustum edge used to fit the auxiliary view.
const FIT_SAMPLES: usize = 16;
/// Relative margin added around the fitted main frustum, so terrain rising into the view at
/// its edges still has grid vertices under it.
const FIT_MARGIN: f64 = 0.05;

impl AuxCamera {
    /// The auxiliary camera for `camera` (aspect = width / height) over the reference plane at
    /// height `ground_z`; `data_far` is the farthest ground distance worth covering.
    pub fn new(
        camera: &Camera,
        aspect: f64,
        ground_z: f64,
        data_far: f64,
        s: &PgmSettings,
    ) -> AuxCamera {
        Self::fit(camera, aspect, ground_z, data_far, s, 0.0)
    }

    /// The auxiliary camera on the earth for `camera` (world axes) standing at `earth` (whose
    /// `reference_m` is the reference height): [`AuxCamera::new`] in the local frame at the
    /// camera's sample, over the reference sphere; `data_far` is the farthest surface
    /// distance worth covering. Main-frustum directions above the sphere's horizon are
    /// flattened onto the horizontal like those above it: terrain beyond the sphere's horizon
    /// that rises into view can lie anywhere out to the largest distance.
    pub fn on_earth(
        camera: &Camera,
        aspect: f64,
        earth: AuxEarth,
        data_far: f64,
        s: &PgmSettings,
    ) -> AuxCamera {
        let local = earth.local_camera(camera);
        let height = (local.position.z - earth.reference_m).max(s.min_height_m);
        let sphere = Sphere {
            radius: earth.sphere_radius(),
            height,
        };
        let dip = sphere.horizon_depression().sin();
        let mut aux = Self::fit(&local, aspect, earth.reference_m, data_far, s, dip);
        aux.earth = Some(earth);
        aux
    }

    /// [`AuxCamera::new`], flattening main-frustum directions whose depression sine is below
    /// `dip` (0: those above the horizontal) onto the horizontal.
    fn fit(
        camera: &Camera,
        aspect: f64,
        ground_z: f64,
        data_far: f64,
        s: &PgmSettings,
        dip: f64,
    ) -> AuxCamera {
        let half = s.fov_deg / 2.0;
        let pitch = camera.pitch_deg.min(-half);
        let aux = Camera {
            position: camera.position,
            yaw_deg: camera.yaw_deg,
            pitch_deg: pitch,
            roll_deg: 0.0,
            ..*camera
        };
        let (ar, au, af) = aux.basis();
        let t = half.to_radians().tan();
        let (mut tan_x, mut tan_y) = ([-t, t], [-t, t]);
        // Fit the main frustum's border: directions above the horizon are flattened onto it
        // (terrain seen there lies on the plane towards the horizon, same azimuth).
        let (mr, mu, mf) = camera.basis();
        let ty = (camera.vfov_deg.to_radians() / 2.0).tan();
        let tx = ty * aspect;
        let mut fitted: Option<([f64; 2], [f64; 2])> = None;
        for i in 0..4 * FIT_SAMPLES {
            let s = (i % FIT_SAMPLES) as f64 / FIT_SAMPLES as f64 * 2.0 - 1.0;
            let (sx, sy) = match i / FIT_SAMPLES {
                0 => (s, -1.0),
                1 => (1.0, s),
                2 => (-s, 1.0),
                _ => (-1.0, -s),
            };
            let mut d = mf + mr * (sx * tx) + mu * (sy * ty);
            if d.z > 0.0 || (dip > 0.0 && d.z > -dip * d.length()) {
                d.z = 0.0;
            }
            let Some(d) = d.try_normalize() else { continue };
            let z = d.dot(af);
            if z < 1e-3 {
                continue; // behind the auxiliary camera: not representable, see docs/pgm.md
            }
            let (x, y) = (d.dot(ar) / z, d.dot(au) / z);
            let f = fitted.get_or_insert(([x, x], [y, y]));
            f.0 = [f.0[0].min(x), f.0[1].max(x)];
            f.1 = [f.1[0].min(y), f.1[1].max(y)];
        }
        if let Some((fx, fy)) = fitted {
            let (mx, my) = (FIT_MARGIN * (fx[1] - fx[0]), FIT_MARGIN * (fy[1] - fy[0]));
            tan_x = [tan_x[0].min(fx[0] - mx), tan_x[1].max(fx[1] + mx)];
            tan_y = [tan_y[0].min(fy[0] - my), tan_y[1].max(fy[1] + my)];
        }
        // Never above the horizon (tan = tan(-pitch)), never wider than PGM_MAX_TAN.
        let horizon = if pitch > -89.999 {
            (-pitch).to_radians().tan()
        } else {
            f64::INFINITY
        };
        let cap = PGM_MAX_TAN;
        tan_x = [tan_x[0].max(-cap), tan_x[1].min(cap)];
        tan_y = [tan_y[0].max(-cap), tan_y[1].min(cap).min(horizon)];
        let height = (camera.position.z - ground_z).max(s.min_height_m);
        AuxCamera {
            yaw_deg: camera.yaw_deg,
            pitch_deg: pitch,
            height,
            tan_x,
            tan_y,
            // The far plane cuts at view depth `far`: its corners are farther than that.
            max_distance: data_far
                .min(camera.far * (1.0 + tx * tx + ty * ty).sqrt())
                .max(1.0),
            earth: None,
        }
    }

    /// The reference sphere on the earth (None: the flat world).
    pub fn sphere(&self) -> Option<Sphere> {
        self.earth.map(|e| Sphere {
            radius: e.sphere_radius(),
            height: self.height,
        })
    }

    /// Vertical field of view in degrees (for reports and tests).
    pub fn vfov_deg(&self) -> f64 {
        (self.tan_y[1].atan() - self.tan_y[0].atan()).to_degrees()
    }

    /// Horizontal field of view in degrees.
    pub fn hfov_deg(&self) -> f64 {
        (self.tan_x[1].atan() - self.tan_x[0].atan()).to_degrees()
    }

    /// Each grid row's position in `[0, 1]` from the bottom of the view (`tan_y[0]`) to its top
    /// (`tan_y[1]`): half the rows uniform in the image plane (as Houska's plain grid), half
    /// uniform in the logarithm of the ground distance along the heading (between the camera's
    /// height and `max_distance`), so the far field keeps a constant relative row spacing
    /// instead of ending in one band of rows kilometres apart (Houska's row warping; issue 16:
    /// a grid uniform in the image plane put everything beyond ~10 km into one row when the
    /// camera was 10 m above the ground). Row `r` sits where the sum of both normalised
    /// coordinates is `2 r / (rows - 1)`.
    pub fn row_fractions(&self, rows: u32, warp: bool) -> Vec<f32> {
        let last = rows.max(2) - 1;
        if !warp {
            return (0..=last).map(|r| r as f32 / last as f32).collect();
        }
        let cam = Camera {
            yaw_deg: self.yaw_deg,
            pitch_deg: self.pitch_deg,
            roll_deg: 0.0,
            ..Camera::default()
        };
        let (_, up, fwd) = cam.basis();
        let heading = DVec3::new(fwd.x, fwd.y, 0.0)
            .try_normalize()
            .unwrap_or_else(|| DVec3::new(up.x, up.y, 0.0).normalize_or_zero());
        let (y0, y1) = (self.tan_y[0], self.tan_y[1]);
        let near = self.height.min(self.max_distance);
        let sphere = self.sphere();
        let log_dist = |y: f64| {
            let d = fwd + up * y;
            let dist = if let Some(sphere) = sphere {
                sphere.distance(-d.z / d.length(), self.max_distance)
            } else if d.z < 0.0 {
                self.height * d.dot(heading) / -d.z
            } else {
                self.max_distance
            };
            dist.clamp(near, self.max_distance).ln()
        };
        let (l0, l1) = (log_dist(y0), log_dist(y1));
        let span = y1 - y0;
        let coord = |y: f64| {
            let u = (y - y0) / span;
            if l1 - l0 > 1e-6 {
                u + (log_dist(y) - l0) / (l1 - l0)
            } else {
                2.0 * u
            }
        };
        (0..=last)
            .map(|r| {
                let target = 2.0 * r as f64 / last as f64;
                let (mut lo, mut hi) = (y0, y1);
                for _ in 0..48 {
                    let mid = 0.5 * (lo + hi);
                    if coord(mid) < target {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                match r {
                    0 => 0.0,
                    r if r == last => 1.0,
                    _ => ((0.5 * (lo + hi) - y0) / span) as f32,
                }
            })
            .collect()
    }

    /// The shader's view of this camera: directions of the grid's corners and extents.
    pub fn uniforms(&self, grid: [u32; 2], band: u32, mips: u32) -> PgmUniforms {
        let cam = Camera {
            yaw_deg: self.yaw_deg,
            pitch_deg: self.pitch_deg,
            roll_deg: 0.0,
            ..Camera::default()
        };
        let (r, u, f) = cam.basis();
        // On the earth the angles are the local frame's: directions turn into world axes.
        let world = |v: DVec3| self.earth.map_or(v, |e| e.axes * v);
        let dir0 = world(f + r * self.tan_x[0] + u * self.tan_y[0]);
        let dcol = world(r * (self.tan_x[1] - self.tan_x[0]));
        let drow = world(u * (self.tan_y[1] - self.tan_y[0]));
        let v4 = |v: DVec3, w: f64| [v.x as f32, v.y as f32, v.z as f32, w as f32];
        let mut out = PgmUniforms {
            dir0: v4(dir0, self.height),
            dcol: v4(dcol, self.max_distance),
            drow: v4(drow, 0.0),
            grid: [grid[0], grid[1], band, mips],
            ..Default::default()
        };
        if let (Some(e), Some(sphere)) = (self.earth, self.sphere()) {
            let [sin_h, d_h, e_h] = sphere.gpu_terms();
            let cell = e.sample.floor();
            let frac = e.sample - cell;
            out.earth = v4(e.axes.z_axis, sphere.radius);
            out.to_col = v4(e.to_sample[0], e.reference_m);
            out.to_row = v4(e.to_sample[1], f64::from(sin_h));
            out.cam_cell = [cell.x as i32, cell.y as i32, 0, 0];
            out.cam_frac = [frac.x as f32, frac.y as f32, d_h, e_h];
        }
        out
    }
}

/// The height mip chain: level 0 is the data, level `k + 1` the 2x2 box average of level `k`
/// (`max(1, size >> 1)` per side; an odd last row/column is averaged into its neighbour's
/// texel only through the box of the texel that contains it, i.e. it is dropped, as the GPU's
/// own mip sizes do). Returns the levels' texels (f32, row 0 = south).
pub fn height_mips(data: &Heightmap) -> Vec<Vec<f32>> {
    let mut levels = vec![data.heights.clone()];
    let (mut w, mut h) = (data.width as usize, data.height as usize);
    while w > 1 || h > 1 {
        let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
        let prev = levels.last().expect("level 0 exists");
        let mut next = Vec::with_capacity(nw * nh);
        for j in 0..nh {
            for i in 0..nw {
                let (mut sum, mut n) = (0.0f64, 0u32);
                for y in (2 * j)..(2 * j + 2).min(h) {
                    for x in (2 * i)..(2 * i + 2).min(w) {
                        sum += prev[y * w + x] as f64;
                        n += 1;
                    }
                }
                next.push((sum / n as f64) as f32);
            }
        }
        levels.push(next);
        (w, h) = (nw, nh);
    }
    levels
}

/// Minimum height per block of `MIN_BLOCK`^2 samples: the reference plane is put at the lowest
/// terrain near the camera, so nearby terrain lies above it and stays inside the grid's
/// footprint (terrain below the plane would be projected outward, past the view's edges).
pub struct BlockMin {
    cols: u32,
    rows: u32,
    min: Vec<f32>,
    block_m: f64,
}

/// Samples per side of a [`BlockMin`] block.
pub const MIN_BLOCK: u32 = 8;
/// Blocks searched at most in each direction from the camera's block.
const MIN_SEARCH_BLOCKS: i64 = 32;

impl BlockMin {
    pub fn new(data: &Heightmap) -> Self {
        let (cols, rows) = (
            data.width.div_ceil(MIN_BLOCK),
            data.height.div_ceil(MIN_BLOCK),
        );
        let mut min = vec![f32::INFINITY; (cols * rows) as usize];
        for y in 0..data.height {
            for x in 0..data.width {
                let b = ((y / MIN_BLOCK) * cols + x / MIN_BLOCK) as usize;
                min[b] = min[b].min(data.heights[(y * data.width + x) as usize]);
            }
        }
        BlockMin {
            cols,
            rows,
            min,
            block_m: MIN_BLOCK as f64 * data.spacing,
        }
    }

    /// Lowest height of the blocks within `radius` metres (a square) of `(x, y)`, searching at
    /// most `MIN_SEARCH_BLOCKS` blocks each way; `None` when the square misses the data.
    pub fn min_near(&self, x: f64, y: f64, radius: f64) -> Option<f64> {
        let reach = ((radius / self.block_m).ceil() as i64).clamp(1, MIN_SEARCH_BLOCKS);
        let (bx, by) = ((x / self.block_m).floor(), (y / self.block_m).floor());
        if !(bx.is_finite() && by.is_finite()) {
            return None;
        }
        let (bx, by) = (bx as i64, by as i64);
        let x0 = (bx - reach).max(0);
        let x1 = (bx + reach).min(self.cols as i64 - 1);
        let y0 = (by - reach).max(0);
        let y1 = (by + reach).min(self.rows as i64 - 1);
        let mut lo = f32::INFINITY;
        for j in y0..=y1 {
            for i in x0..=x1 {
                lo = lo.min(self.min[(j * self.cols as i64 + i) as usize]);
            }
        }
        lo.is_finite().then_some(lo as f64)
    }
}

/// Rows per instanced band so one band's vertices fit 16-bit indices.
pub fn band_rows(cols: u32, rows: u32) -> u32 {
    ((65536 / cols).saturating_sub(1)).clamp(1, rows - 1)
}

/// Counter-clockwise (seen from above) triangle list over `cols` x `band + 1` vertices.
pub fn band_indices(cols: u32, band: u32) -> Vec<u16> {
    let mut out = Vec::with_capacity(((cols - 1) * band * 6) as usize);
    for r in 0..band {
        for c in 0..cols - 1 {
            let (a, b, cc, d) = (
                r * cols + c,
                r * cols + c + 1,
                (r + 1) * cols + c,
                (r + 1) * cols + c + 1,
            );
            out.extend([a, b, cc, b, d, cc].map(|i| i as u16));
        }
    }
    out
}

/// Descriptor set 1 (`shaders/pgm.wgsl`; on the earth `shaders/pgm_earth.wgsl` too): the
/// uniforms, the height mip chain, its sampler, the row fractions, the grid vertices placed
/// on the earth.
pub const PGM_SET: &[Binding] = {
    use vk::DescriptorType as T;
    const V: vk::ShaderStageFlags = vk::ShaderStageFlags::VERTEX;
    const VC: vk::ShaderStageFlags = stages(V, vk::ShaderStageFlags::COMPUTE);
    &[
        Binding::new(0, T::UNIFORM_BUFFER, VC, "pgm"),
        Binding::new(1, T::SAMPLED_IMAGE, V, "height_mips"),
        Binding::new(2, T::SAMPLER, V, "mip_sampler"),
        Binding::new(3, T::STORAGE_BUFFER, VC, "row_t"),
        Binding::new(4, T::STORAGE_BUFFER, VC, "earth_vertices"),
    ]
};

/// PGM filters its height mips linearly: a one-line error where `format` cannot be.
fn require_linear_filter(gpu: &Gpu, format: vk::Format) -> Result<()> {
    let props = unsafe {
        gpu.instance
            .raw
            .get_physical_device_format_properties(gpu.physical, format)
    };
    if !props
        .optimal_tiling_features
        .contains(vk::FormatFeatureFlags::SAMPLED_IMAGE_FILTER_LINEAR)
    {
        return Err(Error::invalid(
            "pgm",
            format!("the device cannot filter {format:?} textures linearly"),
        ));
    }
    Ok(())
}

/// The pipeline that draws the bands of the grid (`shaders/pgm.wgsl`), with set 0 and PGM's
/// set 1.
fn band_pipeline(
    gpu: &Arc<Gpu>,
    ctx: &MethodContext<'_>,
    sets: &DescriptorSets,
) -> Result<Pipeline> {
    terrain_pipeline(
        gpu,
        &ctx.formats,
        &TerrainPipelineDesc::triangles(
            crate::driver::shaders::PGM_SPV.variant(ctx.terrain.variant),
            &[ctx.terrain.descriptors.layout, sets.layout],
        ),
    )
}

/// The compute pass that places the grid vertices on the earth (`shaders/pgm_earth.wgsl`),
/// with set 0 and PGM's set 1.
fn earth_pass(gpu: &Arc<Gpu>, ctx: &MethodContext<'_>, sets: &DescriptorSets) -> Result<Pipeline> {
    compute_pipeline(
        gpu,
        crate::driver::shaders::PGM_EARTH_SPV.variant(ctx.terrain.variant),
        c"prepare_earth",
        &[ctx.terrain.descriptors.layout, sets.layout],
    )
}

/// One view slot's buffers of set 1.
struct SlotBuffers {
    uniforms: Buffer,
    row_t: Buffer,
    earth_vertices: Buffer,
}

impl SlotBuffers {
    fn new(gpu: &Arc<Gpu>, slot: usize, rows: u32, vertex_bytes: u64) -> Result<Self> {
        Ok(SlotBuffers {
            uniforms: Buffer::new(
                gpu,
                &format!("pgm uniforms {slot}"),
                size_of::<PgmUniforms>() as u64,
                vk::BufferUsageFlags::UNIFORM_BUFFER,
                MemoryLocation::CpuToGpu,
            )?,
            row_t: Buffer::new(
                gpu,
                &format!("pgm row fractions {slot}"),
                rows as u64 * 4,
                vk::BufferUsageFlags::STORAGE_BUFFER,
                MemoryLocation::CpuToGpu,
            )?,
            earth_vertices: Buffer::new(
                gpu,
                &format!("pgm earth vertices {slot}"),
                vertex_bytes,
                vk::BufferUsageFlags::STORAGE_BUFFER,
                MemoryLocation::GpuOnly,
            )?,
        })
    }
}

/// `data`'s heights and their mips ([`height_mips`]) as one texture, and its level count.
fn height_mip_texture(
    gpu: &Arc<Gpu>,
    data: &Heightmap,
    format: vk::Format,
) -> Result<(Image, u32)> {
    let levels = height_mips(data);
    let refs: Vec<&[u8]> = levels.iter().map(|l| bytemuck::cast_slice(l)).collect();
    let heights = Image::texture_with_mips(
        gpu,
        "pgm height mips",
        format,
        vk::Extent2D {
            width: data.width,
            height: data.height,
        },
        &refs,
    )?;
    Ok((heights, levels.len() as u32))
}

/// Every view slot's buffers of set 1, each slot's set written with them, `heights` and
/// `sampler`: the uniforms, row fractions and earth vertices, each a buffer per slot.
fn slot_buffers(
    gpu: &Arc<Gpu>,
    sets: &DescriptorSets,
    slots: usize,
    rows: u32,
    vertex_bytes: u64,
    heights: &Image,
    sampler: vk::Sampler,
) -> Result<(Vec<Buffer>, Vec<Buffer>, Vec<Buffer>)> {
    let mut uniforms = Vec::with_capacity(slots);
    let mut row_t = Vec::with_capacity(slots);
    let mut earth_vertices = Vec::with_capacity(slots);
    for i in 0..slots {
        let b = SlotBuffers::new(gpu, i, rows, vertex_bytes)?;
        sets.write(
            i,
            &[
                ("pgm", Resource::Buffer(b.uniforms.raw)),
                ("height_mips", Resource::Image(heights.view)),
                ("mip_sampler", Resource::Sampler(sampler)),
                ("row_t", Resource::Buffer(b.row_t.raw)),
                ("earth_vertices", Resource::Buffer(b.earth_vertices.raw)),
            ],
        )?;
        uniforms.push(b.uniforms);
        row_t.push(b.row_t);
        earth_vertices.push(b.earth_vertices);
    }
    Ok((uniforms, row_t, earth_vertices))
}

/// The index buffer of one band ([`band_indices`]: `band` rows of quads, `cols` vertices
/// wide), and its index count.
fn band_index_buffer(gpu: &Arc<Gpu>, cols: u32, band: u32) -> Result<(Buffer, u32)> {
    let grid = band_indices(cols, band);
    let index_bytes: &[u8] = bytemuck::cast_slice(&grid);
    let indices = Buffer::with_data(
        gpu,
        "pgm band indices",
        vk::BufferUsageFlags::INDEX_BUFFER,
        index_bytes,
    )?;
    Ok((indices, grid.len() as u32))
}

pub struct Pgm {
    gpu: Arc<Gpu>,
    settings: PgmSettings,
    pipeline: Pipeline,
    indices: Buffer,
    index_count: u32,
    instances: u32,
    band: u32,
    uniforms: Vec<Buffer>,
    /// Per slot: each row's fraction of the auxiliary view (`AuxCamera::row_fractions`).
    row_t: Vec<Buffer>,
    /// Per slot: the grid vertices placed on the earth (a placeholder on the flat world).
    _earth_vertices: Vec<Buffer>,
    /// On the earth: the pass that places them (`shaders/pgm_earth.wgsl`).
    earth_pass: Option<Pipeline>,
    sets: DescriptorSets,
    _heights: Image,
    mips: u32,
    /// Bilinear height under the camera (the reference plane) needs the data on the CPU.
    data: Arc<Heightmap>,
    block_min: BlockMin,
    /// The geolocation lattice on the earth (None: the flat world, or the flat projection
    /// asked for by `earth_projection = false`).
    lattice: Option<std::sync::Arc<crate::geo::Lattice>>,
    // Last: destroyed after everything that uses it.
    _sampler: Sampler,
}

impl Pgm {
    pub fn new(ctx: &MethodContext<'_>, settings: &PgmSettings) -> Result<Self> {
        let gpu = ctx.gpu;
        let settings = settings.clone();
        settings.validate()?;
        let format = vk::Format::R32_SFLOAT;
        require_linear_filter(gpu, format)?;
        let data = ctx.data.require_grid("method pgm")?.clone();
        let (heights, mips) = height_mip_texture(gpu, &data, format)?;
        // The height mips' sampler: trilinear, clamped at the edges, every level.
        let sampler = Sampler::new(gpu, SamplerInfo::trilinear_clamped())?;
        let sets = DescriptorSets::new(gpu, PGM_SET, ctx.slots)?;
        let [cols, rows] = settings.grid();
        let lattice = ctx.lattice.filter(|_| settings.earth_projection).cloned();
        let vertex_bytes = match lattice {
            Some(_) => (cols * rows) as u64 * size_of::<EarthVertex>() as u64,
            None => size_of::<EarthVertex>() as u64,
        };
        let (uniforms, row_t, earth_vertices) = slot_buffers(
            gpu,
            &sets,
            ctx.slots,
            rows,
            vertex_bytes,
            &heights,
            sampler.raw,
        )?;
        let band = band_rows(cols, rows);
        let (indices, index_count) = band_index_buffer(gpu, cols, band)?;
        let pipeline = band_pipeline(gpu, ctx, &sets)?;
        Ok(Pgm {
            gpu: gpu.clone(),
            pipeline,
            index_count,
            indices,
            instances: (rows - 1).div_ceil(band),
            band,
            uniforms,
            row_t,
            _earth_vertices: earth_vertices,
            earth_pass: match lattice {
                Some(_) => Some(earth_pass(gpu, ctx, &sets)?),
                None => None,
            },
            sets,
            _heights: heights,
            mips,
            block_min: BlockMin::new(&data),
            lattice,
            data,
            settings,
            _sampler: sampler,
        })
    }

    /// The auxiliary camera this method uses for `view`.
    pub fn aux_for(&self, view: &ViewState) -> AuxCamera {
        if let Some(lattice) = &self.lattice {
            return self.aux_on_earth(lattice, view);
        }
        let cam = &view.camera;
        let p = cam.position;
        let (ex, ey) = self.data.extent();
        // Farthest data corner from the camera, plus a sample: beyond it every vertex clamps.
        let far = [(0.0, 0.0), (ex, 0.0), (0.0, ey), (ex, ey)]
            .iter()
            .map(|&(x, y)| DVec3::new(x - p.x, y - p.y, 0.0).length())
            .fold(0.0, f64::max)
            + self.data.spacing;
        // Reference plane: the lowest terrain within a few camera heights (see BlockMin).
        let under = self.data.height_at(p.x, p.y);
        let radius = 4.0 * (p.z - under).max(0.0);
        let ground = self
            .block_min
            .min_near(p.x, p.y, radius)
            .map_or(under, |m| m.min(under));
        let aspect = view.width as f64 / view.height as f64;
        AuxCamera::new(cam, aspect, ground, far, &self.settings)
    }

    /// [`Pgm::aux_for`] on the earth: the reference height is found on the grid around the
    /// sample under the camera, the largest distance is the farthest data corner's (a chord,
    /// scaled to the reference sphere's radius, plus two samples).
    fn aux_on_earth(&self, lattice: &crate::geo::Lattice, view: &ViewState) -> AuxCamera {
        let cam = &view.camera;
        let mut earth = AuxEarth::at(lattice, cam.position);
        let spacing = self.data.spacing;
        let g = earth.sample * spacing;
        let under = self.data.height_at(g.x, g.y);
        let radius = 4.0 * (earth.height_m - under).max(0.0);
        earth.reference_m = self
            .block_min
            .min_near(g.x, g.y, radius)
            .map_or(under, |m| m.min(under));
        let (w, h) = ((self.data.width - 1) as f64, (self.data.height - 1) as f64);
        let chord = [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)]
            .iter()
            .map(|&(c, r)| (lattice.position(DVec2::new(c, r), 0.0) - cam.position).length())
            .fold(0.0, f64::max);
        let far = chord * earth.sphere_radius() / earth.radius_m + 2.0 * spacing;
        let aspect = view.width as f64 / view.height as f64;
        AuxCamera::on_earth(cam, aspect, earth, far, &self.settings)
    }
}

impl LodMethod for Pgm {
    fn name(&self) -> &'static str {
        "pgm"
    }

    fn update(&mut self, slot: ViewSlot, view: &ViewState) -> Result<()> {
        let aux = self.aux_for(view);
        let grid = self.settings.grid();
        let u = aux.uniforms(grid, self.band, self.mips);
        let rows = aux.row_fractions(grid[1], self.settings.warp_rows);
        self.row_t[slot.index()].write(bytemuck::cast_slice(&rows))?;
        self.uniforms[slot.index()].write(bytemuck::bytes_of(&u))
    }

    /// On the earth: places every grid vertex (`shaders/pgm_earth.wgsl`).
    fn record_prepass(
        &mut self,
        cmd: vk::CommandBuffer,
        slot: ViewSlot,
        frame_set: vk::DescriptorSet,
    ) {
        let Some(pass) = &self.earth_pass else {
            return;
        };
        let d = &self.gpu.device;
        let b = Barriers::new(&self.gpu);
        let [cols, rows] = self.settings.grid();
        // The slot's previous frame read the vertices in its vertex stage (same queue).
        b.memory(cmd, MemoryAccess::PreviousFrame, MemoryAccess::ComputeWrite);
        unsafe {
            pass.bind(
                cmd,
                vk::PipelineBindPoint::COMPUTE,
                &[frame_set, self.sets.sets[slot.index()]],
            );
            d.cmd_dispatch(
                cmd,
                cols.div_ceil(PGM_EARTH_TILE),
                rows.div_ceil(PGM_EARTH_TILE),
                1,
            );
        }
        b.memory(
            cmd,
            MemoryAccess::ComputeWrite,
            MemoryAccess::VertexShaderRead,
        );
    }

    fn record_draw(
        &mut self,
        cmd: vk::CommandBuffer,
        slot: ViewSlot,
        frame_set: vk::DescriptorSet,
    ) {
        let d = &self.gpu.device;
        unsafe {
            self.pipeline.bind(
                cmd,
                vk::PipelineBindPoint::GRAPHICS,
                &[frame_set, self.sets.sets[slot.index()]],
            );
            d.cmd_bind_index_buffer(cmd, self.indices.raw, 0, vk::IndexType::UINT16);
            d.cmd_draw_indexed(cmd, self.index_count, self.instances, 0, 0, 0);
        }
    }

    /// Every drawn triangle, including the zero-area ones of the last band past the last row.
    fn triangles(&self, _slot: ViewSlot) -> u64 {
        self.instances as u64 * self.index_count as u64 / 3
    }

    fn counters(&self, _slot: ViewSlot) -> Vec<(&'static str, u64)> {
        let [cols, rows] = self.settings.grid();
        vec![
            ("grid_triangles", 2 * (cols as u64 - 1) * (rows as u64 - 1)),
            ("mip_levels", self.mips as u64),
        ]
    }
}

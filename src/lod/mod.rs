//! LOD methods behind one seam: the renderer, the evaluator and the benchmarks only see
//! [`LodMethod`], so brute force and later methods are interchangeable.

pub mod brute;
pub mod pgm;
pub mod udlod;

use ash::vk;

use crate::error::{Error, Result};
use crate::render::pipeline::TargetFormats;
use crate::render::terrain::TerrainGpu;
use crate::scene::Camera;

/// The methods vkterrain knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MethodKind {
    /// Every height sample is a vertex: the exact reference.
    Brute,
    /// GPU quadtree tiling in compute + vertex morphing (Kühnert's UDLOD).
    Udlod,
    /// Persistent grid mapping: a fixed screen-space grid projected onto the ground through an
    /// auxiliary camera (a baseline that is known to swim).
    Pgm,
}

impl MethodKind {
    pub const ALL: &[(&'static str, MethodKind)] = &[
        ("brute", MethodKind::Brute),
        ("udlod", MethodKind::Udlod),
        ("pgm", MethodKind::Pgm),
    ];

    pub fn parse(name: &str) -> Result<Self> {
        Self::ALL
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, k)| *k)
            .ok_or_else(|| {
                let names: Vec<_> = Self::ALL.iter().map(|(n, _)| *n).collect();
                Error::invalid(
                    "method",
                    format!(
                        "unknown method {name:?} (expected one of {})",
                        names.join(", ")
                    ),
                )
            })
    }

    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(_, k)| *k == self)
            .map(|(n, _)| *n)
            .unwrap_or("?")
    }
}

/// What a method gets to build its GPU state.
pub struct MethodContext<'a> {
    pub gpu: &'a std::sync::Arc<crate::driver::Gpu>,
    pub terrain: &'a TerrainGpu,
    /// Level-0 heights: the grid in memory, or a tile pyramid (clipmap path).
    pub data: &'a crate::dataset::Terrain,
    pub settings: &'a LodSettings,
    pub formats: TargetFormats,
    pub slots: usize,
}

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

/// One LOD method. Per frame the renderer calls `update` (host side, slot free), then records
/// `record_prepass` outside and `record_draw` inside the terrain render pass; set 0 (frame
/// uniforms + terrain textures) is bound by the method with its own pipeline layout.
pub trait LodMethod {
    fn name(&self) -> &'static str;
    /// Host-side per-frame work for `slot` (uniforms, CPU selection). The slot's previous GPU
    /// work is complete when this is called.
    fn update(&mut self, slot: usize, view: &ViewState) -> Result<()>;
    /// Compute work before the render pass (tiling, culling); none by default. `frame_set` is
    /// descriptor set 0 of this slot.
    fn record_prepass(
        &mut self,
        _cmd: vk::CommandBuffer,
        _slot: usize,
        _frame_set: vk::DescriptorSet,
    ) {
    }
    /// Draws inside the terrain pass; `frame_set` is descriptor set 0 of this slot.
    fn record_draw(&mut self, cmd: vk::CommandBuffer, slot: usize, frame_set: vk::DescriptorSet);
    /// Triangles the last frame of `slot` drew (including zero-area ones). Called once that
    /// frame's GPU work is complete, so GPU-driven methods can report what the GPU chose.
    fn triangles(&self, slot: usize) -> u64;
    /// Method-specific counters of the last completed frame of `slot` (e.g. tiles, overflow).
    fn counters(&self, _slot: usize) -> Vec<(&'static str, u64)> {
        Vec::new()
    }
    /// Tests only: the tiles the GPU selected in the last completed frame of `slot`.
    fn debug_tiles(&self, _slot: usize) -> Result<Option<Vec<[u32; 3]>>> {
        Ok(None)
    }
}

/// Creates a method by kind.
pub fn create(kind: MethodKind, ctx: &MethodContext<'_>) -> Result<Box<dyn LodMethod>> {
    Ok(match kind {
        MethodKind::Brute => Box::new(brute::BruteForce::new(ctx)?),
        MethodKind::Udlod => Box::new(udlod::Udlod::new(ctx)?),
        MethodKind::Pgm => Box::new(pgm::Pgm::new(ctx)?),
    })
}

/// Settings of the LOD methods (config `[lod]`).
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct LodSettings {
    /// UDLOD: quads per tile side (even, 4..=64).
    pub grid_size: u32,
    /// UDLOD: screen-space geometric error target in pixels.
    pub tau_px: f64,
    /// UDLOD: fraction of each level's range over which vertices morph (0.05..=0.45).
    pub morph_range: f64,
    /// UDLOD: capacity of the final tile list (tiles per frame).
    pub max_tiles: u32,
    /// UDLOD: vertex morphing (off only to demonstrate popping and cracks in tests).
    pub morph: bool,
    /// UDLOD: frustum culling of tiles.
    pub cull: bool,
    /// UDLOD: cap of the per-region error field (1 = distance-only selection: every region
    /// refined for the level's worst error). Larger lets smooth regions keep coarser levels.
    pub error_field_max: f64,
    /// UDLOD: draw without an index buffer (six vertex-shader runs per quad) instead of the
    /// shared indexed grid; kept for measurement (`benches/udlod.rs` compares the two).
    pub vertex_pulling: bool,
    /// PGM: grid vertices `[columns, rows]`: columns run across the screen (left to right),
    /// rows from the bottom of the auxiliary view up to the horizon.
    pub pgm_grid: [u32; 2],
    /// PGM: smallest field of view of the auxiliary camera in degrees (90..=170), both
    /// horizontally and vertically; its pitch is clamped to at most `-pgm_fov_deg / 2`.
    pub pgm_fov_deg: f64,
    /// PGM: lowest height of the auxiliary camera above the reference plane (the terrain under
    /// the camera), metres.
    pub pgm_min_height_m: f64,
}

impl Default for LodSettings {
    fn default() -> Self {
        LodSettings {
            grid_size: 16,
            tau_px: 1.0,
            morph_range: 0.2,
            max_tiles: 16384,
            morph: true,
            cull: true,
            error_field_max: 8.0,
            vertex_pulling: false,
            pgm_grid: [240, 1050],
            pgm_fov_deg: 90.0,
            pgm_min_height_m: 2.0,
        }
    }
}

impl LodSettings {
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("lod settings", m));
        if !(4..=64).contains(&self.grid_size) || self.grid_size % 2 != 0 {
            return bad(format!(
                "grid_size {} must be even and within 4..=64",
                self.grid_size
            ));
        }
        if !(self.tau_px.is_finite() && self.tau_px >= 0.05 && self.tau_px <= 1000.0) {
            return bad(format!(
                "tau_px {} must be within 0.05..=1000 pixels",
                self.tau_px
            ));
        }
        if !(self.morph_range.is_finite() && (0.05..=0.45).contains(&self.morph_range)) {
            return bad(format!(
                "morph_range {} must be within 0.05..=0.45",
                self.morph_range
            ));
        }
        if !(16..=1 << 22).contains(&self.max_tiles) {
            return bad(format!(
                "max_tiles {} must be within 16..=4194304",
                self.max_tiles
            ));
        }
        if !(self.error_field_max.is_finite() && (1.0..=1024.0).contains(&self.error_field_max)) {
            return bad(format!(
                "error_field_max {} must be within 1..=1024",
                self.error_field_max
            ));
        }
        let [cols, rows] = self.pgm_grid;
        if !(2..=4096).contains(&cols) || !(2..=16384).contains(&rows) {
            return bad(format!(
                "pgm_grid [{cols}, {rows}] needs 2..=4096 columns and 2..=16384 rows"
            ));
        }
        if cols as u64 * rows as u64 > 1 << 24 {
            return bad(format!(
                "pgm_grid [{cols}, {rows}] has more than 16777216 vertices"
            ));
        }
        if !(self.pgm_fov_deg.is_finite() && (90.0..=170.0).contains(&self.pgm_fov_deg)) {
            return bad(format!(
                "pgm_fov_deg {} must be within 90..=170 degrees",
                self.pgm_fov_deg
            ));
        }
        if !(self.pgm_min_height_m.is_finite()
            && self.pgm_min_height_m > 0.0
            && self.pgm_min_height_m <= 100_000.0)
        {
            return bad(format!(
                "pgm_min_height_m {} must be within (0, 100000] metres",
                self.pgm_min_height_m
            ));
        }
        Ok(())
    }
}

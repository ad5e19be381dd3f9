//! LOD methods behind one seam: the renderer, the evaluator and the benchmarks only see
//! [`LodMethod`], so brute force and later methods are interchangeable.

pub mod blocks;
pub mod brute;
pub mod chunked;
pub mod geomipmap;
pub mod pgm;
pub mod sweep;
pub mod tessellation;
pub mod udlod;

pub use chunked::settings::ChunkedSettings;
pub use geomipmap::settings::{CullBox, GeomipmapSettings};
pub use pgm::settings::PgmSettings;
pub use tessellation::settings::TessellationSettings;
pub use udlod::settings::UdlodSettings;

use ash::vk;

use crate::driver::pipeline::TargetFormats;
use crate::error::{Error, Result};
use crate::frame::{TerrainGpu, ViewState};
use crate::slots::ViewSlot;
use sweep::Sweep;

/// The methods vkterrain knows (the `name` of `[method]`, `--method`, `--methods`).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum, serde::Deserialize, serde::Serialize,
)]
#[serde(rename_all = "lowercase")]
pub enum MethodKind {
    /// Every height sample is a vertex: the exact reference.
    Brute,
    /// GPU quadtree tiling in compute + vertex morphing (Kühnert's UDLOD).
    Udlod,
    /// Persistent grid mapping: a fixed screen-space grid projected onto the ground through an
    /// auxiliary camera (a baseline that is known to swim).
    Pgm,
    /// Hardware tessellation of flat triangle patches, levels from on-screen edge length
    /// (Fischer 2024); needs the device feature `tessellationShader`.
    Tessellation,
    /// GeoMipMapping: blocks of 2^n + 1 samples, per-block level from the 3D distance, border
    /// permutations against cracks, no morphing (Tabakovic's ATLOD).
    Geomipmap,
    /// GPU chunked LOD (Hedberg 2022): the chunk quadtree selected in compute by projected
    /// error (naive walk or concurrent binary tree), edge patching through a LOD map, one
    /// chunk mesh instanced per chunk.
    Chunked,
}

impl MethodKind {
    pub const ALL: &[MethodKind] = &[
        MethodKind::Brute,
        MethodKind::Udlod,
        MethodKind::Pgm,
        MethodKind::Tessellation,
        MethodKind::Geomipmap,
        MethodKind::Chunked,
    ];

    pub fn parse(name: &str) -> Result<Self> {
        <Self as clap::ValueEnum>::from_str(name, false).map_err(|_| {
            let names: Vec<_> = Self::ALL.iter().map(|k| k.name()).collect();
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
        match self {
            MethodKind::Brute => "brute",
            MethodKind::Udlod => "udlod",
            MethodKind::Pgm => "pgm",
            MethodKind::Tessellation => "tessellation",
            MethodKind::Geomipmap => "geomipmap",
            MethodKind::Chunked => "chunked",
        }
    }
}

/// A method with its settings: config `[method]`, where `name` selects the method and the
/// other keys are that method's settings.
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(tag = "name", rename_all = "lowercase", deny_unknown_fields)]
pub enum MethodConfig {
    /// No settings (a struct variant, so that a stray key is an error, not ignored).
    Brute {},
    Udlod(UdlodSettings),
    Pgm(PgmSettings),
    Tessellation(TessellationSettings),
    Geomipmap(GeomipmapSettings),
    Chunked(ChunkedSettings),
}

impl Default for MethodConfig {
    fn default() -> Self {
        MethodConfig::Udlod(UdlodSettings::default())
    }
}

impl From<MethodKind> for MethodConfig {
    fn from(kind: MethodKind) -> Self {
        MethodConfig::default_for(kind)
    }
}

impl From<UdlodSettings> for MethodConfig {
    fn from(s: UdlodSettings) -> Self {
        MethodConfig::Udlod(s)
    }
}

impl From<PgmSettings> for MethodConfig {
    fn from(s: PgmSettings) -> Self {
        MethodConfig::Pgm(s)
    }
}

impl MethodConfig {
    pub fn kind(&self) -> MethodKind {
        match self {
            MethodConfig::Brute {} => MethodKind::Brute,
            MethodConfig::Udlod(_) => MethodKind::Udlod,
            MethodConfig::Pgm(_) => MethodKind::Pgm,
            MethodConfig::Tessellation(_) => MethodKind::Tessellation,
            MethodConfig::Geomipmap(_) => MethodKind::Geomipmap,
            MethodConfig::Chunked(_) => MethodKind::Chunked,
        }
    }

    /// `kind` with its default settings.
    pub fn default_for(kind: MethodKind) -> Self {
        match kind {
            MethodKind::Brute => MethodConfig::Brute {},
            MethodKind::Udlod => MethodConfig::Udlod(UdlodSettings::default()),
            MethodKind::Pgm => MethodConfig::Pgm(PgmSettings::default()),
            MethodKind::Tessellation => MethodConfig::Tessellation(TessellationSettings::default()),
            MethodKind::Geomipmap => MethodConfig::Geomipmap(GeomipmapSettings::default()),
            MethodKind::Chunked => MethodConfig::Chunked(ChunkedSettings::default()),
        }
    }

    /// This configuration if it is of `kind`, else `kind` with its default settings.
    pub fn with_kind(self, kind: MethodKind) -> Self {
        if self.kind() == kind {
            self
        } else {
            Self::default_for(kind)
        }
    }

    pub fn validate(&self) -> Result<()> {
        match self {
            MethodConfig::Brute {} => Ok(()),
            MethodConfig::Udlod(s) => s.validate(),
            MethodConfig::Pgm(s) => s.validate(),
            MethodConfig::Tessellation(s) => s.validate(),
            MethodConfig::Geomipmap(s) => s.validate(),
            MethodConfig::Chunked(s) => s.validate(),
        }
    }

    /// UDLOD's settings, or an error naming `what` needs them.
    pub fn udlod_mut(&mut self, what: &str) -> Result<&mut UdlodSettings> {
        match self {
            MethodConfig::Udlod(s) => Ok(s),
            other => Err(Error::invalid(
                what,
                format!(
                    "is a UDLOD setting, but the method is {}",
                    other.kind().name()
                ),
            )),
        }
    }

    /// The keys `--sweep` can vary for this method, with their help.
    pub fn sweep_keys(kind: MethodKind) -> Vec<(&'static str, &'static str)> {
        fn keys<S>(t: &[Sweep<S>]) -> Vec<(&'static str, &'static str)> {
            t.iter().map(|s| (s.key, s.help)).collect()
        }
        match kind {
            MethodKind::Brute => Vec::new(),
            MethodKind::Udlod => keys(UdlodSettings::SWEEP),
            MethodKind::Pgm => keys(PgmSettings::SWEEP),
            MethodKind::Tessellation => keys(TessellationSettings::SWEEP),
            MethodKind::Geomipmap => keys(GeomipmapSettings::SWEEP),
            MethodKind::Chunked => keys(ChunkedSettings::SWEEP),
        }
    }

    /// Sets sweep parameter `key` to `value` (validate afterwards).
    pub fn apply_sweep(&mut self, key: &str, value: f64) -> Result<()> {
        match self {
            MethodConfig::Brute {} => sweep::apply::<()>(&[], &mut (), key, value),
            MethodConfig::Udlod(s) => sweep::apply(UdlodSettings::SWEEP, s, key, value),
            MethodConfig::Pgm(s) => sweep::apply(PgmSettings::SWEEP, s, key, value),
            MethodConfig::Tessellation(s) => {
                sweep::apply(TessellationSettings::SWEEP, s, key, value)
            }
            MethodConfig::Geomipmap(s) => sweep::apply(GeomipmapSettings::SWEEP, s, key, value),
            MethodConfig::Chunked(s) => sweep::apply(ChunkedSettings::SWEEP, s, key, value),
        }
    }
}

/// One line per method: the keys `--sweep` takes (for `--help`).
pub fn sweep_help() -> String {
    let mut out = String::from("Parameter sweep KEY=v1,v2,... (repeatable); keys by method:");
    for &kind in MethodKind::ALL {
        let keys = MethodConfig::sweep_keys(kind);
        if !keys.is_empty() {
            let k: Vec<String> = keys.iter().map(|(k, h)| format!("{k} ({h})")).collect();
            out.push_str(&format!(" {}: {};", kind.name(), k.join(", ")));
        }
    }
    out
}

/// What a method gets to build its GPU state.
pub struct MethodContext<'a> {
    pub gpu: &'a std::sync::Arc<crate::driver::Gpu>,
    pub terrain: &'a TerrainGpu,
    /// Level-0 heights: the grid in memory, or a tile pyramid (clipmap path).
    pub data: &'a crate::dataset::Terrain,
    pub formats: TargetFormats,
    pub slots: usize,
    /// The geolocation lattice the terrain is drawn through (None: the flat world): methods
    /// that cull on the CPU, or mirror the GPU's culling there, need it for the curved boxes.
    pub lattice: Option<&'a std::sync::Arc<crate::geo::Lattice>>,
}

/// The tiles of a frame: `[x, y, lod]` each, in tiles of their level. A level-`lod` tile spans
/// `tile_samples << lod` level-0 sample steps per side, from `(x, y)` times that.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DrawnTiles {
    pub tiles: Vec<[u32; 3]>,
    pub tile_samples: u32,
}

/// One LOD method. Per frame the renderer calls `update` (host side, slot free), then records
/// `record_prepass` outside and `record_draw` inside the terrain render pass; set 0 (frame
/// uniforms + terrain textures) is bound by the method with its own pipeline layout.
pub trait LodMethod {
    fn name(&self) -> &'static str;
    /// Host-side per-frame work for `slot` (uniforms, CPU selection). The slot's previous GPU
    /// work is complete when this is called.
    fn update(&mut self, slot: ViewSlot, view: &ViewState) -> Result<()>;
    /// Compute work before the render pass (tiling, culling); none by default. `frame_set` is
    /// descriptor set 0 of this slot.
    fn record_prepass(
        &mut self,
        _cmd: vk::CommandBuffer,
        _slot: ViewSlot,
        _frame_set: vk::DescriptorSet,
    ) {
    }
    /// Draws inside the terrain pass; `frame_set` is descriptor set 0 of this slot.
    fn record_draw(&mut self, cmd: vk::CommandBuffer, slot: ViewSlot, frame_set: vk::DescriptorSet);
    /// Triangles the last frame of `slot` drew (including zero-area ones). Called once that
    /// frame's GPU work is complete, so GPU-driven methods can report what the GPU chose.
    fn triangles(&self, slot: ViewSlot) -> u64;
    /// Tiles (or other units) the last completed frame of `slot` wanted but the method's fixed
    /// budget could not hold (UDLOD's `max_tiles`): that frame is coarser than its settings
    /// ask. 0 for methods without such a budget.
    fn budget_overflow(&self, _slot: ViewSlot) -> u64 {
        0
    }
    /// Method-specific counters of the last completed frame of `slot` (e.g. tiles, overflow).
    fn counters(&self, _slot: ViewSlot) -> Vec<(&'static str, u64)> {
        Vec::new()
    }
    /// Tiles the last completed frame of `slot` drew (None: the method draws no tiles), read
    /// at every frame's delivery (`FrameView::tiles`), so without allocating.
    fn tiles(&self, _slot: ViewSlot) -> Option<u64> {
        None
    }
    /// The tiles the last completed frame of `slot` drew (`None`: the method draws no
    /// quadtree of tiles). The evaluator reads from them which pixels show geometry coarser
    /// than the data's level 0 (docs/eval.md, "Coarse pixels").
    fn drawn_tiles(&self, _slot: ViewSlot) -> Result<Option<DrawnTiles>> {
        Ok(None)
    }
    #[cfg(feature = "test-support")]
    /// Tests only: the tiles the GPU selected in the last completed frame of `slot`.
    fn debug_tiles(&self, _slot: ViewSlot) -> Result<Option<Vec<[u32; 3]>>> {
        Ok(None)
    }
    #[cfg(feature = "test-support")]
    /// Tests only: per tile of [`LodMethod::debug_tiles`], the draw it went to (UDLOD:
    /// `udlod::draw_group`).
    fn debug_tile_draws(&self, _slot: ViewSlot) -> Result<Option<Vec<u32>>> {
        Ok(None)
    }
    #[cfg(feature = "test-support")]
    /// Tests only: the method's own descriptor set 1 of `slot` (layout, set), for probes that
    /// evaluate its shader functions through it (`None`: the method has none to probe).
    fn probe_set(&self, _slot: ViewSlot) -> Option<(vk::DescriptorSetLayout, vk::DescriptorSet)> {
        None
    }
    #[cfg(feature = "test-support")]
    /// Tests only: the method's vertex morph evaluated on the GPU for `(tile, local vertex)`
    /// pairs through set 0 `frame` (layout, set) and the method's own set of `slot`, as the last
    /// completed frame left them (`None`: the method has no morph).
    fn probe_vertices(
        &self,
        _slot: ViewSlot,
        _frame: (vk::DescriptorSetLayout, vk::DescriptorSet),
        _inputs: &[(udlod::levels::Tile, [u32; 2])],
    ) -> Result<Option<Vec<udlod::probe::ProbedVertex>>> {
        Ok(None)
    }
}

/// Creates the method `config` names, with its settings.
pub fn create(config: &MethodConfig, ctx: &MethodContext<'_>) -> Result<Box<dyn LodMethod>> {
    config.validate()?;
    Ok(match config {
        MethodConfig::Brute {} => Box::new(brute::BruteForce::new(ctx)?),
        MethodConfig::Udlod(s) => Box::new(udlod::Udlod::new(ctx, s)?),
        MethodConfig::Pgm(s) => Box::new(pgm::Pgm::new(ctx, s)?),
        MethodConfig::Tessellation(s) => Box::new(tessellation::Tessellation::new(ctx, s)?),
        MethodConfig::Geomipmap(s) => Box::new(geomipmap::Geomipmap::new(ctx, s)?),
        MethodConfig::Chunked(s) => Box::new(chunked::Chunked::new(ctx, s)?),
    })
}

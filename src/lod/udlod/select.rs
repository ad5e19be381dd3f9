//! UDLOD on the CPU: the level structure, per-tile min/max heights and geometric errors, the
//! per-tile split distances derived from the screen-space error target and the crack-free
//! ties between levels (the split field), the frustum, the vertex morph cascade, and a
//! reference implementation of the GPU's tile selection (tests compare the GPU's final tile
//! list against it).
//!
//! Arithmetic that must agree with the shaders (`select_tiles`, `morph_factor`,
//! `morphed_vertex`, `field_at`) is written in f32 in the same order as
//! `shaders/udlod_tiling.wgsl`, `shaders/include/udlod_morph.wgsl` and
//! `shaders/include/udlod_common.wgsl`.

use std::sync::Arc;

use glam::{DVec3, Vec3};

use super::grid::TileMask;
use super::settings::{MORPH_LEVELS_ALL, UdlodSettings};
use crate::dataset::stats::{FieldStats, TileStats, level_interpolate};
use crate::dataset::{Heightmap, Level0};
use crate::error::{Error, Result};
use crate::geo::{EarthCull, Lattice};
use crate::gpu_constants::{UDLOD_COLLAPSE_MARGIN, UDLOD_MAX_LEVELS, UDLOD_NO_SPLIT};
use crate::scene::Camera;

/// A quadtree tile: `(x, y)` in tiles of its level, `lod` 0 = full resolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Tile {
    pub x: u32,
    pub y: u32,
    pub lod: u32,
}

/// The static structure of the quadtree over one data set.
#[derive(Clone, Debug)]
pub struct Levels {
    /// Quads per tile side.
    pub grid_size: u32,
    /// The root level: one tile covers the whole data set.
    pub root_lod: u32,
    pub width: u32,
    pub height: u32,
    /// Metres between samples in the grid frame (`x = col * spacing`, `y = row * spacing`)
    /// the LOD viewer and the sample positions are given in.
    pub spacing: f64,
    /// The LOD metric: metres per sample along x and y, each a lower bound of the drawn
    /// surface's spacing along that axis anywhere on the grid, so LOD distances are never
    /// longer than true ones. `[spacing, spacing]` except on a native non-square grid on the
    /// earth ([`Levels::on_lattice`]).
    pub metric: [f64; 2],
    /// Tiles per side of each level (only tiles that touch the data).
    pub tiles_per_side: Vec<(u32, u32)>,
    /// Offset of each level's entries in `min_max` and `tile_error` (level 0 has none unless
    /// `finest_held`: [`Levels::stats_tile`]).
    pub level_offsets: Vec<u32>,
    /// (min, max) height in metres of every tile's samples (and of its morph targets, which are
    /// samples of the same tile); level 0's only when `finest_held`.
    pub min_max: Vec<[f32; 2]>,
    /// Geometric error of every tile in metres: the largest height difference between the
    /// full-resolution samples inside the tile and the tile's triangulated grid (level 0: 0,
    /// stored only when `finest_held`).
    pub tile_error: Vec<f32>,
    /// Geometric error of each level (the largest of its tiles'; 0 for level 0).
    pub level_error: Vec<f64>,
    /// Whether level 0's tiles are held (chunked LOD's levels) or stand in for by their
    /// parents (UDLOD's, when there is a coarser level: [`Levels::stats_tile`]).
    pub finest_held: bool,
    /// Split-field nodes per tile side (`UdlodSettings::field_density`): 1 puts the field's
    /// nodes at the tiles' corners; `d` puts them every `grid_size / d` quads, whose cells
    /// take the errors of the smaller tiles ([`Levels::field_cell_error`]).
    pub field_density: u32,
    /// With `field_density > 1`: the geometric error of every field cell (a tile of
    /// `grid_size / field_density` quads), per level from level 1 at `field_offsets`, row-major
    /// over `field_tiles_per_side`. Empty with one node per tile corner (the tiles' own), and
    /// between [`Levels::release_field_errors`] and [`Levels::restore_field_errors`].
    pub field_error: Vec<f32>,
    pub field_offsets: Vec<u32>,
    pub field_tiles_per_side: Vec<(u32, u32)>,
}

impl Levels {
    /// Builds the levels' statistics (per tile: min/max height and geometric error).
    /// `data` is any source of level-0 samples (the grid in memory, or a tile pyramid read
    /// node by node); the result depends only on the sample values. Errors are the source's
    /// (a pyramid node that cannot be read). Computes the tile statistics on this thread; a
    /// data set's stored statistics go through [`Levels::from_stats`].
    pub fn new<D: Level0 + ?Sized>(data: &D, grid_size: u32) -> Result<Self> {
        let stats = TileStats::compute_serial(data, grid_size)?;
        Ok(Self::from_stats(stats, data.spacing()))
    }

    /// The levels `settings` draw with: tiles of `grid_size` quads and a split field of
    /// `field_density` nodes per tile side ([`Levels::with_field_density`]), computed on this
    /// thread.
    pub fn for_settings<D: Level0 + ?Sized>(data: &D, settings: &UdlodSettings) -> Result<Self> {
        let d = settings.field_density();
        let stats = TileStats::compute_serial(data, settings.grid_size / d)?;
        Self::with_field_density(stats.without_finest(), d, data.spacing())
    }

    /// [`Levels::new`] holding level 0's tiles too (chunked LOD culls and bounds its level-0
    /// chunks with their own heights).
    pub fn with_finest<D: Level0 + ?Sized>(data: &D, grid_size: u32) -> Result<Self> {
        let stats = TileStats::compute_serial(data, grid_size)?;
        Ok(Self::from_stats_with_finest(stats, data.spacing()))
    }

    /// The levels from per-tile statistics (computed, or stored by `vkterrain preprocess`).
    /// Level 0's tiles are dropped when there is a coarser level
    /// ([`TileStats::without_finest`]): a level-0 tile never splits and has no error, and its
    /// parent's heights bound it for culling ([`Levels::stats_tile`]), so the statistics take
    /// a quarter of the memory (docs/udlod-rounds.md, "Host memory of the statistics").
    pub fn from_stats(stats: TileStats, spacing: f64) -> Self {
        Self::from_stats_with_finest(stats.without_finest(), spacing)
    }

    /// The levels from per-tile statistics as they are: with level 0's tiles when `stats`
    /// hold them (chunked LOD), else as [`Levels::from_stats`].
    pub fn from_stats_with_finest(stats: TileStats, spacing: f64) -> Self {
        let finest_held = stats.has_finest();
        let root_lod = stats.root_lod();
        let held: usize = stats.levels.iter().map(|l| l.error.len()).sum();
        let mut tiles_per_side = Vec::new();
        let mut level_offsets = Vec::new();
        let mut min_max = Vec::with_capacity(held);
        let mut tile_error = Vec::with_capacity(held);
        let mut level_error = Vec::new();
        for level in stats.levels {
            tiles_per_side.push(level.tiles);
            level_offsets.push(min_max.len() as u32);
            min_max.extend(level.min_max);
            tile_error.extend(level.error);
            level_error.push(level.max_error);
        }
        Levels {
            grid_size: stats.grid_size,
            root_lod,
            width: stats.width,
            height: stats.height,
            spacing,
            metric: [spacing, spacing],
            tiles_per_side,
            level_offsets,
            min_max,
            tile_error,
            level_error,
            finest_held,
            field_density: 1,
            field_error: Vec::new(),
            field_offsets: Vec::new(),
            field_tiles_per_side: Vec::new(),
        }
    }

    /// The levels of tiles `density` times larger than `fine`'s, with a split field of
    /// `density` nodes per tile side whose cells take `fine`'s errors (`docs/udlod.md`, "A
    /// finer split field").
    pub fn with_field_density(fine: TileStats, density: u32, spacing: f64) -> Result<Self> {
        Ok(Self::from_field_stats(
            FieldStats::from_cells(fine, density)?,
            spacing,
        ))
    }

    /// The levels of `stats.tiles` with a split field of `stats.density` nodes per tile side
    /// whose cells take the errors of `stats.cells`.
    pub fn from_field_stats(stats: FieldStats, spacing: f64) -> Self {
        let mut levels = Self::from_stats(stats.tiles, spacing);
        if let Some(cells) = stats.cells {
            levels.field_density = stats.density;
            levels.hold_field_errors(cells);
        }
        levels
    }

    /// Takes the errors of the field's cells from their statistics (levels 1 to the root).
    fn hold_field_errors(&mut self, cells: TileStats) {
        let held: usize = cells.levels[1..=self.root_lod as usize]
            .iter()
            .map(|l| l.error.len())
            .sum();
        self.field_error = Vec::with_capacity(held);
        self.field_offsets.clear();
        self.field_tiles_per_side.clear();
        for (lod, level) in cells.levels.into_iter().enumerate() {
            if lod > self.root_lod as usize {
                break;
            }
            self.field_offsets.push(self.field_error.len() as u32);
            self.field_tiles_per_side.push(level.tiles);
            if lod > 0 {
                self.field_error.extend(level.error);
            }
        }
    }

    /// Whether [`SplitField::new`] can build a field from these levels: the field's cells'
    /// errors are held (always with one node per tile corner, whose cells are the tiles).
    pub fn holds_field_errors(&self) -> bool {
        self.field_density == 1 || self.field_error.len() == self.field_cells_held()
    }

    /// Field cells with an error held, levels 1 and up (`field_tiles_per_side`).
    fn field_cells_held(&self) -> usize {
        (self.field_tiles_per_side.iter().skip(1))
            .map(|&(nx, ny)| nx as usize * ny as usize)
            .sum()
    }

    /// Frees the field's cells' errors (with two nodes per tile side 0.33 bytes per level-0
    /// sample at grid 4, a third of what UDLOD holds): a split field built from them needs
    /// them again only for another key ([`Levels::restore_field_errors`]).
    pub fn release_field_errors(&mut self) {
        if self.field_density > 1 {
            self.field_error = Vec::new();
        }
    }

    /// Takes the field's cells' errors back from `stats`, the statistics these levels were built
    /// from read again (bit for bit the same when the data is): a one-line error if they do
    /// not describe these levels' cells.
    pub fn restore_field_errors(&mut self, stats: FieldStats) -> Result<()> {
        let fits = stats.density == self.field_density
            && stats.cells.as_ref().is_some_and(|c| {
                c.levels.len() > self.root_lod as usize
                    && (c.levels.iter().zip(&self.field_tiles_per_side)).all(|(l, &t)| l.tiles == t)
            });
        match stats.cells {
            Some(cells) if fits => {
                self.hold_field_errors(cells);
                Ok(())
            }
            _ => Err(Error::invalid(
                "udlod",
                format!(
                    "the split field's cell statistics read again do not match the levels' ({} nodes per tile side)",
                    self.field_density
                ),
            )),
        }
    }

    /// Quads per split-field cell side (`grid_size / field_density`).
    pub fn field_cell_quads(&self) -> u32 {
        self.grid_size / self.field_density
    }

    /// Split-field cells per side of level `lod`: `field_density` per tile (cells past the
    /// data's edge have no error).
    pub fn field_cells_per_side(&self, lod: u32) -> (u32, u32) {
        let (nx, ny) = self.tiles_per_side[lod as usize];
        (nx * self.field_density, ny * self.field_density)
    }

    /// Split-field nodes stored over all levels from level 1 (level 0's are ones and not
    /// stored): `(nx + 1) x (ny + 1)` per level for its [`Levels::field_cells_per_side`].
    pub fn field_nodes(&self) -> usize {
        (1..=self.root_lod)
            .map(|lod| self.field_cells_per_side(lod))
            .map(|(nx, ny)| (nx as usize + 1) * (ny as usize + 1))
            .sum()
    }

    /// The geometric error of split-field cell `(x, y)` of level `lod` >= 1: the tile's own
    /// with one node per tile corner, else the small tile's (0 past the data's edge).
    pub fn field_cell_error(&self, lod: u32, x: u32, y: u32) -> f32 {
        if self.field_density == 1 {
            return self.tile_error(Tile { x, y, lod });
        }
        let (nx, ny) = self.field_tiles_per_side[lod as usize];
        if x >= nx || y >= ny {
            return 0.0;
        }
        self.field_error[(self.field_offsets[lod as usize] + y * nx + x) as usize]
    }

    pub fn levels(&self) -> u32 {
        self.root_lod + 1
    }

    /// These levels with the LOD metric of a grid drawn through `lattice` whose stated
    /// metres between samples are `axis_spacing`: on a native non-square grid (a geographic
    /// one) each axis's smallest spacing on the drawn surface at the data's lowest height
    /// (below the datum it shrinks) ([`Lattice::min_axis_spacing`]), so east-west and
    /// north-south distances are each measured with their own lower bound. Square grids keep
    /// `[spacing, spacing]`: their selection is unchanged bit for bit (docs/udlod.md,
    /// "Per-axis metric on the earth").
    pub fn on_lattice(mut self, axis_spacing: [f64; 2], lattice: &Lattice) -> Self {
        if let Some(metric) = lattice.lod_metric(axis_spacing, self.lowest() as f64) {
            self.metric = metric;
        }
        self
    }

    /// The data's lowest height (m; the root tile's minimum).
    pub fn lowest(&self) -> f32 {
        self.min_max[self.tile_index(Tile {
            x: 0,
            y: 0,
            lod: self.root_lod,
        })][0]
    }

    /// The LOD metric as a stretch of the grid frame per axis, as the GPU gets it (f32;
    /// exactly `[1, 1]` on square grids): a grid-frame offset times it is metres.
    pub fn stretch(&self) -> [f32; 2] {
        self.metric.map(|m| (m / self.spacing) as f32)
    }

    /// Diagonal of a level-`lod` tile in the LOD metric (the stretch as the GPU applies it):
    /// `sqrt(2) * tile_extent(lod)` on square grids.
    pub fn tile_diagonal(&self, lod: u32) -> f64 {
        let [sx, sy] = self.stretch().map(|s| s as f64);
        self.tile_extent(lod) * (sx * sx + sy * sy).sqrt()
    }

    /// Tile side in metres at `lod`.
    pub fn tile_extent(&self, lod: u32) -> f64 {
        (self.grid_size << lod) as f64 * self.spacing
    }

    /// The tile whose statistics stand for `t`: `t` itself, or for a level-0 tile when
    /// level 0's are not held its parent, whose heights contain its own (mirrors
    /// `tile_min_max` in `shaders/udlod_tiling.wgsl`, where UDLOD's levels never hold them
    /// below a coarser root).
    pub fn stats_tile(&self, t: Tile) -> Tile {
        if t.lod == 0 && !self.finest_held {
            return Tile {
                x: t.x / 2,
                y: t.y / 2,
                lod: 1,
            };
        }
        t
    }

    fn tile_index(&self, t: Tile) -> usize {
        let t = self.stats_tile(t);
        let (nx, _) = self.tiles_per_side[t.lod as usize];
        (self.level_offsets[t.lod as usize] + t.y * nx + t.x) as usize
    }

    /// (min, max) height bounding the tile's samples: its own, or its parent's at level 0.
    pub fn tile_min_max(&self, t: Tile) -> [f32; 2] {
        self.min_max[self.tile_index(t)]
    }

    /// The tile's geometric error (0 at level 0).
    pub fn tile_error(&self, t: Tile) -> f32 {
        if t.lod == 0 {
            return 0.0;
        }
        self.tile_error[self.tile_index(t)]
    }

    /// Does the tile touch the data set?
    pub fn inside(&self, t: Tile) -> bool {
        let (nx, ny) = self.tiles_per_side[t.lod as usize];
        t.x < nx && t.y < ny
    }
}

/// Height of the level-`lod` triangulated grid at full-resolution sample `(c, r)`. Quads are
/// split along the diagonal from (1, 0) to (0, 1), as `grid_indices` does. The level's edges
/// run along full-resolution edges, so the largest difference between the two meshes is at a
/// full-resolution sample: the per-sample maximum is the exact mesh-to-mesh error.
pub fn level_height<D: Level0 + ?Sized>(data: &D, lod: u32, c: u32, r: u32) -> Result<f64> {
    Ok(level_interpolate(
        lod,
        level_corners(data, lod, c, r)?,
        c,
        r,
    ))
}

/// The four level-`lod` samples around `(c, r)`: `(c0, r0)`, `(c0 + step, r0)`,
/// `(c0, r0 + step)`, `(c0 + step, r0 + step)`, clamped to the data.
fn level_corners<D: Level0 + ?Sized>(data: &D, lod: u32, c: u32, r: u32) -> Result<[f64; 4]> {
    let step = 1u32 << lod;
    let (w, h) = (data.width(), data.height());
    let s = |c: u32, r: u32| data.sample(c.min(w - 1), r.min(h - 1)).map(|v| v as f64);
    let (c0, r0) = (c / step * step, r / step * step);
    Ok([
        s(c0, r0)?,
        s(c0 + step, r0)?,
        s(c0, r0 + step)?,
        s(c0 + step, r0 + step)?,
    ])
}

/// What a [`SplitField`] depends on besides the data: it is rebuilt when one of these changes
/// (in practice once per renderer and view size).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldKey {
    /// Focal length in pixels (`Camera::focal_px`).
    pub focal_px: f64,
    pub tau_px: f64,
    pub morph_range: f64,
    /// Levels over which a tile's vertices morph (`UdlodSettings::morph_levels`, resolved).
    pub morph_levels: u32,
    /// Largest ratio between a level's largest and a tile's split distance (1: one distance
    /// per level, the distance-only selection).
    pub field_max: f64,
    /// The share of a tile's worst-case projected error spent on `tau`
    /// ([`worst_case_share`](super::settings::worst_case_share) unless the settings override it).
    pub share: f64,
    /// How each cell is charged its morph zone's width: [`ZoneRule::Width`] for the morph the
    /// renderer draws; the others only for counting.
    pub zone_rule: ZoneRule,
}

/// How the split field charges each cell for its morph zone's width `W` ([`zone_widths`]).
/// The renderer's morph assumes [`ZoneRule::Width`]; the others are what-ifs that
/// `examples/udlod_budget.rs` counts (`--zone-rule`; `docs/udlod.md`, "What sets the field"):
/// fields built with them are not sound for the morph drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ZoneRule {
    /// The zone is `max(W, r s)` wide and charged in full (the renderer's).
    #[default]
    Width,
    /// As if the zone were `W min(1, E / s)` wide, `E` the larger of the cell's and its
    /// children's pixel terms: a zone that narrows with the error.
    ErrorScaled,
    /// As if the zone cost nothing: what `W` costs at most.
    Free,
}

impl FieldKey {
    pub fn new(settings: &UdlodSettings, focal_px: f64) -> Self {
        FieldKey {
            focal_px,
            tau_px: settings.tau_px,
            morph_range: settings.morph_range,
            morph_levels: settings.morph_levels(),
            field_max: settings.error_field_max,
            share: settings.worst_case_share(),
            zone_rule: ZoneRule::Width,
        }
    }
}

/// Relative margin on the split field's nesting and reach terms: covers the f32 rounding of
/// `m`, `D` and the `m * d < D` test on the GPU (~1e-7 each).
pub(super) const CHAIN_MARGIN: f64 = 1e-5;

/// Per-tile split distances: how near the LOD viewer may come to each tile before it splits,
/// derived per tile from its own geometric error and the pixel target, and tied between
/// levels tile by tile so the morph cascade closes every edge (`docs/udlod.md`, "Split field"
/// and "The morph cascade").
///
/// Stored as the GPU reads it: per level a split distance `D[l]` (the level's largest) and a
/// field `m_l >= 1` at the corners of the level's tiles (with `field_density` `d > 1` at the
/// corners of its field cells, `d` per tile side), interpolated bilinearly; a point's
/// split distance is `s_l(p) = D[l] / m_l(p)`. A tile splits when its nearest point (at the
/// reference height) is nearer than the largest `s` of its corners (`m_min * d < D`);
/// grid points of level `l - 1` morph over the last `morph_range` of `s_l(p)`. With `s_Q` the
/// smallest and `S_Q` the largest corner value of tile `Q`, for every tile `Q` of level `l`
/// (`cell_requirement`, per field cell; with one node per tile corner the cells are the tiles):
/// 1. pixel target: `s_Q >= k e_Q f / tau` (`e_Q`: the tile's own error, `k`:
///    [`worst_case_share`](super::settings::worst_case_share) of the grid size), so wherever `Q`'s geometry is drawn, unmorphed
///    or blended into its children's morph zone, it is at least that far away (with the morph
///    cascade `s_Q >= (1 - r) k e_Q f / tau + W[l]` too: its zone is at least `W[l]` wide);
/// 2. nesting: `s_Q >= S_P` for each child `P`: where an unsplit tile meets finer ones, their
///    edge vertices are fully morphed through every level between;
/// 3. reach: the morph zone of `s_Q` (`r s_Q`, with the morph cascade at least
///    [`Self::zone`]) starts beyond `S_G + diagonal(l - q)` for each descendant `G` of level
///    `l - q` (`q`: `FieldKey::morph_levels`; the diagonal in the LOD metric,
///    [`Levels::tile_diagonal`], `sqrt(2) extent` on square grids): a tile's vertices morph
///    over at most `q` levels and stay inside it; with walks past the tile (the default) the
///    separation instead, beyond `S_G` of level `l - 2`: no fold ([`cell_requirement`]);
/// 4. with the morph cascade, a gentle morph: a corner's distance is at least its neighbour's
///    over `FIELD_STEP_RATIO` (`gentle_morph`).
///
/// Level 0 never splits. Each corner takes the largest requirement of the tiles around it;
/// `field_max` then raises small values to the level's largest / `field_max`.
#[derive(Clone, Debug)]
pub struct SplitField {
    pub key: FieldKey,
    /// `D[l]` in metres: the largest split distance of each level (0 for level 0, which never
    /// splits; [`UDLOD_NO_SPLIT`] past the root), `UDLOD_MAX_LEVELS` entries as uploaded.
    pub split: Vec<f32>,
    /// Per level, the least width in metres of the zone over which the level below morphs
    /// onto it (`W[l]`; 0 with one level step, where the zone is `morph_range` of the split
    /// distance): with the morph cascade the zone is the larger of `W[l]` and `r s`
    /// (`zone_widths`). `UDLOD_MAX_LEVELS` entries as uploaded.
    pub zone: Vec<f32>,
    /// Field values `m >= 1` at every level's tile corners, `(nx + 1) x (ny + 1)` row-major
    /// per level from level 1 (level 0's are all ones and not stored).
    pub corners: Vec<f32>,
    /// Offset of each level's corners in `corners`.
    pub corner_offsets: Vec<u32>,
    /// Per level, `(k, s)` pairs: with the level's split distances ([`Self::tile_split`])
    /// sorted in decreasing order, `s` (metres) is the one at rank `k`, so `k` tiles have one of
    /// at least `s` and every other tile one of at most `s`; at `k` = 0, 1, 2, 4, 8, ... and
    /// the level's tile count (`s` = 0). What [`reserved_leaves_bound`] needs of the field,
    /// without a pass over the tiles per frame. Empty for level 0, which never splits.
    pub split_ranks: Vec<Vec<(u32, f32)>>,
}

pub(super) const QUAD: [(u32, u32); 4] = [(0, 0), (1, 0), (0, 1), (1, 1)];

impl SplitField {
    /// The field for `key` from `levels`, which must hold their field cells' errors
    /// ([`Levels::holds_field_errors`]; a renderer restores them before a new key).
    pub fn new(levels: &Levels, key: FieldKey) -> Self {
        assert!(
            levels.holds_field_errors(),
            "SplitField::new: the levels' field cell errors were released"
        );
        let cap = key.field_max.max(1.0);
        let zone = zone_widths(levels, &key);
        let mut field = SplitField {
            key,
            split: vec![UDLOD_NO_SPLIT; UDLOD_MAX_LEVELS as usize],
            zone,
            // Every level's nodes, allocated once (the field is the largest array UDLOD
            // builds); the levels below are read from them as the GPU evaluates them.
            corners: Vec::with_capacity(levels.field_nodes()),
            corner_offsets: Vec::new(),
            split_ranks: Vec::new(),
        };
        for lod in 0..=levels.root_lod {
            field.corner_offsets.push(field.corners.len() as u32);
            if lod == 0 {
                // Level 0 never splits: its field is 1 everywhere and not stored.
                field.split[0] = 0.0;
                continue;
            }
            field.build_level(levels, lod, cap);
        }
        field.split_ranks = (0..=levels.root_lod)
            .map(|lod| match lod {
                0 => Vec::new(),
                _ => field.ranks_of_level(levels, lod),
            })
            .collect();
        field
    }

    /// Builds level `lod`'s nodes (the levels below built): each node's split distance `s`,
    /// the largest requirement of the cells around it ([`cell_requirement`]), the gentle morph
    /// with the cascade, then its field value `D / s` clamped to `[1, cap]`.
    fn build_level(&mut self, levels: &Levels, lod: u32, cap: f64) {
        let (nx, ny) = levels.field_cells_per_side(lod);
        let cw = nx as usize + 1;
        // The level's nodes hold their split distances `s` first (f32: the chain's margin
        // covers the rounding), then their field values: no second array of the level.
        let offset = self.corners.len();
        self.corners.resize(offset + cw * (ny as usize + 1), 0.0);
        for cy in 0..ny {
            for cx in 0..nx {
                let need = cell_requirement(levels, self, [cx, cy, lod]) as f32;
                for (i, j) in QUAD {
                    let s = &mut self.corners[offset + (cy + j) as usize * cw + (cx + i) as usize];
                    *s = s.max(need);
                }
            }
        }
        let s = &mut self.corners[offset..];
        if self.key.morph_levels > 1 {
            gentle_morph(levels, lod, s);
        }
        // A level whose tiles need nothing (flat data) keeps a tiny positive distance.
        let largest = s
            .iter()
            .map(|&v| v as f64)
            .fold(1e-3 * levels.spacing, f64::max) as f32;
        self.split[lod as usize] = largest;
        let floor = largest as f64 / cap;
        for v in s {
            *v = ((largest as f64 / (*v as f64).max(floor)) as f32).clamp(1.0, cap as f32);
        }
    }

    /// The `(k, s)` pairs of [`Self::split_ranks`] for one level.
    fn ranks_of_level(&self, levels: &Levels, lod: u32) -> Vec<(u32, f32)> {
        let (nx, ny) = levels.tiles_per_side[lod as usize];
        let mut splits: Vec<f32> = (0..ny)
            .flat_map(|y| (0..nx).map(move |x| Tile { x, y, lod }))
            .map(|t| self.tile_split(levels, t) as f32)
            .collect();
        splits.sort_by(|a, b| b.total_cmp(a));
        let n = splits.len();
        let mut ranks: Vec<(u32, f32)> =
            std::iter::successors(Some(0usize), |k| Some((2 * k).max(1)))
                .take_while(|&k| k < n)
                .map(|k| (k as u32, splits[k]))
                .collect();
        ranks.push((n as u32, 0.0));
        ranks
    }

    fn corner(&self, levels: &Levels, lod: u32, i: u32, j: u32) -> f32 {
        if lod == 0 {
            return 1.0;
        }
        let (nx, _) = levels.field_cells_per_side(lod);
        self.corners[(self.corner_offsets[lod as usize] + j * (nx + 1) + i) as usize]
    }

    /// (min, max) of the field over a tile: its `(field_density + 1)^2` nodes (mirrors
    /// `tile_field_min` in `udlod_common.wgsl`).
    pub fn tile_range(&self, levels: &Levels, t: Tile) -> [f32; 2] {
        let d = levels.field_density;
        let mut range = [f32::INFINITY, f32::NEG_INFINITY];
        for j in 0..=d {
            for i in 0..=d {
                let c = self.corner(levels, t.lod, t.x * d + i, t.y * d + j);
                range = [range[0].min(c), range[1].max(c)];
            }
        }
        range
    }

    /// A tile's split distance: the largest of its corners' (`D / m_min`).
    pub fn tile_split(&self, levels: &Levels, t: Tile) -> f64 {
        self.split[t.lod as usize] as f64 / self.tile_range(levels, t)[0] as f64
    }

    /// The largest split distance, as the GPU evaluates it (`D / m` at the nodes), of the
    /// field cells of level `lod` (below `cl`, built) under field cell `[cx, cy, cl]`: `D`
    /// over the least node of their `(2^(cl - lod) + 1)^2` nodes. 0 at level 0, which never
    /// splits.
    fn largest_below(&self, levels: &Levels, [cx, cy, cl]: [u32; 3], lod: u32) -> f64 {
        let k = cl - lod;
        let (nx, ny) = levels.field_cells_per_side(lod);
        let (x0, y0) = (cx << k, cy << k);
        if lod == 0 || x0 >= nx || y0 >= ny {
            return 0.0;
        }
        let (x1, y1) = (((cx + 1) << k).min(nx), ((cy + 1) << k).min(ny));
        let least = (y0..=y1)
            .flat_map(|j| (x0..=x1).map(move |i| (i, j)))
            .map(|(i, j)| self.corner(levels, lod, i, j))
            .fold(f32::INFINITY, f32::min);
        self.split[lod as usize] as f64 / least as f64
    }

    /// The field of level `lod` at integer sample `sample` (mirrors `field_at` in
    /// `udlod_common.wgsl`): bilinear in the level's tile cell, clamped to the cell's corner
    /// range so rounding never leaves it; 1 past the root level.
    pub fn at(&self, levels: &Levels, sample: [i32; 2], lod: u32) -> f32 {
        if lod > levels.root_lod {
            return 1.0;
        }
        let ([i, j], f) = field_cell_of(levels, sample, lod);
        bilinear_in_range(QUAD.map(|(a, b)| self.corner(levels, lod, i + a, j + b)), f)
    }
}

/// The field cell of level `lod` holding integer sample `sample` (clamped to the level's
/// cells) and the sample's fraction across it.
pub(super) fn field_cell_of(levels: &Levels, sample: [i32; 2], lod: u32) -> ([u32; 2], [f32; 2]) {
    let span = (levels.field_cell_quads() << lod) as i32;
    let (nx, ny) = levels.field_cells_per_side(lod);
    let cx = (sample[0] / span).clamp(0, nx as i32 - 1);
    let cy = (sample[1] / span).clamp(0, ny as i32 - 1);
    let fx = (sample[0] - cx * span) as f32 / span as f32;
    let fy = (sample[1] - cy * span) as f32 / span as f32;
    ([cx as u32, cy as u32], [fx, fy])
}

/// Bilinear in a cell's corners `c` (ordered as [`QUAD`]) at fraction `f`, clamped to the
/// corners' range so rounding never leaves it.
pub(super) fn bilinear_in_range(c: [f32; 4], [fx, fy]: [f32; 2]) -> f32 {
    let south = c[0] * (1.0 - fx) + c[1] * fx;
    let north = c[2] * (1.0 - fx) + c[3] * fx;
    let v = south * (1.0 - fy) + north * fy;
    v.clamp(
        c[0].min(c[1]).min(c[2].min(c[3])),
        c[0].max(c[1]).max(c[2].max(c[3])),
    )
}

/// The smallest split distance field cell `[x, y, level]` (level >= 1; the tile with one
/// node per tile corner) allows at its corners, in the terms below (`field`: the field built
/// up to the level below, whose cells' split distances it reads as the GPU evaluates them):
/// - its own error at the pixel target;
/// - nesting: no less than any child's, so a point's split distance never falls from one level
///   to the next and an unsplit tile's neighbours are fully morphed onto it through every level
///   between (`docs/udlod.md`, "The morph cascade");
/// - reach: with `q` = `key.morph_levels` (at most [`cascade_levels`]), every point of a
///   descendant `G` of level `l - q` that splits is nearer than `S_G + diagonal(l - q)`, and
///   this tile's morph zone (`zone`) starts beyond that, so the vertices of `G`'s
///   children never morph at level `l - 1`: a level-`a` tile's vertices move at levels `a` to
///   `a + q - 1` only, which keeps them inside the tile (its culling box stays true), and
///   neighbours differ by at most `q` levels. With `q = 1` this is the CDLOD-style chain
///   UDLOD had before the cascade (`(1 - r) s_Q >= S_P + diagonal(l - 1)` over the children);
/// - or, with walks past the tile (`morph_levels = 0`, [`MORPH_LEVELS_ALL`]), separation: this
///   tile's morph zone starts beyond `S_G` of every descendant `G` of level `l - 2`
///   ([`SEPARATION_LEVELS`]), no diagonal: wherever level `l - 1` morphs, level `l - 3` has
///   morphed fully, so at most two successive levels morph at a point and no walk folds
///   (`docs/udlod.md`, "Walks past the tile"). Vertices then leave their tile; culling boxes
///   grow with them ([`tile_reach`]).
fn cell_requirement(levels: &Levels, field: &SplitField, cell: [u32; 3]) -> f64 {
    cell_terms(levels, field, cell).requirement()
}

/// The terms of [`cell_requirement`], each a split distance in metres.
#[derive(Clone, Copy, Debug)]
pub(super) struct CellTerms {
    /// The cell's own error at the pixel target.
    pub(super) pixel: f64,
    /// Where its morph zone `W` wide may start ([`zone_start`]) plus `W`.
    pub(super) zone: f64,
    nesting: f64,
    /// The reach over `q` levels, or with walks past the tile the separation over two.
    pub(super) separation: f64,
}

impl CellTerms {
    fn requirement(&self) -> f64 {
        let chain = self.nesting.max(self.separation) * (1.0 + CHAIN_MARGIN);
        self.pixel.max(self.zone).max(chain)
    }

    /// The term that sets the requirement (ties go to the earlier of pixel, zone, nesting).
    fn setting(&self) -> FieldTerm {
        let r = self.requirement();
        if r == self.pixel {
            FieldTerm::Pixel
        } else if r == self.zone {
            FieldTerm::Zone
        } else if self.nesting >= self.separation {
            FieldTerm::Nesting
        } else {
            FieldTerm::Separation
        }
    }
}

pub(super) fn cell_terms(
    levels: &Levels,
    field: &SplitField,
    [cx, cy, lod]: [u32; 3],
) -> CellTerms {
    let (key, zone) = (&field.key, &field.zone);
    let pixel = key.share * levels.field_cell_error(lod, cx, cy) as f64 * key.focal_px / key.tau_px;
    // This tile's geometry shows, blended, from the start of its morph zone on; where the zone
    // is `W` wide it starts no nearer than what the children's own geometry allows.
    let start = zone_start(levels, key, [cx, cy, lod], pixel);
    // The least `s` whose zone starts at or beyond `b`: `s - width >= b`.
    let w = zone[lod as usize] as f64;
    let past = |b: f64| match key.zone_rule {
        ZoneRule::Width => b + w,
        ZoneRule::ErrorScaled => {
            // `s - W E / s >= b` where `E < s`: `s^2 - b s - W E >= 0`.
            let e = pixel.max(children_pixel(levels, key, [cx, cy, lod]));
            (b + w).min((b + (b * b + 4.0 * w * e).sqrt()) / 2.0)
        }
        ZoneRule::Free => b,
    };
    let nesting = field.largest_below(levels, [cx, cy, lod], lod - 1);
    let (back, diagonal) = match key.morph_levels {
        MORPH_LEVELS_ALL => (SEPARATION_LEVELS, false),
        q => (q, true),
    };
    let separation = match lod.checked_sub(back) {
        Some(level) if level >= 1 => {
            // Where the zone is `max(W, r s)`: `s - max(W, r s) >= beyond`. The tiles of
            // level `lod - back` under a field cell are its cells of that level, whole.
            let mut beyond = field.largest_below(levels, [cx, cy, lod], level);
            if diagonal {
                beyond += levels.tile_diagonal(level);
            }
            (beyond / (1.0 - key.morph_range)).max(past(beyond))
        }
        _ => 0.0,
    };
    CellTerms {
        pixel,
        zone: past(start),
        nesting,
        separation,
    }
}

/// A term of the split field's requirement per cell (`cell_requirement`): the pixel target,
/// the morph zone's width past its start, nesting, and the reach (bounded walks) or separation.
/// Its discriminant indexes [`FieldTermCounts::cells`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldTerm {
    Pixel,
    Zone,
    Nesting,
    Separation,
}

impl FieldTerm {
    pub const ALL: [FieldTerm; 4] = [Self::Pixel, Self::Zone, Self::Nesting, Self::Separation];

    pub fn name(self) -> &'static str {
        match self {
            Self::Pixel => "pixel",
            Self::Zone => "zone",
            Self::Nesting => "nesting",
            Self::Separation => "separation",
        }
    }
}

/// Per level of `field` (index = level, 0 empty): how many field cells each [`FieldTerm`]
/// sets (indexed as [`FieldTerm::ALL`]), and how many of the level's corners the gentle
/// morph or the field's cap raised above every adjacent cell's requirement. Where the
/// triangles go at large tau (`examples/udlod_budget.rs`; `docs/udlod.md`, "What sets the
/// field").
pub fn field_terms(levels: &Levels, field: &SplitField) -> Vec<FieldTermCounts> {
    let mut out = vec![FieldTermCounts::default(); levels.root_lod as usize + 1];
    for lod in 1..=levels.root_lod {
        let (nx, ny) = levels.field_cells_per_side(lod);
        let cw = nx as usize + 1;
        let mut corner_need = vec![0.0f64; cw * (ny as usize + 1)];
        let counts = &mut out[lod as usize];
        for (cx, cy) in (0..ny).flat_map(|y| (0..nx).map(move |x| (x, y))) {
            let terms = cell_terms(levels, field, [cx, cy, lod]);
            counts.cells[terms.setting() as usize] += 1;
            for (i, j) in QUAD {
                let c = &mut corner_need[(cy + j) as usize * cw + (cx + i) as usize];
                *c = c.max(terms.requirement());
            }
        }
        for (k, need) in corner_need.iter().enumerate() {
            let (i, j) = ((k % cw) as u32, (k / cw) as u32);
            let s = field.split[lod as usize] as f64 / field.corner(levels, lod, i, j) as f64;
            counts.corners += 1;
            // f32 storage and the division: a relative 1e-5 is rounding, not a raise.
            counts.corners_raised += (s > *need * (1.0 + 1e-5) + 1e-6) as u32;
        }
    }
    out
}

/// One level's line of [`field_terms`].
#[derive(Clone, Copy, Debug, Default)]
pub struct FieldTermCounts {
    pub cells: [u32; 4],
    pub corners: u32,
    pub corners_raised: u32,
}

/// The nearest distance at which a morph zone `W` wide of field cell `[cx, cy, lod]` may
/// start, given its pixel term `screen`. In the zone the cell's children's vertices slide onto
/// its grid, so the surface there is a blend `(1 - f) children + f cell` whose error is at
/// most `(1 - f) e_c + f e` (`e_c`: the children's largest error), linear in the distance as
/// `f` and the pixel target `tau d / (k focal)` are. It meets the target at the zone's end
/// (`f = 1`, `s >= screen`) and at its start (`f = 0`) where that start is no nearer than the
/// children's own pixel term: between, too. The children's term is taken where it is the
/// nearer start; elsewhere (a child nearly as rough as the cell) `(1 - r) screen`, where one
/// level step starts its zone, which the share was measured with (`docs/udlod.md`, "The zone's
/// start", issue 18's fourteenth round). Level 1's children are level 0's: no error.
fn zone_start(levels: &Levels, key: &FieldKey, [cx, cy, lod]: [u32; 3], screen: f64) -> f64 {
    if lod < 2 {
        return 0.0;
    }
    let one_step = (1.0 - key.morph_range) * screen;
    one_step.min(children_pixel(levels, key, [cx, cy, lod]))
}

/// The largest pixel term of field cell `[cx, cy, lod]`'s children (level `lod - 1`; 0 for
/// level 1, whose children are level 0's exact samples).
fn children_pixel(levels: &Levels, key: &FieldKey, [cx, cy, lod]: [u32; 3]) -> f64 {
    if lod < 2 {
        return 0.0;
    }
    let (nx, ny) = levels.field_cells_per_side(lod - 1);
    let children = QUAD
        .iter()
        .map(|&(i, j)| (2 * cx + i, 2 * cy + j))
        .filter(|&(x, y)| x < nx && y < ny)
        .map(|(x, y)| levels.field_cell_error(lod - 1, x, y) as f64)
        .fold(0.0, f64::max);
    key.share * children * key.focal_px / key.tau_px
}

/// Levels below a tile whose split distances its morph zone starts beyond, with walks past
/// the tile ([`cell_requirement`]'s separation). A vertex odd at level `i` next to a corner
/// sliding at level `i + 2` stays on its side of it only if `1 + f_i + 2 f_i f_(i+1) >=
/// 4 f_(i+2)`: with equal split distances at the three levels and zones doubling per level
/// that fails everywhere in the zone (a fold); with level `i` fully morphed wherever `i + 2`
/// moves it reduces to `f_(i+1) >= 2 f_(i+2) - 1`, which zones doubling per level give.
const SEPARATION_LEVELS: u32 = 2;

/// Growth of the split distance allowed from one field corner to the next (8-neighbourhood):
/// see [`gentle_morph`]. 2; with 1.5 (until issue 18's fifth round) the cascade drew 0-7 %
/// more triangles on the data sets and 12-16 % more on half-rough terrain, with no fold under
/// either ratio in the fold runs (docs/udlod-rounds.md, "The morph cascade").
const FIELD_STEP_RATIO: f64 = 2.0;

/// Grid steps of the level below that the morph zone spans at least, with the morph cascade.
const ZONE_STEPS: f64 = 4.0;

/// `W[l]` per level ([`SplitField::zone`]): with the morph cascade [`ZONE_STEPS`] grid steps
/// (quad diagonals) of level `l - 1`, so the morph factor changes by at most `1 / ZONE_STEPS`
/// per step from the distance; 0 with one level step.
fn zone_widths(levels: &Levels, key: &FieldKey) -> Vec<f32> {
    let mut zone = vec![0.0f32; UDLOD_MAX_LEVELS as usize];
    if key.morph_levels > 1 {
        for lod in 1..=levels.root_lod {
            let step = levels.tile_diagonal(lod - 1) / levels.grid_size as f64;
            zone[lod as usize] = (ZONE_STEPS * step) as f32;
        }
    }
    zone
}

/// Keeps the morph of level `lod - 1`'s grid points gentle across the grid (`docs/udlod.md`,
/// "The morph cascade"): where the morph factor jumps from 0 to 1 between neighbouring
/// vertices, their triangles fold over (single pixels far off the surface, measured on
/// SRTM1). The distance's share of that is bounded by the zone's least width
/// ([`zone_widths`]); the field's by this floor on the corner split distances `s` of level
/// `lod`: a corner's distance is at least its neighbour's over [`FIELD_STEP_RATIO`] (a
/// chamfer pass each way: the largest `s(c') / ratio^steps(c, c')`), so over a tile's
/// `2 grid_size` steps of the level below the zone's end moves by at most
/// `(ratio - 1) s` against a zone of at least `r s`: with the distance's `1 / ZONE_STEPS`,
/// at most `0.25 + 1 / (2 grid_size r)` (0.875 at grid 4) per step, under the full slide.
/// Applied only with `morph_levels > 1`, so one level step keeps the selection it had.
pub(super) fn gentle_morph(levels: &Levels, lod: u32, s: &mut [f32]) {
    let (nx, ny) = levels.field_cells_per_side(lod);
    // The same growth per grid step wherever the nodes are: `d` nodes per tile side share
    // the tile's growth.
    let ratio = 1.0 + (FIELD_STEP_RATIO - 1.0) / levels.field_density as f64;
    let (w, h) = (nx as usize + 1, ny as usize + 1);
    let pass = |s: &mut [f32], order: &mut dyn Iterator<Item = usize>, back: bool| {
        for k in order {
            let (x, y) = ((k % w) as i64, (k / w) as i64);
            let dy = if back { 1 } else { -1 };
            for (ox, oy) in [(-1, 0), (1, 0), (-1, dy), (0, dy), (1, dy)] {
                let (sx, sy) = (x + ox, y + oy);
                let visited_row = oy != 0 || (if back { ox > 0 } else { ox < 0 });
                if visited_row && sx >= 0 && sy >= 0 && (sx as usize) < w && (sy as usize) < h {
                    let n = (s[sy as usize * w + sx as usize] as f64 / ratio) as f32;
                    if n > s[k] {
                        s[k] = n;
                    }
                }
            }
        }
    };
    pass(s, &mut (0..w * h), false);
    pass(s, &mut (0..w * h).rev(), true);
}

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
    /// ([`quadrants_culled`]).
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

/// Distance from the LOD viewer to the nearest point of the tile's rectangle at the reference
/// height, in the LOD metric (grid-frame offsets times [`SelectionParams::stretch`]).
pub fn tile_distance(levels: &Levels, p: &SelectionParams, t: Tile) -> f32 {
    let span = (levels.grid_size << t.lod) as i32;
    let [x, y] = [t.x as i32 * span, t.y as i32 * span];
    rect_distance(p, [x, y], [x + span, y + span])
}

/// Distance from the LOD viewer to the nearest point of the grid rectangle from sample `c0`
/// to sample `c1` at the reference height, in the LOD metric ([`tile_distance`] for any
/// rectangle).
pub fn rect_distance(p: &SelectionParams, c0: [i32; 2], c1: [i32; 2]) -> f32 {
    let lo = p.from_viewer(c0);
    let hi = p.from_viewer(c1);
    let dx = lo[0].max(0.0f32.min(hi[0])) * p.stretch[0];
    let dy = lo[1].max(0.0f32.min(hi[1])) * p.stretch[1];
    Vec3::new(dx, dy, p.viewer[2]).length()
}

/// Does the tile split? Its smallest scaled distance (field minimum x distance) against the
/// level's split distance, i.e. its nearest point against the largest split distance of its
/// corners (`refine` in `udlod_tiling.wgsl`).
pub fn tile_splits(levels: &Levels, p: &SelectionParams, t: Tile) -> bool {
    let field_min = p.field.tile_range(levels, t)[0];
    t.lod > 0 && field_min * tile_distance(levels, p, t) < p.field.split[t.lod as usize]
}

/// Is the tile's box outside the frustum? The box is the rectangle its morphed vertices can
/// reach ([`tile_reach`]), clamped to the data, by the heights of the tile that holds it; on
/// the earth the curved box over it ([`EarthCull::outside`], in f64: it decides as the GPU's
/// f32 `earth_box` except within the GPU's rounding of the boundary; tests/udlod.rs
/// brackets it). `decided` (`reach_box`, `box_outside`) in `shaders/udlod_tiling.wgsl`.
pub fn tile_culled(levels: &Levels, p: &SelectionParams, t: Tile) -> bool {
    tile_visibility(levels, p, t) == Visibility::Culled
}

/// Where a tile's box lies against the frustum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Visibility {
    /// Outside a plane by more than the margin ([`tile_culled`]).
    Culled,
    /// Across a plane.
    Crossing,
    /// Inside every plane ([`tile_inside`]).
    Inside,
}

/// [`tile_culled`] and [`tile_inside`] from one box (`decided` in `udlod_tiling.wgsl` builds
/// it once too).
pub fn tile_visibility(levels: &Levels, p: &SelectionParams, t: Tile) -> Visibility {
    let span = (levels.grid_size << t.lod) as i32;
    rect_visibility(levels, p, tile_reach(levels, p, t), span)
}

/// The quadrants (bits `1 << q`, [`super::grid`]) of final tile `t` whose box lies outside the
/// frustum: drawn as nothing (docs/udlod-rounds.md, "Quadrants outside the view"). Each box is
/// [`tile_culled`]'s for the quadrant's rectangle ([`quadrant_reach`]); none without culling
/// or with `cull_quadrants` off. `quadrant_square` and `reach_culled` in `shaders/udlod_tiling.wgsl`.
pub fn quadrants_culled(levels: &Levels, p: &SelectionParams, t: Tile) -> u32 {
    if !(p.cull && p.cull_quadrants) || tile_inside(levels, p, t) {
        return 0;
    }
    (0..4)
        .filter(|&q| quadrant_culled(levels, p, t, q))
        .fold(0, |bits, q| bits | 1 << q)
}

/// Quadrant `q` of final tile `t` tested on its own ([`quadrants_culled`] without the
/// shortcut of [`tile_inside`]).
pub fn quadrant_culled(levels: &Levels, p: &SelectionParams, t: Tile, q: u32) -> bool {
    let half = (levels.grid_size << t.lod) as i32 / 2;
    rect_visibility(levels, p, quadrant_reach(levels, p, t, q), half) == Visibility::Culled
}

/// The box of `reach` (its rectangle x the heights of the tile holding it) against the
/// frustum: culled when outside a plane by more than a margin of 1e-3 of `span` samples (the
/// rectangle's side before its walks; it keeps rounding from culling a touching box), else
/// inside or crossing.
fn rect_visibility(
    levels: &Levels,
    p: &SelectionParams,
    reach: TileReach,
    span: i32,
) -> Visibility {
    let (c0, c1) = (reach.lo, reach.hi);
    let heights = levels.tile_min_max(reach.heights);
    let margin = 1e-3 * (span as f32 * p.spacing);
    let (outside, inside) = match &p.earth {
        Some(earth) => earth.visibility(&p.frustum, c0, c1, heights, margin as f64),
        None => {
            let outside = flat_box_outside(p, c0, c1, heights, margin);
            (outside, !outside && flat_box_inside(p, c0, c1, heights))
        }
    };
    match (outside, inside) {
        (true, _) => Visibility::Culled,
        (false, true) => Visibility::Inside,
        (false, false) => Visibility::Crossing,
    }
}

/// Does tile `t`'s box ([`tile_culled`]'s) lie inside every plane of the frustum? Then no
/// quadrant of it is culled, so [`quadrants_culled`] tests none, as the prepass does
/// (`UDLOD_TILE_INSIDE`, set by `decided` in `shaders/udlod_tiling.wgsl` and
/// [`super::seed::decided`]). Why none is: every morphed vertex of a quadrant lies in the
/// quadrant's box (what makes its test sound) and in the tile's, so inside the frustum; a box
/// holding a point inside every plane is outside none. (The flat world's quadrant boxes also
/// lie within the tile's; the earth's need not, each being grown by its own curvature.)
pub fn tile_inside(levels: &Levels, p: &SelectionParams, t: Tile) -> bool {
    tile_visibility(levels, p, t) == Visibility::Inside
}

/// Is the box over the grid rectangle from sample `c0` to `c1`, `heights` (min, max) high,
/// inside every plane of the frustum (its corner nearest each plane's back side on or in front
/// of it)? `box_inside` in `shaders/include/terrain_common.wgsl`.
pub fn flat_box_inside(p: &SelectionParams, c0: [i32; 2], c1: [i32; 2], heights: [f32; 2]) -> bool {
    plane_distances(p, c0, c1, heights, Corner::Back).all(|d| d >= 0.0)
}

/// Is the box over the grid rectangle from sample `c0` to `c1`, `heights` (min, max) high, more
/// than `margin` metres outside a plane of the frustum? The flat world's test of
/// [`tile_culled`].
pub fn flat_box_outside(
    p: &SelectionParams,
    c0: [i32; 2],
    c1: [i32; 2],
    heights: [f32; 2],
    margin: f32,
) -> bool {
    plane_distances(p, c0, c1, heights, Corner::Front).any(|d| d < -margin)
}

/// Which corner of a box [`plane_distances`] measures: the one furthest along each plane's
/// normal, or the one furthest against it.
#[derive(Clone, Copy, PartialEq)]
enum Corner {
    Front,
    Back,
}

/// Per frustum plane, the signed distance of the flat box's `corner` (the arithmetic of
/// `box_outside` and `box_inside` in `shaders/include/terrain_common.wgsl`).
fn plane_distances(
    p: &SelectionParams,
    c0: [i32; 2],
    c1: [i32; 2],
    [zmin, zmax]: [f32; 2],
    corner: Corner,
) -> impl Iterator<Item = f32> + '_ {
    let lo = p.relative(c0);
    let hi = p.relative(c1);
    let (zlo, zhi) = (zmin - p.camera_z, zmax - p.camera_z);
    p.frustum.iter().map(move |pl| {
        let pick = |n: f32, low: f32, high: f32| {
            if (n >= 0.0) == (corner == Corner::Front) {
                high
            } else {
                low
            }
        };
        let (x, y, z) = (
            pick(pl[0], lo[0], hi[0]),
            pick(pl[1], lo[1], hi[1]),
            pick(pl[2], zlo, zhi),
        );
        pl[0] * x + pl[1] * y + pl[2] * z + pl[3]
    })
}

/// Where a tile's morphed vertices can lie ([`tile_reach`]): the rectangle of samples from `lo`
/// to `hi` (both included), and the tile whose statistics bound the heights there.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileReach {
    pub lo: [i32; 2],
    pub hi: [i32; 2],
    pub heights: Tile,
}

/// The rectangle a tile's morphed vertices can reach. A vertex's walk
/// ([`morph_cascade`]) only moves towards lower coordinates, and where it stays within the
/// tile's first `cascade_levels` levels it ends inside the tile; past them the point it has
/// reached is one of the tile's corners, whose own walk it then follows. So every vertex
/// (each a blend of its walk's points) lies between the lowest point of the corners' walks
/// ([`walk_end`]) and the tile's far corner. With a bounded walk (`morph_levels` at most
/// `cascade_levels`, the reach term of the split field) the corners never move and this is
/// the tile itself. The heights: those of the smallest tile, the tile or an ancestor, that
/// holds the rectangle (its samples bound every height sampled there). `tile_reach` in
/// `shaders/udlod_tiling.wgsl`.
pub fn tile_reach(levels: &Levels, p: &SelectionParams, t: Tile) -> TileReach {
    let span = (levels.grid_size << t.lod) as i32;
    rect_reach(levels, p, tile_origin(levels, t), span, t.lod, t)
}

/// The rectangle quadrant `q` of tile `t`'s morphed vertices can reach. A quadrant is a square
/// of `grid / 2 << lod` samples aligned to its side, so [`tile_reach`]'s argument holds for it
/// as for a tile: a walk inside it ends inside it or at one of its corners. Its heights: from
/// the tile of the level below that covers it (for a level-0 tile the tile itself). `rect_reach`
/// in `shaders/udlod_tiling.wgsl`.
pub fn quadrant_reach(levels: &Levels, p: &SelectionParams, t: Tile, q: u32) -> TileReach {
    let half = (levels.grid_size << t.lod) as i32 / 2;
    let o = tile_origin(levels, t);
    let (qx, qy) = (q & 1, q >> 1);
    let c0 = [o[0] + qx as i32 * half, o[1] + qy as i32 * half];
    // The quadrant's tile one level down, unless the tile is level 0 or that tile lies past
    // the data's edge (the quadrant's vertices are then clamped onto the edge).
    let below = Tile {
        x: 2 * t.x + qx,
        y: 2 * t.y + qy,
        lod: t.lod.saturating_sub(1),
    };
    let heights = if t.lod > 0 && levels.inside(below) {
        below
    } else {
        t
    };
    rect_reach(levels, p, c0, half, t.lod, heights)
}

fn tile_origin(levels: &Levels, t: Tile) -> [i32; 2] {
    let span = (levels.grid_size << t.lod) as i32;
    [t.x as i32 * span, t.y as i32 * span]
}

/// The reach of the square of `span` samples from `c0` whose grid points walk from level
/// `lod`, with the heights of the smallest tile from `heights` up that holds it.
fn rect_reach(
    levels: &Levels,
    p: &SelectionParams,
    c0: [i32; 2],
    span: i32,
    lod: u32,
    heights: Tile,
) -> TileReach {
    let (w, h) = (levels.width as i32 - 1, levels.height as i32 - 1);
    let hi = [(c0[0] + span).min(w), (c0[1] + span).min(h)];
    let lo = QUAD.iter().fold(c0, |lo, &(i, j)| {
        let corner = [c0[0] + i as i32 * span, c0[1] + j as i32 * span];
        let end = walk_end(levels, p, corner, lod);
        [lo[0].min(end[0]), lo[1].min(end[1])]
    });
    // A quadrant past the data's edge: its vertices are clamped onto the edge.
    let lo = [lo[0].min(hi[0]), lo[1].min(hi[1])];
    TileReach { lo, hi, heights }.with_heights_from(levels, heights)
}

impl TileReach {
    /// `heights`: `start` or the smallest of its ancestors whose rectangle holds `lo`.
    fn with_heights_from(mut self, levels: &Levels, start: Tile) -> Self {
        let mut heights = start;
        while heights.lod < levels.root_lod && {
            let side = (levels.grid_size << heights.lod) as i32;
            self.lo[0] < heights.x as i32 * side || self.lo[1] < heights.y as i32 * side
        } {
            heights = Tile {
                x: heights.x / 2,
                y: heights.y / 2,
                lod: heights.lod + 1,
            };
        }
        self.heights = heights;
        self
    }
}

/// One step of every morph walk: where grid point `point` slides at level `j`, its lower even
/// neighbour there (itself where it is even at `j`). `slid_at` in
/// `shaders/include/udlod_morph.wgsl`.
fn slid_at(point: [i32; 2], j: u32) -> [i32; 2] {
    point.map(|v| v - (((v as u32 >> j) & 1) as i32) * (1 << j))
}

/// The last point of grid point `sample`'s morph walk from level `lod`: [`morph_cascade`]'s
/// walk up, without the positions. Every point of the walk lies between it and `sample`.
/// `walk_on` in `shaders/include/udlod_morph.wgsl` (from the point's first odd level).
pub fn walk_end(levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> [i32; 2] {
    let mut point = sample;
    for j in lod..levels.root_lod {
        let odd = point.map(|v| ((v as u32 >> j) & 1) as i32);
        if odd == [0, 0] {
            continue;
        }
        if !morph_moves(levels, p, point, j) {
            break;
        }
        point = slid_at(point, j);
    }
    point
}

/// Whether [`morph_factor`] is not 0, without the fold's neighbour reads: the fold only lowers
/// a factor above 1/2 to one of at least 1/2, so the factor is 0 exactly where the ramp is not
/// above 0 or morphing is off. What the walks ask (`morph_moves` in
/// `shaders/include/udlod_morph.wgsl`; on Mesa 22.3, which runs every branch, the fold's
/// reads were two more ramps in each of the prepass's walk steps).
pub fn morph_moves(levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> bool {
    p.morph && morph_ramp(levels, p, sample, lod) > 0.0
}

/// The reference selection: the same decisions as the GPU's refine passes, without capacity
/// limits. Returns the final (drawn) tiles.
pub fn select_tiles(levels: &Levels, p: &SelectionParams) -> Vec<Tile> {
    let mut out = Vec::new();
    walk(levels, p, |t, splits| {
        if !splits {
            out.push(t);
        }
    });
    out
}

/// Final-list entries the refinement reserves for `p`: one root leaf, 3 more per split of a
/// tile the frustum keeps (`refine` in `udlod_tiling.wgsl`); what [`reserved_leaves_bound`]
/// bounds.
pub fn reserved_leaves(levels: &Levels, p: &SelectionParams) -> u64 {
    1 + 3 * splits_per_level(levels, p).iter().sum::<u64>()
}

/// The tiles of each level (index = level) that split for `p`.
pub fn splits_per_level(levels: &Levels, p: &SelectionParams) -> Vec<u64> {
    let mut splits = vec![0; levels.levels() as usize];
    walk(levels, p, |t, s| splits[t.lod as usize] += s as u64);
    splits
}

/// The refinement's walk from the root, level by level: `kept(tile, splits)` for every tile
/// on the data that the frustum keeps; the children of those that split are walked next.
fn walk(levels: &Levels, p: &SelectionParams, mut kept: impl FnMut(Tile, bool)) {
    let mut layer = vec![Tile {
        x: 0,
        y: 0,
        lod: levels.root_lod,
    }];
    while !layer.is_empty() {
        let mut next = Vec::new();
        for t in layer {
            if !levels.inside(t) || (p.cull && tile_culled(levels, p, t)) {
                continue;
            }
            let splits = tile_splits(levels, p, t);
            kept(t, splits);
            if splits {
                next.extend(QUAD.map(|(dx, dy)| Tile {
                    x: t.x * 2 + dx,
                    y: t.y * 2 + dy,
                    lod: t.lod - 1,
                }));
            }
        }
        layer = next;
    }
}

/// An upper bound, known before the prepass, on the final-list entries a selection with this
/// split field and LOD metric `stretch` reserves, wherever the viewer is and whatever the
/// frustum culls: the refinement starts from one root leaf and every split reserves 3 more
/// (`refine` in `udlod_tiling.wgsl`; `select_tiles` here). A tile splits only when its
/// nearest point is nearer than its split distance `s` (`m_min * d < D`, `m_min >= 1`, and
/// `d` at least the horizontal part of the distance, [`tile_distance`]). So for any `t`, the
/// tiles of a level that split are at most the `k(t)` ranked above `t` plus those within
/// `t` of the viewer, whose rectangles meet the ellipse of radius `t` in the stretched metric:
/// at most `floor(2 t / (stretch S)) + 2` tiles of side `S` metres along each axis (`t` taken
/// 1e-4 larger for the GPU's f32 rounding). The bound takes the best `t` among the field's
/// [`SplitField::split_ranks`]. Used to size the tile lists before each frame (`Udlod::update`).
pub fn reserved_leaves_bound(levels: &Levels, field: &SplitField, stretch: [f32; 2]) -> u64 {
    let splits: u64 = (1..=levels.root_lod)
        .map(|lod| level_splits_bound(levels, field, stretch, lod))
        .sum();
    1 + 3 * splits
}

/// [`reserved_leaves_bound`]'s bound on the tiles of level `lod` (>= 1) that split.
pub fn level_splits_bound(levels: &Levels, field: &SplitField, stretch: [f32; 2], lod: u32) -> u64 {
    let side = (levels.grid_size << lod) as f64 * levels.spacing;
    let (nx, ny) = levels.tiles_per_side[lod as usize];
    let near = |t: f32| {
        // 1e-4 wider: the GPU's f32 test may split a tile a rounding beyond `t`.
        let reach = 2.0 * t as f64 * (1.0 + 1e-4);
        let along = |s: f32, n: u32| {
            let s = (s as f64).max(f64::MIN_POSITIVE);
            ((reach / (s * side)).floor().min(n as f64) as u64 + 2).min(n as u64)
        };
        along(stretch[0], nx) * along(stretch[1], ny)
    };
    (field.split_ranks[lod as usize].iter())
        .map(|&(k, t)| k as u64 + near(t))
        .min()
        .unwrap_or(0)
}

/// Morph factor of grid point `sample` of level `lod` (0 = its own level's grid, 1 = fully on
/// the next level's grid; 0 everywhere with morphing off): the next level's scaled distance
/// against the last `morph_range` of its split distance, or with the morph cascade the last
/// `max(zone, morph_range s)` metres of the point's split distance `s`
/// ([`SplitField::zone`]). A pure function of the point and the
/// level, so vertices shared by tiles agree. `morph_factor` in
/// `shaders/include/udlod_morph.wgsl`, operation for operation.
pub fn morph_factor(levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> f32 {
    let on = if p.morph { 1.0 } else { 0.0 };
    let mut f = morph_ramp(levels, p, sample, lod).clamp(0.0, 1.0);
    // A point odd along both axes stays within `(1 + b) / 2`, `b` the smaller factor of its
    // neighbours at (1, 0) and (0, 1) of its block, or the triangle between the three turns
    // over (docs/udlod-rounds.md, "Folds at the quads' diagonal"). (The shader reads the two
    // neighbours in a loop from a least factor of 1: the same minimum of values in [0, 1].)
    if f > 0.5 && sample.map(|v| (v as u32 >> lod) & 1) == [1, 1] {
        let step = 1 << lod;
        let along_x = morph_ramp(levels, p, [sample[0], sample[1] - step], lod).clamp(0.0, 1.0);
        let along_y = morph_ramp(levels, p, [sample[0] - step, sample[1]], lod).clamp(0.0, 1.0);
        f = f.min(0.5 * (1.0 + along_x.min(along_y)));
    }
    f * on
}

/// [`morph_factor`] before its clamp to `[0, 1]` and the on/off switch (`morph_ramp` in
/// `shaders/include/udlod_morph.wgsl`): at least 1 where the point lies fully on the next
/// level's grid.
fn morph_ramp(levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> f32 {
    let d = viewer_distance(p, sample);
    let field = p.field.at(levels, sample, lod + 1);
    let parent_split = p.field.split[lod as usize + 1];
    let zone = p.field.zone[lod as usize + 1];
    if zone > 0.0 {
        return cascade_ramp(p, d, parent_split / field, zone);
    }
    let scaled = d * field;
    1.0 - (1.0 - scaled / parent_split) / p.morph_range
}

/// The LOD viewer's distance to integer sample `sample` in the LOD metric (at the reference
/// height), as the morph measures it.
pub(super) fn viewer_distance(p: &SelectionParams, sample: [i32; 2]) -> f32 {
    let rel = p.from_viewer(sample);
    Vec3::new(rel[0] * p.stretch[0], rel[1] * p.stretch[1], p.viewer[2]).length()
}

/// The morph cascade's ramp at distance `d` for a morph completing at `s` over a zone at
/// least `zone` wide: 1 at `s`, falling over the last `max(zone, morph_range s)`.
pub(super) fn cascade_ramp(p: &SelectionParams, d: f32, s: f32, zone: f32) -> f32 {
    let width = zone.max(p.morph_range * s);
    1.0 - (s - d) / width
}

/// Which quadrants of tile `t` are drawn as the parent's grid (bit `qx + 2 qy`,
/// [`super::grid`]): those whose grid vertices odd at the tile's level all lie fully on the
/// parent's grid (`final_tile_checks` in `shaders/udlod_tiling.wgsl`; `grid_size` must be
/// even). Their odd vertices coincide with even ones, so the quadrant's triangles are the
/// parent grid's over its even vertices (each parent quad's two, the same diagonal) and
/// degenerate ones (`docs/udlod.md`, "Collapsed quadrants"). At grid 2 a tile is drawn so only
/// when all four are ([`TileMask::new`]).
pub fn tile_collapse_mask(levels: &Levels, p: &SelectionParams, t: Tile) -> u32 {
    if !p.morph {
        return 0;
    }
    collapse_mask_by(levels, t, |sample| morph_ramp(levels, p, sample, t.lod))
}

/// [`tile_collapse_mask`] with the odd vertices' morph ramp given (`ramp` of a sample).
pub(super) fn collapse_mask_by(levels: &Levels, t: Tile, ramp: impl Fn([i32; 2]) -> f32) -> u32 {
    let g = levels.grid_size;
    let mut keeps = 0;
    for j in 0..=g {
        for i in (0..=g).filter(|i| (i | j) & 1 == 1) {
            let quadrants = super::grid::quadrants_of(g, [i, j]);
            if quadrants & !keeps != 0
                && ramp(tile_sample(levels, t, [i, j])) < 1.0 + UDLOD_COLLAPSE_MARGIN
            {
                keeps |= quadrants;
            }
        }
    }
    super::grid::ALL_QUADRANTS & !keeps
}

/// How final tile `t` is drawn: its quadrants on the parent grid ([`tile_collapse_mask`]) and
/// those outside the frustum ([`quadrants_culled`]) as one mask (`tile_mask` in
/// `shaders/udlod_tiling.wgsl`).
pub fn tile_mask(levels: &Levels, p: &SelectionParams, t: Tile) -> TileMask {
    let collapsing = tile_collapse_mask(levels, p, t);
    TileMask::new(levels.grid_size, collapsing, quadrants_culled(levels, p, t))
}

/// How a grid point moved in [`morph_cascade`] (`MORPH_*` and `morph_moved` in
/// `shaders/include/udlod_morph.wgsl`, which the prepass's back-face split asks of every vertex).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Moved {
    /// Not at all.
    Still,
    /// Fully onto the parent grid at the tile's own level, and no further: the tile's
    /// triangles stay the parent grid's (or degenerate).
    OneLevel,
    /// Part-way, or on through further levels: sliver triangles possible (the prepass's
    /// `final_tile_checks` draws the tile without back-face culling).
    Slivers,
}

/// A grid point after the morph cascade (`Cascade` in `shaders/include/udlod_morph.wgsl`):
/// an integer cell plus a fraction, not yet folded or clamped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cascade {
    pub cell: [i32; 2],
    pub frac: [f32; 2],
    /// The factor at the point's first odd level (0 if it reached none).
    pub morph: f32,
    /// How it moved (on the GPU its own walk, `morph_moved`).
    pub moved: Moved,
    /// Levels at which it moved (CPU only: tests count vertices morphing over several).
    pub levels: u32,
}

/// Where grid point `sample` of a level-`lod` tile ends up (`docs/udlod.md`, "The morph
/// cascade"): up, at every level `j` from `lod` on at which the point reached is odd, it has
/// the factor [`morph_factor`] there and slides towards its lower even neighbour, the next
/// point, until a factor of 0; down, the last point stays and each earlier one lies `1 - f` of
/// the way from where the next one ended up back towards itself. The CPU mirror of
/// `morph_cascade` in `shaders/include/udlod_morph.wgsl`, the same f32 and integer operations
/// in the same order.
pub fn morph_cascade(levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> Cascade {
    let mut c = Cascade {
        cell: sample,
        frac: [0.0; 2],
        morph: 0.0,
        moved: Moved::Still,
        levels: 0,
    };
    let mut walk: Vec<([i32; 2], f32)> = Vec::new();
    let mut point = sample;
    let mut first = true;
    for j in lod..levels.root_lod {
        let odd = point.map(|v| ((v as u32 >> j) & 1) as i32);
        if odd == [0, 0] {
            continue;
        }
        let f = morph_factor(levels, p, point, j);
        if first {
            c.morph = f;
            first = false;
        }
        if f == 0.0 {
            break;
        }
        c.moved = if c.moved == Moved::Still && j == lod && f == 1.0 {
            Moved::OneLevel
        } else {
            Moved::Slivers
        };
        walk.push((point, f));
        point = slid_at(point, j);
    }
    c.levels = walk.len() as u32;
    c.cell = point;
    for &(from, f) in walk.iter().rev() {
        if f < 1.0 {
            c.frac =
                [0, 1].map(|i| c.frac[i] + (1.0 - f) * ((from[i] - c.cell[i]) as f32 - c.frac[i]));
        }
    }
    c
}

/// Integer sample of vertex `local` of tile `t`: u32 arithmetic (wrapping), then the cast, as
/// the shaders do.
fn tile_sample(levels: &Levels, t: Tile, local: [u32; 2]) -> [i32; 2] {
    let step = 1u32 << t.lod;
    let tile = [t.x, t.y];
    std::array::from_fn(|i| {
        let origin = tile[i].wrapping_mul(levels.grid_size).wrapping_mul(step);
        origin.wrapping_add(local[i].wrapping_mul(step)) as i32
    })
}

/// A tile's grid vertex after morphing (`MorphedVertex` in `shaders/include/udlod_morph.wgsl`
/// without the height): an integer sample `cell` plus a fraction in `[0, 1)` per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MorphedVertex {
    pub cell: [i32; 2],
    pub frac: [f32; 2],
    /// The morph factor at the vertex's first odd level.
    pub morph: f32,
    /// Levels at which it moved (CPU only, [`Cascade::levels`]).
    pub levels: u32,
    /// How it moved (CPU only: tests check the prepass's back-face split against it).
    pub moved: Moved,
}

impl MorphedVertex {
    /// The position in samples as the shaders form it (`vec2<f32>(cell) + frac`).
    pub fn grid_pos(&self) -> [f32; 2] {
        [
            self.cell[0] as f32 + self.frac[0],
            self.cell[1] as f32 + self.frac[1],
        ]
    }
}

/// Where vertex `local` (column, row in the tile's grid) of tile `t` ends up after morphing:
/// the CPU mirror of `morphed_vertex` in `shaders/include/udlod_morph.wgsl`, the same f32 and
/// integer operations in the same order ([`morph_cascade`], whole samples folded from the
/// fraction into the cell, clamped at the data's last sample). `tests/udlod.rs` proves it
/// equal to the GPU's through the morph probe.
pub fn morphed_vertex(
    levels: &Levels,
    p: &SelectionParams,
    t: Tile,
    local: [u32; 2],
) -> MorphedVertex {
    let c = morph_cascade(levels, p, tile_sample(levels, t, local), t.lod);
    let last = [levels.width as i32 - 1, levels.height as i32 - 1];
    let mut cell = [0i32; 2];
    let mut frac = [0f32; 2];
    for i in 0..2 {
        let whole = c.frac[i].floor();
        let mut ce = c.cell[i] + whole as i32;
        let mut f = c.frac[i] - whole;
        f = f.min((last[i] - ce).max(0) as f32);
        ce = ce.min(last[i]);
        cell[i] = ce;
        frac[i] = f;
    }
    MorphedVertex {
        cell,
        frac,
        morph: c.morph,
        levels: c.levels,
        moved: c.moved,
    }
}

/// The 257² procedural terrain (60 m) the unit tests of this module and of `completion` build
/// their levels on.
#[cfg(test)]
pub(super) fn test_terrain() -> crate::dataset::Heightmap {
    use crate::dataset::procedural::{self, ProceduralParams};
    procedural::generate(&ProceduralParams {
        size: 257,
        spacing: 60.0,
        ..Default::default()
    })
    .unwrap()
}

/// Four cameras over [`test_terrain`], 150 m to 3 km up, looking down 20 degrees in four
/// headings.
#[cfg(test)]
pub(super) fn test_poses() -> [crate::scene::Camera; 4] {
    std::array::from_fn(|k| {
        let height = [150.0, 400.0, 1200.0, 3000.0][k];
        crate::scene::Camera {
            position: glam::DVec3::new(3000.0 + 2000.0 * k as f64, 4000.0, height),
            yaw_deg: 30.0 + 70.0 * k as f64,
            pitch_deg: -20.0,
            ..crate::scene::Camera::default()
        }
    })
}

#[cfg(test)]
mod tests {
    use super::{
        FieldKey, Levels, QUAD, SelectionParams, SplitField, UdlodSettings, ZoneRule, field_terms,
        morph_factor, morph_moves, morph_ramp, test_poses, test_terrain,
    };

    /// `morph_moves` answers `morph_factor != 0` at every grid point of every level of the
    /// test terrain from four poses, with morphing on and off; and the poses reach both
    /// answers, and factors the fold lowered. Negative controls by hand: `morph_moves` without `p.morph` fails (morphing off),
    /// and with `> 0.5` for `> 0.0` (a factor of 0.4994617 at level 0).
    #[test]
    fn morph_moves_is_a_nonzero_morph_factor() {
        let data = test_terrain();
        let (mut moving, mut still, mut folds) = (0u32, 0u32, 0u32);
        for morph in [true, false] {
            let settings = UdlodSettings {
                morph,
                ..UdlodSettings::default()
            };
            let levels = Levels::for_settings(&data, &settings).unwrap();
            for (k, cam) in test_poses().iter().enumerate() {
                let p =
                    SelectionParams::new(&levels, &data, &settings, cam, cam.position, 640, 360);
                for lod in 0..levels.root_lod {
                    let step = 1usize << lod;
                    for y in (0..levels.height as i32).step_by(step) {
                        for x in (0..levels.width as i32).step_by(step) {
                            let f = morph_factor(&levels, &p, [x, y], lod);
                            let moves = morph_moves(&levels, &p, [x, y], lod);
                            assert_eq!(
                                moves,
                                f != 0.0,
                                "morph {morph}, pose {k}, level {lod}, ({x}, {y}): factor {f}"
                            );
                            moving += moves as u32;
                            still += !moves as u32;
                            let ramp = morph_ramp(&levels, &p, [x, y], lod).clamp(0.0, 1.0);
                            folds += (morph && f < ramp) as u32;
                        }
                    }
                }
            }
        }
        assert!(
            moving > 0 && still > 0 && folds > 0,
            "moving {moving}, still {still}, lowered by the fold {folds}"
        );
    }

    /// Every field cell's morph zone (the last `max(W, r s)` of its split distance `s`) starts
    /// no nearer than its children's pixel term or one level step's start, whichever is
    /// nearer ([`super::zone_start`]: what keeps the blended surface in the zone within
    /// tau), at one and two nodes per tile side, tau 1 and 4; and some cells start nearer
    /// than one level step's start alone allowed (the rule before issue 18's fourteenth round:
    /// `s >= (1 - r) screen + W`). Negative control by hand: a zone start of 0 fails the first.
    #[test]
    fn morph_zones_start_where_the_children_meet_tau() {
        let data = test_terrain();
        for density in [1, 2] {
            let settings = UdlodSettings {
                field_density: density,
                ..UdlodSettings::default()
            };
            let levels = Levels::for_settings(&data, &settings).unwrap();
            for tau_px in [1.0, 4.0] {
                let key = FieldKey::new(&UdlodSettings { tau_px, ..settings }, 311.8);
                let field = SplitField::new(&levels, key);
                let pixel = |lod: u32, x: u32, y: u32| {
                    let (nx, ny) = levels.field_cells_per_side(lod);
                    let e = if x < nx && y < ny && lod > 0 {
                        levels.field_cell_error(lod, x, y) as f64
                    } else {
                        0.0
                    };
                    key.share * e * key.focal_px / key.tau_px
                };
                let mut nearer = 0;
                for lod in 2..=levels.root_lod {
                    let w = field.zone[lod as usize] as f64;
                    let (nx, ny) = levels.field_cells_per_side(lod);
                    for (cx, cy) in (0..ny).flat_map(|y| (0..nx).map(move |x| (x, y))) {
                        let screen = pixel(lod, cx, cy);
                        let children = QUAD
                            .map(|(i, j)| pixel(lod - 1, 2 * cx + i, 2 * cy + j))
                            .into_iter()
                            .fold(0.0, f64::max);
                        let largest_m = QUAD
                            .map(|(i, j)| field.corner(&levels, lod, cx + i, cy + j))
                            .into_iter()
                            .fold(0.0f32, f32::max);
                        let s = field.split[lod as usize] as f64 / largest_m as f64;
                        let start = s - w.max(key.morph_range * s);
                        let one_step = (1.0 - key.morph_range) * screen;
                        let needed = children.min(one_step);
                        assert!(
                            start >= needed * (1.0 - 1e-5),
                            "density {density}, tau {tau_px}, level {lod}, cell ({cx}, {cy}): \
                             zone starts at {start} m, children need {children} m, one level \
                             step {one_step} m"
                        );
                        nearer += (s < (one_step + w) * (1.0 - 1e-5)) as u32;
                    }
                }
                assert!(
                    nearer > 0,
                    "density {density}, tau {tau_px}: no zone starts nearer than one level step's"
                );
            }
        }
    }

    /// `field_terms` names the term that sets each field cell: at a pixel target so fine that
    /// the pixel term dwarfs every zone the cells' own errors set most of them (the rest:
    /// nesting, where a child is rougher than its parent), zone and separation none; at one so
    /// coarse that it asks for nothing the zone `W` sets levels 1-2 and the separation every
    /// level above (over flat needs `s_l = s_(l-2) + W_l` beats nesting's `s_(l-1)`). Negative
    /// control by hand: `CellTerms::setting` without its zone branch fails the second part
    /// (level 1's 1,024 cells put on nesting).
    #[test]
    fn field_terms_name_what_sets_each_cell() {
        let data = test_terrain();
        // One node per tile corner: with two per side (the default) the separation term sets
        // one of level 3's cells even at tau 1e-3 (a rough cell beside smooth ones).
        let settings = UdlodSettings {
            field_density: 1,
            ..UdlodSettings::default()
        };
        let levels = Levels::for_settings(&data, &settings).unwrap();
        let counts = |tau_px: f64| {
            let key = FieldKey::new(
                &UdlodSettings {
                    tau_px,
                    ..settings.clone()
                },
                311.8,
            );
            field_terms(&levels, &SplitField::new(&levels, key))
        };
        let [pixel, zone, _, separation] = [0, 1, 2, 3];
        for (lod, c) in counts(1e-3).iter().enumerate().skip(1) {
            let cells: u32 = c.cells.iter().sum();
            let (nx, ny) = levels.field_cells_per_side(lod as u32);
            assert_eq!(cells, nx * ny, "level {lod}: every cell counted once");
            assert!(
                c.cells[pixel] * 2 >= cells && c.cells[zone] + c.cells[separation] == 0,
                "tau 1e-3, level {lod}: cells set by pixel/zone/nesting/separation {:?}",
                c.cells
            );
            assert!(c.corners_raised <= c.corners);
        }
        for (lod, c) in counts(1e4).iter().enumerate().skip(1) {
            let cells: u32 = c.cells.iter().sum();
            let expected = if lod <= 2 { zone } else { separation };
            assert_eq!(
                c.cells[expected], cells,
                "tau 1e4, level {lod}: cells set by pixel/zone/nesting/separation {:?}",
                c.cells
            );
        }
    }

    /// The what-if zone rules only ever lower the field: at every corner of every level the
    /// split distance with `ErrorScaled` is at most the renderer's (`Width`) and with `Free` at
    /// most `ErrorScaled`'s, and each is lower somewhere (257² test terrain, tau 4, where the
    /// zone sets most cells). Negative control by hand: `max` for `min` in `ErrorScaled`'s
    /// solution (the renderer's field again) fails the last: no corner lower.
    #[test]
    fn what_if_zone_rules_only_lower_the_field() {
        let data = test_terrain();
        let settings = UdlodSettings {
            tau_px: 4.0,
            ..UdlodSettings::default()
        };
        let levels = Levels::for_settings(&data, &settings).unwrap();
        let distances = |zone_rule| {
            let key = FieldKey {
                zone_rule,
                ..FieldKey::new(&settings, 311.8)
            };
            let field = SplitField::new(&levels, key);
            let mut out = Vec::new();
            for lod in 1..=levels.root_lod {
                let (nx, ny) = levels.field_cells_per_side(lod);
                for (i, j) in (0..=ny).flat_map(|j| (0..=nx).map(move |i| (i, j))) {
                    let corner = field.corner(&levels, lod, i, j) as f64;
                    out.push(field.split[lod as usize] as f64 / corner);
                }
            }
            out
        };
        let width = distances(ZoneRule::Width);
        let scaled = distances(ZoneRule::ErrorScaled);
        let free = distances(ZoneRule::Free);
        let (mut lower_scaled, mut lower_free) = (0, 0);
        for ((w, e), f) in width.iter().zip(&scaled).zip(&free) {
            assert!(
                *e <= w * (1.0 + 1e-5),
                "error-scaled {e} m above width's {w} m"
            );
            assert!(
                *f <= e * (1.0 + 1e-5),
                "free {f} m above error-scaled {e} m"
            );
            lower_scaled += (*e < w * 0.99) as u32;
            lower_free += (*f < e * 0.99) as u32;
        }
        assert!(
            lower_scaled > 0 && lower_free > 0,
            "{lower_scaled} / {lower_free} corners lower"
        );
    }

    /// Released field cell errors come back bit for bit from the same statistics read again
    /// (the renderer's path for a new field key): the field built after the restore equals the
    /// one built before. Controls: released, the levels cannot build a field; another grid's
    /// cells are refused with a one-line error naming the nodes per tile side.
    #[test]
    fn released_field_errors_come_back_bit_for_bit() {
        let data = test_terrain();
        let settings = UdlodSettings::default();
        let d = settings.field_density();
        assert!(d > 1);
        let cells = |grid: u32| {
            let stats = crate::dataset::stats::TileStats::compute_serial(&data, grid).unwrap();
            crate::dataset::stats::FieldStats::from_cells(stats, d).unwrap()
        };
        let mut levels = Levels::from_field_stats(cells(settings.grid_size / d), data.spacing);
        let key = FieldKey::new(&settings, 311.8);
        let before = SplitField::new(&levels, key);
        levels.release_field_errors();
        assert!(!levels.holds_field_errors() && levels.field_error.is_empty());
        assert!(std::panic::catch_unwind(|| SplitField::new(&levels, key)).is_err());
        let wrong = levels
            .restore_field_errors(cells(settings.grid_size))
            .unwrap_err();
        assert!(
            wrong
                .to_string()
                .contains(&format!("({d} nodes per tile side)")),
            "{wrong}"
        );
        assert!(!levels.holds_field_errors());
        levels
            .restore_field_errors(cells(settings.grid_size / d))
            .unwrap();
        assert!(levels.holds_field_errors());
        let after = SplitField::new(&levels, key);
        assert_eq!(
            (before.split, before.zone, before.corners),
            (after.split, after.zone, after.corners)
        );
    }
}

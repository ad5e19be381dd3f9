//! The quadtree over one data set: its levels, per-tile min/max heights and geometric
//! errors (from the data set's statistics or computed from level 0), and the height of a
//! level's triangulated grid.

use super::settings::UdlodSettings;
use crate::dataset::Level0;
use crate::dataset::stats::{FieldStats, TileStats, level_interpolate};
use crate::error::{Error, Result};
use crate::geo::Lattice;

/// A quadtree tile: `(x, y)` in tiles of its level, `lod` 0 = full resolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Tile {
    pub x: u32,
    pub y: u32,
    pub lod: u32,
}

/// A tile's four children (or a cell's four corners) as offsets, in quadrant order `q = x + 2 y`
/// (as the shaders number quadrants).
pub(super) const QUAD: [(u32, u32); 4] = [(0, 0), (1, 0), (0, 1), (1, 1)];

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
    /// `density` nodes per tile side whose cells take `fine`'s errors (`docs/udlod-rounds.md`, "A
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

    /// Whether [`super::field::SplitField::new`] can build a field from these levels: the field's cells'
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

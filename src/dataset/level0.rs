//! Level-0 samples without holding level 0: the [`Level0`] trait (implemented by the in-memory
//! [`Heightmap`] and by [`PyramidReader`], which reads a tile pyramid's level-0 nodes through a
//! bounded LRU cache), and [`Terrain`], what the renderer is given: the whole grid (single-texture
//! path) or the pyramid (clipmap path: no array of level-0 size on the host).

use std::cell::RefCell;
use std::collections::HashMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};

use super::Heightmap;
use super::interp::GridCell;
use super::pyramid::{LayerSet, Layout, LevelRows, Node};
use super::stats::{FieldStats, Finest, TileStats};
use super::tiles::Dataset;
use super::tiles::LoadGrid;
use super::xyz::XyzPyramid;
use crate::error::{Error, Result};

/// Full-resolution (level-0) height samples, `(col, row)` at world `(col, row) * spacing`.
pub trait Level0 {
    fn width(&self) -> u32;
    fn height(&self) -> u32;
    /// Metres between neighbouring samples (x and y).
    fn spacing(&self) -> f64;
    /// Native level-0 samples of the data set per sample of this grid (`Heightmap::
    /// source_step`): `[1, 1]` unless loaded from a coarser level or resampled.
    fn source_step(&self) -> [f64; 2] {
        [1.0, 1.0]
    }
    /// Height of sample `(col, row)` in metres; an error for a position outside the grid or data
    /// that cannot be read.
    fn sample(&self, col: u32, row: u32) -> Result<f32>;

    /// Samples `col0..=col1` of `row` into `out` (replacing its contents).
    fn row(&self, row: u32, col0: u32, col1: u32, out: &mut Vec<f32>) -> Result<()> {
        out.clear();
        for c in col0..=col1 {
            out.push(self.sample(c, row)?);
        }
        Ok(())
    }

    /// World extent in metres `(x_max, y_max)`.
    fn extent(&self) -> (f64, f64) {
        (
            (self.width() - 1) as f64 * self.spacing(),
            (self.height() - 1) as f64 * self.spacing(),
        )
    }

    /// Bilinear height at a world position, clamped to the grid: the same arithmetic as
    /// [`Heightmap::height_at`] (bit for bit).
    fn bilinear(&self, x: f64, y: f64) -> Result<f64> {
        let (sx, sy) = (x / self.spacing(), y / self.spacing());
        GridCell::at(sx, sy, self.width(), self.height())
            .try_bilinear(|c, r| self.sample(c, r).map(f64::from))
    }

    /// Height of the full-resolution triangle mesh at a world position, clamped to the grid:
    /// the same arithmetic as [`Heightmap::mesh_height_at`] (bit for bit).
    fn mesh_height(&self, x: f64, y: f64) -> Result<f64> {
        let (w, h) = (self.width(), self.height());
        let gx = (x / self.spacing()).clamp(0.0, (w - 1) as f64);
        let gy = (y / self.spacing()).clamp(0.0, (h - 1) as f64);
        let (c0, r0) = (
            (gx.floor() as u32).min(w.saturating_sub(2)),
            (gy.floor() as u32).min(h.saturating_sub(2)),
        );
        let (c1, r1) = ((c0 + 1).min(w - 1), (r0 + 1).min(h - 1));
        let (fx, fy) = (gx - c0 as f64, gy - r0 as f64);
        let (h00, h10) = (self.sample(c0, r0)? as f64, self.sample(c1, r0)? as f64);
        let (h01, h11) = (self.sample(c0, r1)? as f64, self.sample(c1, r1)? as f64);
        Ok(if fx + fy <= 1.0 {
            h00 + (h10 - h00) * fx + (h01 - h00) * fy
        } else {
            h11 + (h01 - h11) * (1.0 - fx) + (h10 - h11) * (1.0 - fy)
        })
    }
}

impl Level0 for Heightmap {
    fn width(&self) -> u32 {
        self.width
    }
    fn height(&self) -> u32 {
        self.height
    }
    fn spacing(&self) -> f64 {
        self.spacing
    }
    fn source_step(&self) -> [f64; 2] {
        self.source_step
    }
    #[inline]
    fn sample(&self, col: u32, row: u32) -> Result<f32> {
        if col >= self.width || row >= self.height {
            return Err(out_of_range(col, row, self.width, self.height));
        }
        Ok(Heightmap::sample(self, col, row))
    }
    fn bilinear(&self, x: f64, y: f64) -> Result<f64> {
        Ok(self.height_at(x, y))
    }
    fn row(&self, row: u32, col0: u32, col1: u32, out: &mut Vec<f32>) -> Result<()> {
        if row >= self.height || col1 >= self.width || col0 > col1 {
            return Err(out_of_range(col1, row, self.width, self.height));
        }
        let start = row as usize * self.width as usize;
        out.clear();
        out.extend_from_slice(&self.heights[start + col0 as usize..=start + col1 as usize]);
        Ok(())
    }
}

fn out_of_range(col: u32, row: u32, w: u32, h: u32) -> Error {
    Error::invalid(
        "level-0 sample",
        format!("({col}, {row}) is outside the {w}x{h} grid"),
    )
}

/// Level 0 of a `vkterrain preprocess` data set, read node by node (one seek + one read of a
/// `L0.bin` record per miss) through an LRU cache of at most [`PyramidReader::capacity`] nodes
/// (only their `center²` heights are kept). Capacity: three rows of level-0 nodes plus 8, so a
/// row-by-row sweep over UDLOD tiles (which also reads the rows of the coarse grid above and
/// below, at most two more node rows) loads each node about once per sweep.
pub struct PyramidReader {
    /// Where the nodes come from: the data set directory or the tile source.
    pub dir: PathBuf,
    pub name: String,
    width: u32,
    height: u32,
    spacing: f64,
    /// Level-0 height range from the manifest (metres).
    pub height_range: [f32; 2],
    store: Arc<dyn NodeStore>,
    center: u32,
    capacity: usize,
    cache: Mutex<NodeCache>,
}

const RECENT: usize = 8;

struct NodeCache {
    keys: Vec<(u32, u32)>,
    heights: Vec<Vec<f32>>,
    used: Vec<u64>,
    index: HashMap<(u32, u32), usize>,
    last: Option<usize>,
    /// First level-0 sample `(col, row)` of node `last`.
    last_origin: (u32, u32),
    /// The last few nodes used (origin, slot), searched before the hash map: a UDLOD sweep
    /// alternates between a sample's node and the nodes of the coarse grid's corners.
    recent: [((u32, u32), usize); RECENT],
    recent_next: usize,
    tick: u64,
    loads: u64,
}

impl Default for NodeCache {
    fn default() -> Self {
        NodeCache {
            keys: Vec::new(),
            heights: Vec::new(),
            used: Vec::new(),
            index: HashMap::new(),
            last: None,
            last_origin: (0, 0),
            // Slot usize::MAX never matches: empty entries.
            recent: [((0, 0), usize::MAX); RECENT],
            recent_next: 0,
            tick: 0,
            loads: 0,
        }
    }
}

impl PyramidReader {
    /// Opens a data set directory's level 0. The spacing must be square (the clipmap's
    /// requirement too).
    pub fn open(dir: &Path) -> Result<Self> {
        Self::from_store(Arc::new(DiskStore::open(dir)?))
    }

    /// Level 0 of any node store (a data set directory, live XYZ tiles), for the flat world:
    /// its spacing must be square.
    pub fn from_store(store: Arc<dyn NodeStore>) -> Result<Self> {
        Self::from_store_as(store, LoadGrid::SquareMetres)
    }

    /// [`PyramidReader::from_store`]; with [`LoadGrid::Native`] (the ellipsoid) a non-square
    /// grid is taken as it is, its spacing the LOD metric of `tiles::native_lod_spacing`.
    pub fn from_store_as(store: Arc<dyn NodeStore>, grid: LoadGrid) -> Result<Self> {
        let [sx, sy] = store.spacing();
        let what = || store.describe();
        if !(sx.is_finite() && sy.is_finite() && sx > 0.0 && sy > 0.0) {
            return Err(Error::invalid(
                what(),
                format!("sample spacing {sx} x {sy} m"),
            ));
        }
        let square = super::tiles::is_square([sx, sy]);
        if !square && grid == LoadGrid::SquareMetres {
            return Err(Error::invalid(
                what(),
                format!(
                    "sample spacing {sx} x {sy} m is not square; the flat world's clipmap needs square spacing (draw it on the ellipsoid, [render] earth = \"ellipsoid\", or disable [clipmap] to resample)"
                ),
            ));
        }
        let spacing = if square {
            sy
        } else {
            super::tiles::native_lod_spacing(
                store.georef()?.as_ref(),
                store.layout().height,
                [sx, sy],
            )
        };
        let layout = store.layout();
        let limit = 1u64 << 30;
        if layout.width > limit || layout.height > limit {
            return Err(Error::invalid(
                what(),
                format!("level 0 is {}x{} samples", layout.width, layout.height),
            ));
        }
        let (nx, _) = layout.nodes(0);
        Ok(PyramidReader {
            dir: PathBuf::from(store.describe()),
            name: store.name(),
            width: layout.width as u32,
            height: layout.height as u32,
            spacing,
            height_range: store.height_range(),
            center: layout.center,
            capacity: 3 * nx as usize + 8,
            cache: Mutex::new(NodeCache::default()),
            store,
        })
    }

    /// The node store behind the reader.
    pub fn store(&self) -> &Arc<dyn NodeStore> {
        &self.store
    }

    /// UDLOD's tile statistics for `grid_size`: the data set's stored ones, or (not stored)
    /// computed from level 0 with a progress line on stderr; with [`Finest::Skip`] without
    /// level 0's tiles ([`TileStats::without_finest`]).
    pub fn tile_stats(&self, grid_size: u32, finest: Finest) -> Result<TileStats> {
        if let Some(s) = self.store.stored_stats(grid_size, finest)? {
            return Ok(s);
        }
        let t = std::time::Instant::now();
        eprintln!(
            "udlod: tile statistics for grid_size {grid_size} are not stored in {}; computing them from level 0 ({}x{} samples; `vkterrain preprocess --stats-grid-sizes {grid_size}` stores them)...",
            self.store.describe(),
            self.width,
            self.height
        );
        let stats = match self.store.level0_rows() {
            Some(rows) => TileStats::compute(&rows?, grid_size, &|_| {})?,
            None => TileStats::compute_serial(&self.sweep(), grid_size)?,
        };
        eprintln!(
            "udlod: tile statistics computed in {:.1} s",
            t.elapsed().as_secs_f64()
        );
        Ok(match finest {
            Finest::Keep => stats,
            Finest::Skip => stats.without_finest(),
        })
    }

    /// UDLOD's statistics for a split field of `density` nodes per tile side of
    /// `cell_grid * density` quads: from the cells' stored statistics without holding their
    /// heights ([`FieldStats::read`]); with one node per tile corner also from those of
    /// half-size tiles (what two nodes per side at this grid read), folded into the tiles;
    /// else as
    /// [`PyramidReader::tile_stats`] computes them.
    pub fn field_stats(&self, cell_grid: u32, density: u32) -> Result<FieldStats> {
        if let Some(s) = self.store.stored_field_stats(cell_grid, density)? {
            return Ok(s);
        }
        if density == 1 && cell_grid % 2 == 0 {
            if let Some(s) = self.store.stored_field_stats(cell_grid / 2, 2)? {
                return Ok(FieldStats {
                    density: 1,
                    tiles: s.tiles,
                    cells: None,
                });
            }
        }
        FieldStats::from_cells(self.tile_stats(cell_grid, Finest::Skip)?, density)
    }

    /// Most nodes the cache holds.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Upper bound of the bytes the cache may hold (`capacity x center² x 4`).
    pub fn max_cached_bytes(&self) -> u64 {
        self.capacity as u64 * (self.center as u64).pow(2) * 4
    }

    fn lock(&self) -> MutexGuard<'_, NodeCache> {
        // A panic elsewhere cannot leave the cache inconsistent in a way that matters: every
        // entry is a whole node or absent.
        self.cache.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Bytes of node heights held now.
    pub fn cached_bytes(&self) -> u64 {
        self.lock()
            .heights
            .iter()
            .map(|h| h.capacity() as u64 * 4)
            .sum()
    }

    /// Nodes read from disk so far.
    pub fn node_loads(&self) -> u64 {
        self.lock().loads
    }

    /// Drops every cached node (and the open level file).
    pub fn clear(&self) {
        *self.lock() = NodeCache::default();
    }

    /// Exclusive access for a long sweep: one lock instead of one per sample.
    pub fn sweep(&self) -> PyramidSweep<'_> {
        PyramidSweep {
            reader: self,
            cache: RefCell::new(self.lock()),
        }
    }

    #[inline]
    fn get(&self, cache: &mut NodeCache, col: u32, row: u32) -> Result<f32> {
        if let Some(i) = cache.last {
            // Fast path, no division: the sample lies in the node read last.
            let dx = col.wrapping_sub(cache.last_origin.0);
            let dy = row.wrapping_sub(cache.last_origin.1);
            let c = self.center;
            if dx < c && dy < c && col < self.width && row < self.height {
                return Ok(cache.heights[i][(dy * c + dx) as usize]);
            }
        }
        self.get_slow(cache, col, row)
    }

    #[inline(never)]
    fn get_slow(&self, cache: &mut NodeCache, col: u32, row: u32) -> Result<f32> {
        if col >= self.width || row >= self.height {
            return Err(out_of_range(col, row, self.width, self.height));
        }
        let c = self.center;
        for &(origin, i) in &cache.recent {
            let dx = col.wrapping_sub(origin.0);
            let dy = row.wrapping_sub(origin.1);
            if dx < c && dy < c && i != usize::MAX {
                cache.last = Some(i);
                cache.last_origin = origin;
                return Ok(cache.heights[i][(dy * c + dx) as usize]);
            }
        }
        let key = (col / c, row / c);
        let local = ((row % c) * c + col % c) as usize;
        cache.tick += 1;
        let tick = cache.tick;
        let i = match cache.index.get(&key) {
            Some(&i) => i,
            None => self.load(cache, key)?,
        };
        cache.used[i] = tick;
        cache.last = Some(i);
        cache.last_origin = (key.0 * c, key.1 * c);
        let k = cache.recent_next;
        cache.recent[k] = (cache.last_origin, i);
        cache.recent_next = (k + 1) % RECENT;
        Ok(cache.heights[i][local])
    }

    fn load(&self, cache: &mut NodeCache, key: (u32, u32)) -> Result<usize> {
        let heights = self.store.read_centre(key.0, key.1)?;
        if let Some(bad) = heights.iter().position(|h| !h.is_finite()) {
            return Err(Error::invalid(
                format!("{} node 0/{}/{}", self.store.describe(), key.0, key.1),
                format!("height {bad} is not finite: corrupt node"),
            ));
        }
        cache.loads += 1;
        let i = if cache.keys.len() < self.capacity {
            cache.keys.push(key);
            cache.heights.push(heights);
            cache.used.push(0);
            cache.keys.len() - 1
        } else {
            let (i, _) = cache
                .used
                .iter()
                .enumerate()
                .min_by_key(|(_, u)| **u)
                .ok_or_else(|| Error::invalid("level-0 cache", "capacity 0"))?;
            let old = cache.keys[i];
            cache.index.remove(&old);
            for e in cache.recent.iter_mut().filter(|e| e.1 == i) {
                e.1 = usize::MAX;
            }
            cache.keys[i] = key;
            cache.heights[i] = heights;
            i
        };
        cache.index.insert(key, i);
        Ok(i)
    }
}

impl Level0 for PyramidReader {
    fn width(&self) -> u32 {
        self.width
    }
    fn height(&self) -> u32 {
        self.height
    }
    fn spacing(&self) -> f64 {
        self.spacing
    }
    fn sample(&self, col: u32, row: u32) -> Result<f32> {
        let mut cache = self.lock();
        self.get(&mut cache, col, row)
    }
    fn bilinear(&self, x: f64, y: f64) -> Result<f64> {
        self.sweep().bilinear(x, y)
    }
}

/// A [`PyramidReader`] locked for a sweep (see [`PyramidReader::sweep`]).
pub struct PyramidSweep<'a> {
    reader: &'a PyramidReader,
    cache: RefCell<MutexGuard<'a, NodeCache>>,
}

impl Level0 for PyramidSweep<'_> {
    fn width(&self) -> u32 {
        self.reader.width
    }
    fn height(&self) -> u32 {
        self.reader.height
    }
    fn spacing(&self) -> f64 {
        self.reader.spacing
    }
    #[inline]
    fn sample(&self, col: u32, row: u32) -> Result<f32> {
        let mut cache = self.cache.borrow_mut();
        self.reader.get(&mut cache, col, row)
    }
    /// One copy per node the row crosses.
    fn row(&self, row: u32, col0: u32, col1: u32, out: &mut Vec<f32>) -> Result<()> {
        let r = self.reader;
        if row >= r.height || col1 >= r.width || col0 > col1 {
            return Err(out_of_range(col1, row, r.width, r.height));
        }
        let mut cache = self.cache.borrow_mut();
        let c = r.center;
        out.clear();
        let mut col = col0;
        while col <= col1 {
            // Makes the node holding (col, row) the last one read.
            r.get(&mut cache, col, row)?;
            let Some(i) = cache.last else {
                return Err(Error::invalid("level-0 cache", "no node after a read"));
            };
            let (ox, oy) = cache.last_origin;
            let end = col1.min(ox + c - 1);
            let base = ((row - oy) * c) as usize;
            out.extend_from_slice(
                &cache.heights[i][base + (col - ox) as usize..=base + (end - ox) as usize],
            );
            col = end + 1;
        }
        Ok(())
    }
}

/// The terrain a renderer draws: the whole level-0 grid in memory, or a tile pyramid whose
/// level 0 is read through [`PyramidReader`] (heights then come through the clipmap).
/// Cloning shares the data.
#[derive(Clone)]
pub enum Terrain {
    Grid(Arc<Heightmap>),
    Pyramid(Arc<PyramidReader>),
}

impl Terrain {
    pub fn name(&self) -> &str {
        match self {
            Terrain::Grid(h) => &h.name,
            Terrain::Pyramid(p) => &p.name,
        }
    }

    /// The whole grid, when it is in memory.
    pub fn grid(&self) -> Option<&Arc<Heightmap>> {
        match self {
            Terrain::Grid(h) => Some(h),
            Terrain::Pyramid(_) => None,
        }
    }

    /// The whole grid, or a one-line error naming `what` needs it.
    pub fn require_grid(&self, what: &str) -> Result<&Arc<Heightmap>> {
        self.grid().ok_or_else(|| {
            Error::invalid(
                what,
                "needs the whole height map in memory, which is not loaded with [clipmap] enabled; set clipmap.enabled = false",
            )
        })
    }

    /// Stated metres between level-0 samples along x and y (`Heightmap::axis_spacing`; the
    /// pyramid's store's): `[spacing, spacing]` on square grids.
    pub fn axis_spacing(&self) -> [f64; 2] {
        match self {
            Terrain::Grid(h) => h.axis_spacing,
            Terrain::Pyramid(p) => p.store().spacing(),
        }
    }

    /// Minimum and maximum level-0 height (the pyramid's from its manifest).
    pub fn height_range(&self) -> (f32, f32) {
        match self {
            Terrain::Grid(h) => h.height_range(),
            Terrain::Pyramid(p) => (p.height_range[0], p.height_range[1]),
        }
    }
}

impl Level0 for Terrain {
    fn width(&self) -> u32 {
        match self {
            Terrain::Grid(h) => h.width,
            Terrain::Pyramid(p) => p.width,
        }
    }
    fn height(&self) -> u32 {
        match self {
            Terrain::Grid(h) => h.height,
            Terrain::Pyramid(p) => p.height,
        }
    }
    fn spacing(&self) -> f64 {
        match self {
            Terrain::Grid(h) => h.spacing,
            Terrain::Pyramid(p) => p.spacing,
        }
    }
    /// The clipmap's pyramid is level 0 itself.
    fn source_step(&self) -> [f64; 2] {
        match self {
            Terrain::Grid(h) => h.source_step,
            Terrain::Pyramid(_) => [1.0, 1.0],
        }
    }
    fn sample(&self, col: u32, row: u32) -> Result<f32> {
        match self {
            Terrain::Grid(h) => Level0::sample(&**h, col, row),
            Terrain::Pyramid(p) => p.sample(col, row),
        }
    }
    fn bilinear(&self, x: f64, y: f64) -> Result<f64> {
        match self {
            Terrain::Grid(h) => Ok(h.height_at(x, y)),
            Terrain::Pyramid(p) => p.bilinear(x, y),
        }
    }
}

impl From<Arc<Heightmap>> for Terrain {
    fn from(h: Arc<Heightmap>) -> Self {
        Terrain::Grid(h)
    }
}

impl From<&Arc<Heightmap>> for Terrain {
    fn from(h: &Arc<Heightmap>) -> Self {
        Terrain::Grid(h.clone())
    }
}

impl From<Heightmap> for Terrain {
    fn from(h: Heightmap) -> Self {
        Terrain::Grid(Arc::new(h))
    }
}

/// Copies the grid (tests and small data); pass an `Arc<Heightmap>` to share it.
impl From<&Heightmap> for Terrain {
    fn from(h: &Heightmap) -> Self {
        Terrain::Grid(Arc::new(h.clone()))
    }
}

impl From<Arc<PyramidReader>> for Terrain {
    fn from(p: Arc<PyramidReader>) -> Self {
        Terrain::Pyramid(p)
    }
}

impl From<&Terrain> for Terrain {
    fn from(t: &Terrain) -> Self {
        t.clone()
    }
}

/// A tile pyramid's nodes, wherever they live: a data set directory ([`DiskStore`]) or live
/// XYZ tiles ([`XyzPyramid`]). Called from loader threads.
pub trait NodeStore: Send + Sync {
    fn layout(&self) -> Layout;
    fn layers(&self) -> LayerSet;
    /// Source description (shown in summaries).
    fn name(&self) -> String;
    /// Where it is (a directory, a URL template): for messages.
    fn describe(&self) -> String;
    /// Local metres between level-0 samples `[x, y]`.
    fn spacing(&self) -> [f64; 2];
    /// Level-0 height range (metres).
    fn height_range(&self) -> [f32; 2];
    /// Node `(lod, x, y)`, borders included.
    fn read_node(&self, lod: u32, x: u32, y: u32) -> Result<Node>;
    /// The `center²` heights of level-0 node `(x, y)`.
    fn read_centre(&self, x: u32, y: u32) -> Result<Vec<f32>> {
        let l = self.layout();
        let n = self.read_node(0, x, y)?;
        let (c, b, s) = (l.center as usize, l.border as usize, l.side() as usize);
        Ok((0..c)
            .flat_map(|j| n.heights[(j + b) * s + b..(j + b) * s + b + c].to_vec())
            .collect())
    }
    /// UDLOD tile statistics for `grid_size`, if stored (`finest`: whether level 0's tiles
    /// are read).
    fn stored_stats(&self, _grid_size: u32, _finest: Finest) -> Result<Option<TileStats>> {
        Ok(None)
    }
    /// UDLOD's statistics for a split field of `density` nodes per tile side whose cells are
    /// tiles of `cell_grid` quads, if the cells' are stored ([`FieldStats::read`]).
    fn stored_field_stats(&self, _cell_grid: u32, _density: u32) -> Result<Option<FieldStats>> {
        Ok(None)
    }
    /// Level-0 rows straight from storage (parallel statistics), where that is cheap.
    fn level0_rows(&self) -> Option<Result<LevelRows>> {
        None
    }
    /// Tile fetch counters, for stores that fetch tiles.
    fn tile_counts(&self) -> Option<super::xyz::XyzCounts> {
        None
    }
    /// Where the samples lie on the earth (none: procedural or bare PNG data).
    fn georef(&self) -> Result<Option<super::crs::Georef>> {
        Ok(None)
    }
    /// The datum of the heights (`manifest::datum`).
    fn vertical_datum(&self) -> String {
        super::manifest::datum::LOCAL.into()
    }
}

/// A `vkterrain preprocess` data set directory as a node store (level 0 opened once, read
/// with positioned reads).
pub struct DiskStore {
    pub dataset: Dataset,
    level0: File,
    level0_path: PathBuf,
}

impl DiskStore {
    pub fn open(dir: &Path) -> Result<Self> {
        let dataset = Dataset::open(dir)?;
        let (level0, level0_path) = dataset.open_level(0)?;
        Ok(DiskStore {
            dataset,
            level0,
            level0_path,
        })
    }
}

impl NodeStore for DiskStore {
    fn layout(&self) -> Layout {
        self.dataset.layout
    }
    fn layers(&self) -> LayerSet {
        self.dataset.layers
    }
    fn name(&self) -> String {
        format!(
            "{} ({})",
            self.dataset.manifest.name, self.dataset.manifest.content
        )
    }
    fn describe(&self) -> String {
        self.dataset.dir.display().to_string()
    }
    fn spacing(&self) -> [f64; 2] {
        self.dataset.manifest.spacing
    }
    fn height_range(&self) -> [f32; 2] {
        self.dataset.manifest.height_range
    }
    fn read_node(&self, lod: u32, x: u32, y: u32) -> Result<Node> {
        self.dataset.read_node(lod, x, y)
    }
    /// One positioned read of the record's height rows that hold centre texels (their
    /// border texels come along; albedo and mask are not read). The level file's size was
    /// checked when it was opened.
    fn read_centre(&self, x: u32, y: u32) -> Result<Vec<f32>> {
        use std::os::unix::fs::FileExt;
        let l = &self.dataset.layout;
        let (nx, ny) = l.nodes(0);
        let what = || format!("{} node 0/{x}/{y}", self.level0_path.display());
        if x >= nx || y >= ny {
            return Err(Error::invalid(what(), format!("outside {nx}x{ny} nodes")));
        }
        let (c, b, s) = (l.center as usize, l.border as usize, l.side() as usize);
        let start = l.record_offset(0, x, y, self.dataset.layers)
            + super::pyramid::NODE_HEADER
            + (b * s * 4) as u64;
        let mut buf = vec![0u8; c * s * 4];
        self.level0
            .read_exact_at(&mut buf, start)
            .map_err(|e| Error::invalid(what(), format!("unreadable (truncated file?): {e}")))?;
        let mut heights = Vec::with_capacity(c * c);
        for row in buf.chunks_exact(s * 4) {
            heights.extend(
                row[b * 4..(b + c) * 4]
                    .chunks_exact(4)
                    .map(|v| f32::from_le_bytes([v[0], v[1], v[2], v[3]])),
            );
        }
        Ok(heights)
    }
    fn stored_stats(&self, grid_size: u32, finest: Finest) -> Result<Option<TileStats>> {
        self.dataset.tile_stats(grid_size, finest)
    }
    fn stored_field_stats(&self, cell_grid: u32, density: u32) -> Result<Option<FieldStats>> {
        self.dataset.field_stats(cell_grid, density)
    }
    fn georef(&self) -> Result<Option<super::crs::Georef>> {
        Ok(self.dataset.manifest.georef.clone())
    }
    fn vertical_datum(&self) -> String {
        self.dataset.manifest.vertical_datum.clone()
    }
    fn level0_rows(&self) -> Option<Result<LevelRows>> {
        Some(LevelRows::open(
            &self.level0_path,
            self.dataset.layout,
            self.dataset.layers,
            self.dataset.manifest.spacing[1],
        ))
    }
}

impl NodeStore for XyzPyramid {
    fn layout(&self) -> Layout {
        self.layout
    }
    fn layers(&self) -> LayerSet {
        XyzPyramid::layers(self)
    }
    fn name(&self) -> String {
        XyzPyramid::name(self)
    }
    fn describe(&self) -> String {
        self.settings.source.clone()
    }
    fn spacing(&self) -> [f64; 2] {
        [self.spacing, self.spacing]
    }
    fn height_range(&self) -> [f32; 2] {
        self.height_range
    }
    fn read_node(&self, lod: u32, x: u32, y: u32) -> Result<Node> {
        XyzPyramid::read_node(self, lod, x, y)
    }
    fn tile_counts(&self) -> Option<super::xyz::XyzCounts> {
        Some(self.fetcher.counters.snapshot())
    }
    fn georef(&self) -> Result<Option<super::crs::Georef>> {
        self.grid.georef().map(Some)
    }
    fn vertical_datum(&self) -> String {
        super::manifest::datum::UNKNOWN.into()
    }
}

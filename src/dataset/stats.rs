//! Per-tile statistics of the level-0 grid for a quadtree of square tiles: what UDLOD's
//! `Levels` needs at start-up (min/max height and geometric error of every tile of every
//! level), computed once by `vkterrain preprocess` and stored in the data set
//! (`stats-g{grid}.bin`, see `docs/dataset-format.md`), or computed from level 0 when a grid
//! size was not stored.
//!
//! Tiling for `grid_size` quads per tile side: level `l` has tiles of `span = grid_size << l`
//! quads; tile `(tx, ty)` covers level-0 samples `tx*span ..= min((tx+1)*span, width-1)` (and
//! the same in rows), so neighbouring tiles share their edge samples. The root level is the
//! first whose single tile covers every quad. A tile's **error** at level `l >= 1` is the
//! largest `|mesh_l(s) - h(s)|` over its samples `s`, where `mesh_l` is the level-`l` grid
//! (every `2^l`-th sample, clamped to the data) triangulated along the diagonal from
//! `(1, 0)` to `(0, 1)`, evaluated by [`level_interpolate`]; level 0 has error 0.
//!
//! The computation sweeps bands of rows in parallel; per sample the values and the
//! arithmetic are those of the sample-by-sample definition, and the per-tile reductions
//! (min, max, max) do not depend on the order, so the result is the same bit for bit for any
//! number of threads (tested against the definition in `tests/clipmap.rs`).

use std::sync::Mutex;

use rayon::prelude::*;

use super::Level0;
use crate::error::{Error, Result};

/// Magic of a statistics file.
pub const STATS_MAGIC: &[u8; 8] = b"VKTSTATS";
/// Version of the statistics file layout.
pub const STATS_VERSION: u32 = 1;
const HEADER: usize = 40;
/// Header flag (the u32 at byte 36, 0 before it existed): the finest level's tiles are not
/// stored ([`TileStats::without_finest`]; its level entry is).
const FINEST_OMITTED: u32 = 1;
const LEVEL_ENTRY: usize = 16;
const TILE_ENTRY: usize = 12;
/// Tiles read per buffer fill: reading a level needs no buffer of the level's size.
const READ_TILES: usize = 4096;
/// Rows per band of the parallel sweep.
const BAND_ROWS: u32 = 256;

/// One level of tiles.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelTiles {
    /// Tiles per side that touch the data.
    pub tiles: (u32, u32),
    /// `(min, max)` height of every tile's samples, row-major from the south-west tile.
    pub min_max: Vec<[f32; 2]>,
    /// Geometric error of every tile in metres (f32 of the exact f64 value).
    pub error: Vec<f32>,
    /// The largest tile error of the level, in f64 (0 at level 0).
    pub max_error: f64,
}

/// Statistics of every level for one tile size.
#[derive(Clone, Debug, PartialEq)]
pub struct TileStats {
    pub grid_size: u32,
    pub width: u32,
    pub height: u32,
    /// Finest (0) to root.
    pub levels: Vec<LevelTiles>,
}

/// The level-independent shape of a tiling.
#[derive(Clone, Debug)]
struct Shape {
    grid: u32,
    width: u32,
    height: u32,
    /// `(nx, ny, span)` per level.
    levels: Vec<(u32, u32, u32)>,
}

impl Shape {
    fn new(width: u32, height: u32, grid: u32) -> Result<Self> {
        if width < 2 || height < 2 {
            return Err(Error::invalid(
                "tile statistics",
                format!("{width}x{height} samples is smaller than 2x2"),
            ));
        }
        if !(2..=1 << 16).contains(&grid) {
            return Err(Error::invalid(
                "tile statistics",
                format!("grid size {grid} outside 2..=65536"),
            ));
        }
        let root = root_lod(width, height, grid);
        let levels = (0..=root)
            .map(|l| {
                let span = grid << l;
                (
                    (width - 1).div_ceil(span),
                    (height - 1).div_ceil(span),
                    span,
                )
            })
            .collect();
        Ok(Shape {
            grid,
            width,
            height,
            levels,
        })
    }
}

/// The root level of a tiling: the first whose single tile covers every quad.
pub fn root_lod(width: u32, height: u32, grid_size: u32) -> u32 {
    let quads = (width - 1).max(height - 1) as u64;
    let mut root = 0;
    while ((grid_size as u64) << root) < quads {
        root += 1;
    }
    root
}

/// Height of the level-`lod` triangulated grid at level-0 sample `(c, r)` from the four
/// level samples around it (`[h(c0, r0), h(c0 + step, r0), h(c0, r0 + step),
/// h(c0 + step, r0 + step)]`, `c0 = c` rounded down to a multiple of `step = 2^lod`, corners
/// clamped to the data). Quads split along the diagonal from (1, 0) to (0, 1).
pub fn level_interpolate(lod: u32, corners: [f64; 4], c: u32, r: u32) -> f64 {
    let step = 1u32 << lod;
    let (c0, r0) = (c / step * step, r / step * step);
    let (fx, fy) = ((c - c0) as f64 / step as f64, (r - r0) as f64 / step as f64);
    super::interp::triangulated(corners, fx, fy)
}

/// Partial statistics of one band of rows: per level, the tile rows it touches.
struct Partial {
    /// Per level: first tile row, then `rows x nx` entries of (min, max, error).
    levels: Vec<LevelPartial>,
}

/// One level of a [`Partial`]: its first tile row and its tiles' (min, max) and errors.
type LevelPartial = (u32, Vec<[f32; 2]>, Vec<f64>);

/// Full rows of level 0 held while a band is swept: the band's current row and, per level,
/// the two level rows around it.
struct RowCache {
    rows: Vec<(u32, Vec<f32>)>,
}

impl RowCache {
    /// Makes every row of `needed` resident (reading what is missing) and returns their slots.
    fn ensure<D: Level0 + ?Sized>(&mut self, data: &D, needed: &[u32]) -> Result<()> {
        let w = data.width();
        let mut free: Vec<usize> = (0..self.rows.len())
            .filter(|&i| !needed.contains(&self.rows[i].0))
            .collect();
        for &r in needed {
            if self.rows.iter().any(|(k, _)| *k == r) {
                continue;
            }
            let slot = match free.pop() {
                Some(s) => s,
                None => {
                    self.rows.push((u32::MAX, Vec::with_capacity(w as usize)));
                    self.rows.len() - 1
                }
            };
            data.row(r, 0, w - 1, &mut self.rows[slot].1)?;
            self.rows[slot].0 = r;
        }
        Ok(())
    }

    fn get(&self, r: u32) -> &[f32] {
        &self
            .rows
            .iter()
            .find(|(k, _)| *k == r)
            .expect("row made resident")
            .1
    }
}

/// Sweeps rows `r0..=r1`.
fn band<D: Level0 + ?Sized>(data: &D, shape: &Shape, r0: u32, r1: u32) -> Result<Partial> {
    let mut levels = empty_partial_levels(shape, r0, r1);
    let mut cache = RowCache { rows: Vec::new() };
    let (nx0, _, _) = shape.levels[0];
    let mut seg = vec![[f32::INFINITY, f32::NEG_INFINITY]; nx0 as usize];
    let mut seg_err: Vec<f64> = Vec::new();
    let mut needed = Vec::with_capacity(2 * shape.levels.len() + 1);
    for r in r0..=r1 {
        rows_needed(shape, r, &mut needed);
        cache.ensure(data, &needed)?;
        let row = cache.get(r);
        segment_min_max(shape, row, &mut seg);
        for (lod, &(nx, ny, span)) in shape.levels.iter().enumerate() {
            let lod = lod as u32;
            seg_err.clear();
            seg_err.resize(nx as usize, 0.0);
            if lod > 0 {
                segment_errors(shape, &cache, row, r, (lod, span), &mut seg_err);
            }
            fold_row(
                &mut levels[lod as usize],
                (nx, ny, span),
                lod,
                r,
                &seg,
                &seg_err,
            );
        }
    }
    Ok(Partial { levels })
}

/// Every level's tile rows that rows `r0..=r1` touch, every tile empty.
fn empty_partial_levels(shape: &Shape, r0: u32, r1: u32) -> Vec<LevelPartial> {
    shape
        .levels
        .iter()
        .map(|&(nx, ny, span)| {
            let first = (r0 / span).saturating_sub((r0 % span == 0 && r0 > 0) as u32);
            let last = (r1 / span).min(ny - 1);
            let rows = (last + 1 - first) as usize;
            (
                first,
                vec![[f32::INFINITY, f32::NEG_INFINITY]; rows * nx as usize],
                vec![0.0f64; rows * nx as usize],
            )
        })
        .collect()
}

/// The level-0 rows sweeping row `r` reads, into `needed` (cleared first): `r` itself and, per
/// coarser level, the two level rows around it.
fn rows_needed(shape: &Shape, r: u32, needed: &mut Vec<u32>) {
    needed.clear();
    needed.push(r);
    for lod in 1..shape.levels.len() as u32 {
        let step = 1u32 << lod;
        let rl = r >> lod << lod;
        for k in [rl, (rl + step).min(shape.height - 1)] {
            if !needed.contains(&k) {
                needed.push(k);
            }
        }
    }
}

/// `(min, max)` of `row` over every level-0 tile's columns, into `seg`.
fn segment_min_max(shape: &Shape, row: &[f32], seg: &mut [[f32; 2]]) {
    // Level-0 segments (shared edge samples in both neighbours).
    for (tx, s) in seg.iter_mut().enumerate() {
        let c0 = tx as u32 * shape.grid;
        let c1 = (c0 + shape.grid).min(shape.width - 1);
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for &v in &row[c0 as usize..=c1 as usize] {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        *s = [lo, hi];
    }
}

/// The largest error of the level-`lod` grid (`lod >= 1`, tiles of `span` quads) over the
/// samples of `row` (level-0 row `r`) in each of its tiles, into `seg_err`; the level rows
/// around `r` come from `cache`.
fn segment_errors(
    shape: &Shape,
    cache: &RowCache,
    row: &[f32],
    r: u32,
    (lod, span): (u32, u32),
    seg_err: &mut [f64],
) {
    let (w, h) = (shape.width, shape.height);
    let step = 1u32 << lod;
    let rl = r >> lod << lod;
    let south = cache.get(rl);
    let north = cache.get((rl + step).min(h - 1));
    for (tx, e) in seg_err.iter_mut().enumerate() {
        let c0 = tx as u32 * span;
        let c1 = (c0 + span).min(w - 1);
        let mut worst = 0.0f64;
        for c in c0..=c1 {
            let cl = c >> lod << lod;
            let cr = (cl + step).min(w - 1);
            let k = [
                south[cl as usize] as f64,
                south[cr as usize] as f64,
                north[cl as usize] as f64,
                north[cr as usize] as f64,
            ];
            let v = row[c as usize] as f64;
            worst = worst.max((level_interpolate(lod, k, c, r) - v).abs());
        }
        *e = worst;
    }
}

/// Row `r`'s level-0 segments and level-`lod` errors folded into the level's tiles
/// (`(nx, ny, span)`) that hold the row.
fn fold_row(
    level: &mut LevelPartial,
    (nx, ny, span): (u32, u32, u32),
    lod: u32,
    r: u32,
    seg: &[[f32; 2]],
    seg_err: &[f64],
) {
    let (first, mm, err) = level;
    // The tile row holding row r, and the one below when r is their shared edge.
    let ty = r / span;
    let below = (r % span == 0 && ty > 0).then(|| ty - 1);
    for t in [Some(ty).filter(|&t| t < ny), below].into_iter().flatten() {
        let base = ((t - *first) * nx) as usize;
        let per = 1usize << lod;
        for tx in 0..nx as usize {
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for s in &seg[tx * per..((tx + 1) * per).min(seg.len())] {
                lo = lo.min(s[0]);
                hi = hi.max(s[1]);
            }
            let m = &mut mm[base + tx];
            m[0] = m[0].min(lo);
            m[1] = m[1].max(hi);
            err[base + tx] = err[base + tx].max(seg_err[tx]);
        }
    }
}

impl TileStats {
    /// Statistics to fold into: every tile empty; with [`Finest::Skip`] and a coarser
    /// level, none held for level 0.
    fn empty(shape: &Shape, finest: Finest) -> Self {
        Self::empty_holding(shape, finest, true)
    }

    /// [`TileStats::empty`], with the tiles' heights held or (`heights` false) not.
    fn empty_holding(shape: &Shape, finest: Finest, heights: bool) -> Self {
        let skip = finest == Finest::Skip && shape.levels.len() > 1;
        TileStats {
            grid_size: shape.grid,
            width: shape.width,
            height: shape.height,
            levels: shape
                .levels
                .iter()
                .enumerate()
                .map(|(lod, &(nx, ny, _))| {
                    let held = if lod == 0 && skip {
                        0
                    } else {
                        (nx * ny) as usize
                    };
                    LevelTiles {
                        tiles: (nx, ny),
                        min_max: vec![[f32::INFINITY, f32::NEG_INFINITY]; held * heights as usize],
                        error: vec![0.0; held],
                        max_error: 0.0,
                    }
                })
                .collect(),
        }
    }

    /// Folds a band's partial statistics in (min, max and max: any order gives the same bits).
    fn merge(&mut self, p: Partial) {
        for (level, (first, mm, err)) in self.levels.iter_mut().zip(p.levels) {
            let nx = level.tiles.0 as usize;
            let base = first as usize * nx;
            for (i, (m, e)) in mm.iter().zip(&err).enumerate() {
                let t = &mut level.min_max[base + i];
                t[0] = t[0].min(m[0]);
                t[1] = t[1].max(m[1]);
                // f32 rounding is monotonic: the f32 of the max is the max of the f32s.
                level.error[base + i] = level.error[base + i].max(*e as f32);
                level.max_error = level.max_error.max(*e);
            }
        }
    }

    fn bands(shape: &Shape) -> Vec<(u32, u32)> {
        (0..shape.height.div_ceil(BAND_ROWS))
            .map(|b| {
                let r0 = b * BAND_ROWS;
                (r0, (r0 + BAND_ROWS - 1).min(shape.height - 1))
            })
            .collect()
    }

    /// Statistics of `data` for tiles of `grid_size` quads, bands of rows swept in parallel
    /// (rayon's pool); `progress(rows)` is called as bands finish.
    pub fn compute<D: Level0 + Sync + ?Sized>(
        data: &D,
        grid_size: u32,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Result<Self> {
        let shape = Shape::new(data.width(), data.height(), grid_size)?;
        let out = Mutex::new(Self::empty(&shape, Finest::Keep));
        Self::bands(&shape)
            .into_par_iter()
            .try_for_each(|(r0, r1)| -> Result<()> {
                let p = band(data, &shape, r0, r1)?;
                out.lock().unwrap_or_else(|e| e.into_inner()).merge(p);
                progress((r1 + 1 - r0) as u64);
                Ok(())
            })?;
        Ok(out.into_inner().unwrap_or_else(|e| e.into_inner()))
    }

    /// [`TileStats::compute`] on the calling thread (for sources that are not `Sync`).
    pub fn compute_serial<D: Level0 + ?Sized>(data: &D, grid_size: u32) -> Result<Self> {
        let shape = Shape::new(data.width(), data.height(), grid_size)?;
        let mut out = Self::empty(&shape, Finest::Keep);
        for (r0, r1) in Self::bands(&shape) {
            out.merge(band(data, &shape, r0, r1)?);
        }
        Ok(out)
    }

    pub fn root_lod(&self) -> u32 {
        self.levels.len() as u32 - 1
    }

    /// Bytes of the stored form for a `width x height` grid, with or without the finest
    /// level's tiles (`finest_stored`; always with them where it is the only level).
    pub fn stored_size(
        width: u32,
        height: u32,
        grid_size: u32,
        finest_stored: bool,
    ) -> Result<u64> {
        let shape = Shape::new(width, height, grid_size)?;
        let omitted = !finest_stored && shape.levels.len() > 1;
        let tiles: u64 = shape
            .levels
            .iter()
            .skip(omitted as usize)
            .map(|&(nx, ny, _)| nx as u64 * ny as u64)
            .sum();
        Ok(HEADER as u64
            + shape.levels.len() as u64 * LEVEL_ENTRY as u64
            + tiles * TILE_ENTRY as u64)
    }

    /// The stored form: header, per level `(nx, ny, max_error)`, per tile `(min, max, error)`,
    /// little-endian; without the finest level's tiles where these statistics do not hold
    /// them (flagged in the header).
    pub fn to_bytes(&self) -> Vec<u8> {
        let flags = if self.has_finest() { 0 } else { FINEST_OMITTED };
        let tiles: usize = self.levels.iter().map(|l| l.error.len()).sum();
        let mut b =
            Vec::with_capacity(HEADER + self.levels.len() * LEVEL_ENTRY + tiles * TILE_ENTRY);
        b.extend_from_slice(STATS_MAGIC);
        for v in [STATS_VERSION, self.grid_size] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for v in [self.width as u64, self.height as u64] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&(self.levels.len() as u32).to_le_bytes());
        b.extend_from_slice(&flags.to_le_bytes());
        for l in &self.levels {
            b.extend_from_slice(&l.tiles.0.to_le_bytes());
            b.extend_from_slice(&l.tiles.1.to_le_bytes());
            b.extend_from_slice(&l.max_error.to_le_bytes());
        }
        for l in &self.levels {
            for (m, e) in l.min_max.iter().zip(&l.error) {
                b.extend_from_slice(&m[0].to_le_bytes());
                b.extend_from_slice(&m[1].to_le_bytes());
                b.extend_from_slice(&e.to_le_bytes());
            }
        }
        b
    }

    /// Parses and checks the stored form against the grid it must describe: sizes, tile
    /// counts, finite values, `min <= max`, errors `>= 0` and each level's maximum equal to
    /// its largest tile error; the finest level's tiles where the file holds them. `what`
    /// names the file in errors.
    pub fn from_bytes(
        bytes: &[u8],
        what: &str,
        width: u32,
        height: u32,
        grid_size: u32,
    ) -> Result<Self> {
        let finest_stored = bytes
            .get(..HEADER)
            .map_or(Ok(true), finest_stored)
            .map_err(|m| Error::invalid(what, m))?;
        let want = Self::stored_size(width, height, grid_size, finest_stored)?;
        if bytes.len() as u64 != want {
            return Err(Error::invalid(
                what,
                format!(
                    "{} bytes, expected {want} for {width}x{height} samples and grid size {grid_size}: truncated or altered",
                    bytes.len()
                ),
            ));
        }
        let mut cursor = std::io::Cursor::new(bytes);
        Self::parse(
            &mut cursor,
            what,
            width,
            height,
            grid_size,
            if finest_stored {
                Finest::Keep
            } else {
                Finest::Skip
            },
            None,
        )
    }

    /// Parses the stored form from `r` (its length already checked), level by level and
    /// [`READ_TILES`] tiles at a time into the level's arrays; with [`Finest::Skip`] the
    /// finest level's tiles are skipped unread (when a coarser level exists:
    /// [`TileStats::without_finest`]); with `coarse` (a coarser tiling's empty statistics)
    /// the tiles' heights fold into it as they are read and only their errors are kept.
    fn parse<R: std::io::Read + std::io::Seek>(
        r: &mut R,
        what: &str,
        width: u32,
        height: u32,
        grid_size: u32,
        finest: Finest,
        mut coarse: Option<&mut TileStats>,
    ) -> Result<Self> {
        let bad = |m: String| Error::invalid(what, m);
        let shape = Shape::new(width, height, grid_size)?;
        let head = read_header(r, &shape).map_err(bad)?;
        let omitted = !finest_stored(&head).map_err(bad)?;
        if omitted && finest == Finest::Keep {
            return Err(bad("level 0's tiles are not stored".into()));
        }
        let u32_at =
            |b: &[u8], o: usize| u32::from_le_bytes(b[o..o + 4].try_into().expect("4 bytes"));
        let folding = coarse.is_some();
        let mut out = Self::empty_holding(&shape, finest, !folding);
        let skip_finest = finest == Finest::Skip && out.levels.len() > 1;
        let mut buf = Vec::new();
        for (lod, level) in out.levels.iter_mut().enumerate() {
            let e = HEADER + lod * LEVEL_ENTRY;
            let tiles = (u32_at(&head, e), u32_at(&head, e + 4));
            if tiles != level.tiles {
                return Err(bad(format!(
                    "level {lod} has {tiles:?} tiles, expected {:?}",
                    level.tiles
                )));
            }
            if lod == 0 && omitted {
                continue;
            }
            if lod == 0 && skip_finest {
                let stored = level.tiles.0 as usize * level.tiles.1 as usize;
                r.seek(std::io::SeekFrom::Current((stored * TILE_ENTRY) as i64))
                    .map_err(|e| bad(format!("level 0: {e}")))?;
                continue;
            }
            level.max_error = f64::from_le_bytes(head[e + 8..e + 16].try_into().expect("8"));
            // The coarse tiling has fewer levels: the finer ones past its root fold nowhere.
            let mut coarse_level = coarse.as_deref_mut().and_then(|c| {
                let factor = (c.grid_size / grid_size) as usize;
                c.levels.get_mut(lod).map(|l| (factor, l))
            });
            let largest = read_level_tiles(
                r,
                &mut buf,
                level,
                lod,
                folding,
                coarse_level.as_mut().map(|(f, c)| (*f, &mut **c)),
            )
            .map_err(bad)?;
            if let Some((_, c)) = coarse_level {
                c.max_error = level.max_error;
            }
            if !(level.max_error.is_finite() && level.max_error as f32 == largest) {
                return Err(bad(format!(
                    "level {lod}: maximum error {} disagrees with its tiles' {largest}",
                    level.max_error
                )));
            }
        }
        Ok(out)
    }

    /// These statistics without the finest level's tiles (its shape and zero error kept),
    /// when a coarser level exists: UDLOD never splits a level-0 tile and bounds it with its
    /// parent's heights, so three quarters of the tiles need no memory
    /// (`Levels::from_stats`).
    pub fn without_finest(mut self) -> Self {
        if self.levels.len() > 1 {
            let l = &mut self.levels[0];
            l.min_max = Vec::new();
            l.error = Vec::new();
            l.max_error = 0.0;
        }
        self
    }

    /// The statistics of tiles `factor` (a power of two) times larger, bit for bit those
    /// [`TileStats::compute`] gives at `grid_size x factor`: a tile's samples are the union of
    /// its `factor x factor` smaller tiles' (clipped at the data's edge), so its min, max and
    /// error are theirs, and f32 rounding keeps the order of the exact errors. UDLOD's finer
    /// split field reads the small tiles' errors and tiles with the large ones
    /// (`Levels::with_field_density`). A level without tiles (the finest, dropped) stays so.
    pub fn coarsened(&self, factor: u32) -> Result<Self> {
        let shape = Shape::new(
            self.width,
            self.height,
            coarse_grid(self.grid_size, factor)?,
        )?;
        let mut levels = Vec::with_capacity(shape.levels.len());
        for (lod, &(nx, ny, _)) in shape.levels.iter().enumerate() {
            let fine = &self.levels[lod];
            let held = fine.min_max.len() == (fine.tiles.0 * fine.tiles.1) as usize;
            let mut out = LevelTiles {
                tiles: (nx, ny),
                min_max: Vec::new(),
                error: Vec::new(),
                max_error: fine.max_error,
            };
            if held && !fine.min_max.is_empty() {
                let n = (nx * ny) as usize;
                out.min_max = vec![[f32::INFINITY, f32::NEG_INFINITY]; n];
                out.error = vec![0.0; n];
                let fnx = fine.tiles.0 as usize;
                for (f, (&[lo, hi], &er)) in fine.min_max.iter().zip(&fine.error).enumerate() {
                    fold_tile(&mut out, factor as usize, (f % fnx, f / fnx), [lo, hi, er]);
                }
            }
            levels.push(out);
        }
        Ok(TileStats {
            grid_size: shape.grid,
            width: self.width,
            height: self.height,
            levels,
        })
    }

    /// Whether the finest level's tiles are held ([`TileStats::without_finest`]).
    pub fn has_finest(&self) -> bool {
        let l = &self.levels[0];
        l.min_max.len() == (l.tiles.0 * l.tiles.1) as usize
    }

    /// Writes the stored form to `path`, fsynced.
    pub fn write(&self, path: &std::path::Path) -> Result<u64> {
        use std::io::Write;
        let bytes = self.to_bytes();
        let mut f = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
        f.write_all(&bytes).map_err(|e| Error::io(path, e))?;
        f.sync_all().map_err(|e| Error::io(path, e))?;
        Ok(bytes.len() as u64)
    }

    /// Reads and checks a stored file (its size is checked before it is read), one level at
    /// a time; with [`Finest::Skip`] the finest level's tiles are not read.
    pub fn read(
        path: &std::path::Path,
        width: u32,
        height: u32,
        grid_size: u32,
        finest: Finest,
    ) -> Result<Self> {
        Self::read_folding(path, width, height, grid_size, finest, None)
    }

    /// [`TileStats::read`], with `coarse` (a coarser tiling's empty statistics): the tiles'
    /// heights and errors folded into it as they are read, only their errors kept
    /// ([`FieldStats::read`]).
    fn read_folding(
        path: &std::path::Path,
        width: u32,
        height: u32,
        grid_size: u32,
        finest: Finest,
        coarse: Option<&mut TileStats>,
    ) -> Result<Self> {
        use std::io::Seek;
        let what = path.display().to_string();
        let mut file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let finest_stored = read_finest_stored(&mut file, &what)?;
        let want = Self::stored_size(width, height, grid_size, finest_stored)?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        if len != want {
            return Err(Error::invalid(
                what,
                format!("{len} bytes, expected {want}: truncated or altered"),
            ));
        }
        file.rewind().map_err(|e| Error::io(path, e))?;
        let mut r = std::io::BufReader::new(&mut file);
        Self::parse(&mut r, &what, width, height, grid_size, finest, coarse)
    }
}

/// Whether a stored file at `path` holds its finest level's tiles (its header's flag),
/// read from its first bytes.
pub fn stored_with_finest(path: &std::path::Path) -> Result<bool> {
    let mut file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    read_finest_stored(&mut file, &path.display().to_string())
}

/// The flags of the header at the start of `file` ([`finest_stored`]); `what` names it.
fn read_finest_stored(file: &mut std::fs::File, what: &str) -> Result<bool> {
    use std::io::Read;
    let mut head = [0u8; HEADER];
    file.read_exact(&mut head)
        .map_err(|e| Error::invalid(what, format!("unreadable header (truncated?): {e}")))?;
    finest_stored(&head).map_err(|m| Error::invalid(what, m))
}

/// Whether a header (at least [`HEADER`] bytes) says the finest level's tiles are stored:
/// its flags word, where [`FINEST_OMITTED`] is the only flag, and only with a coarser level.
fn finest_stored(head: &[u8]) -> std::result::Result<bool, String> {
    let u32_at = |o: usize| u32::from_le_bytes(head[o..o + 4].try_into().expect("4 bytes"));
    let (levels, flags) = (u32_at(32), u32_at(36));
    if flags & !FINEST_OMITTED != 0 {
        return Err(format!("unknown header flags {flags:#x}"));
    }
    if flags == FINEST_OMITTED && levels < 2 {
        return Err(
            "the finest level's tiles are flagged omitted, but it is the only level".into(),
        );
    }
    Ok(flags == 0)
}

/// Reads the stored form's header and level entries from `r` and checks them against the
/// tiling `shape` describes: magic, version, grid size, samples and level count (the entries'
/// tile counts are checked level by level as they are read).
fn read_header<R: std::io::Read>(r: &mut R, shape: &Shape) -> std::result::Result<Vec<u8>, String> {
    let mut head = vec![0u8; HEADER + shape.levels.len() * LEVEL_ENTRY];
    r.read_exact(&mut head)
        .map_err(|e| format!("unreadable header: {e}"))?;
    if &head[..8] != STATS_MAGIC {
        return Err("not a vkterrain statistics file".into());
    }
    let u32_at = |o: usize| u32::from_le_bytes(head[o..o + 4].try_into().expect("4 bytes"));
    let u64_at = |o: usize| u64::from_le_bytes(head[o..o + 8].try_into().expect("8 bytes"));
    let header = (
        u32_at(8),
        u32_at(12),
        u64_at(16),
        u64_at(24),
        u32_at(32) as usize,
    );
    let expected = (
        STATS_VERSION,
        shape.grid,
        shape.width as u64,
        shape.height as u64,
        shape.levels.len(),
    );
    if header != expected {
        return Err(format!(
            "header (version, grid, width, height, levels) {header:?} disagrees with {expected:?}"
        ));
    }
    Ok(head)
}

/// The grid size of tiles `factor` (a power of two) times larger than tiles of `grid` quads.
fn coarse_grid(grid: u32, factor: u32) -> Result<u32> {
    if !factor.is_power_of_two() {
        return Err(Error::invalid(
            "tile statistics",
            format!("coarsening factor {factor} is not a power of two"),
        ));
    }
    grid.checked_mul(factor)
        .ok_or_else(|| Error::invalid("tile statistics", format!("grid size {grid} x {factor}")))
}

/// One stored tile `(min, max, error)` of level `lod`, checked: finite, `min <= max`, error
/// `>= 0` (0 at level 0).
fn tile_entry(v: &[u8], lod: usize) -> std::result::Result<[f32; 3], String> {
    let f = |o: usize| f32::from_le_bytes(v[o..o + 4].try_into().expect("4 bytes"));
    let (lo, hi, er) = (f(0), f(4), f(8));
    let valid = lo.is_finite() && hi.is_finite() && lo <= hi && er.is_finite() && er >= 0.0;
    if !valid || (lod == 0 && er != 0.0) {
        return Err(format!(
            "level {lod}: tile (min {lo}, max {hi}, error {er}) is not valid"
        ));
    }
    Ok([lo, hi, er])
}

/// Reads level `lod`'s stored tiles from `r`, [`READ_TILES`] at a time through `buf`, into
/// its errors and (unless `folding`) its heights, or folds them into `coarse` (its factor
/// and level); returns the largest error read.
fn read_level_tiles<R: std::io::Read>(
    r: &mut R,
    buf: &mut Vec<u8>,
    level: &mut LevelTiles,
    lod: usize,
    folding: bool,
    mut coarse: Option<(usize, &mut LevelTiles)>,
) -> std::result::Result<f32, String> {
    let mut largest = 0.0f32;
    let nx = level.tiles.0 as usize;
    for (chunk, error) in level.error.chunks_mut(READ_TILES).enumerate() {
        buf.resize(error.len() * TILE_ENTRY, 0);
        r.read_exact(buf)
            .map_err(|e| format!("level {lod}: unreadable (truncated?): {e}"))?;
        let first = chunk * READ_TILES;
        for (k, (err, v)) in error
            .iter_mut()
            .zip(buf.chunks_exact(TILE_ENTRY))
            .enumerate()
        {
            let [lo, hi, er] = tile_entry(v, lod)?;
            *err = er;
            largest = largest.max(er);
            let i = first + k;
            match &mut coarse {
                None if folding => {}
                None => level.min_max[i] = [lo, hi],
                Some((factor, c)) => fold_tile(c, *factor, (i % nx, i / nx), [lo, hi, er]),
            }
        }
    }
    Ok(largest)
}

/// Folds tile `(x, y)` (`[min, max, error]`) into the tile `factor` times larger of `coarse`
/// that holds it (min, max, max: any order gives the same bits), for
/// [`TileStats::coarsened`] and the folded read.
fn fold_tile(
    coarse: &mut LevelTiles,
    factor: usize,
    (x, y): (usize, usize),
    [lo, hi, er]: [f32; 3],
) {
    let c = (y / factor) * coarse.tiles.0 as usize + x / factor;
    let m = &mut coarse.min_max[c];
    *m = [m[0].min(lo), m[1].max(hi)];
    coarse.error[c] = coarse.error[c].max(er);
}

/// Whether a read of stored statistics keeps the finest level's tiles: UDLOD reads without
/// them ([`TileStats::without_finest`]); chunked LOD and the tests keep them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Finest {
    Keep,
    Skip,
}

/// UDLOD's statistics for a split field of `density` nodes per tile side
/// (`Levels::from_field_stats`): the tiles' (`grid_size` quads) and the errors of the field's
/// cells (tiles of `grid_size / density` quads, whose heights are not held), both without
/// level 0's tiles. With one node per tile corner the cells are the tiles and `cells` is
/// empty. The tiles' statistics are coarsened from the cells', bit for bit those computed at
/// `grid_size` ([`TileStats::coarsened`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FieldStats {
    pub density: u32,
    pub tiles: TileStats,
    /// With `density > 1`: every level's cells with their errors (`min_max` empty).
    pub cells: Option<TileStats>,
}

impl FieldStats {
    /// From the cells' statistics in memory.
    pub fn from_cells(cells: TileStats, density: u32) -> Result<Self> {
        if density == 1 {
            return Ok(FieldStats {
                density,
                tiles: cells.without_finest(),
                cells: None,
            });
        }
        let mut cells = cells.without_finest();
        let tiles = cells.coarsened(density)?.without_finest();
        for level in &mut cells.levels {
            level.min_max = Vec::new();
        }
        Ok(FieldStats {
            density,
            tiles,
            cells: Some(cells),
        })
    }

    /// Reads the cells' stored statistics (`stats-g{cell grid}.bin` of `width x height`
    /// samples), checked as [`TileStats::read`] checks them, without ever holding the cells'
    /// heights: they fold into the tiles' as they are read. Equal to [`FieldStats::from_cells`]
    /// of the whole file.
    pub fn read(
        path: &std::path::Path,
        width: u32,
        height: u32,
        cell_grid: u32,
        density: u32,
    ) -> Result<Self> {
        if density == 1 {
            let cells = TileStats::read(path, width, height, cell_grid, Finest::Skip)?;
            return Self::from_cells(cells, 1);
        }
        let grid = coarse_grid(cell_grid, density)?;
        let mut tiles = TileStats::empty(&Shape::new(width, height, grid)?, Finest::Skip);
        let cells = TileStats::read_folding(
            path,
            width,
            height,
            cell_grid,
            Finest::Skip,
            Some(&mut tiles),
        )?;
        Ok(FieldStats {
            density,
            tiles,
            cells: Some(cells),
        })
    }
}

//! Reading a preprocessed data set directory: the manifest, single nodes, whole levels.

use std::fs::File;
use std::path::{Path, PathBuf};

use super::crs::Georef;
use super::manifest::{self, Manifest};
use super::pyramid::{
    LEVEL_HEADER, LEVEL_MAGIC, LayerSet, Layout, Node, level_header, read_node_from,
};
use super::stats::{self, FieldStats, Finest, TileStats};
use super::{Albedo, Heightmap};
use crate::error::{Error, Result};

/// One level assembled: `(width, height, heights, optional RGBA8 albedo)`, row 0 = south.
pub type LevelRaster = (u32, u32, Vec<f32>, Option<Vec<u8>>);

/// An opened data set: its manifest and layout.
#[derive(Clone, Debug)]
pub struct Dataset {
    pub dir: PathBuf,
    pub manifest: Manifest,
    pub layout: Layout,
    pub layers: LayerSet,
}

impl Dataset {
    /// Opens a data set directory; a directory without a manifest (e.g. left by an interrupted
    /// run) is refused.
    pub fn open(dir: &Path) -> Result<Self> {
        let what = dir.display().to_string();
        if dir.is_file() {
            return Err(Error::invalid(
                what,
                format!(
                    "is a file, not a vkterrain data set directory: build one from it with `vkterrain preprocess {} --out DIR` and point dataset.path at DIR",
                    dir.display()
                ),
            ));
        }
        let mpath = dir.join(manifest::FILE_NAME);
        let partial = dir
            .file_name()
            .is_some_and(|n| n.to_string_lossy().ends_with(".partial"));
        if partial || !mpath.is_file() {
            return Err(Error::invalid(
                what,
                format!(
                    "not a complete vkterrain data set (no {}): build one with `vkterrain preprocess INPUTS --out DIR` (a run that was interrupted leaves only DIR.partial; rerun it)",
                    manifest::FILE_NAME
                ),
            ));
        }
        let len = std::fs::metadata(&mpath)
            .map_err(|e| Error::io(&mpath, e))?
            .len();
        if len > manifest::MAX_BYTES {
            return Err(Error::invalid(
                mpath.display().to_string(),
                format!("{len} bytes is too large for a manifest"),
            ));
        }
        let text = std::fs::read_to_string(&mpath).map_err(|e| Error::io(&mpath, e))?;
        let m = Manifest::parse(&text, &mpath.display().to_string())?;
        let (layout, layers) = m.layout()?;
        Ok(Dataset {
            dir: dir.to_path_buf(),
            manifest: m,
            layout,
            layers,
        })
    }

    /// The stored UDLOD tile statistics for `grid_size`, checked against level 0's size
    /// (`finest`: whether level 0's tiles are read).
    pub fn tile_stats(&self, grid_size: u32, finest: Finest) -> Result<Option<TileStats>> {
        let Some(path) = self.stats_file(grid_size) else {
            return Ok(None);
        };
        if finest == Finest::Keep && !stats::stored_with_finest(&path)? {
            return Ok(None);
        }
        let (width, height) = self.level0_size();
        TileStats::read(&path, width, height, grid_size, finest).map(Some)
    }

    /// The stored statistics of tiles of `cell_grid` quads read for a split field of
    /// `density` nodes per tile side ([`FieldStats::read`]).
    pub fn field_stats(&self, cell_grid: u32, density: u32) -> Result<Option<FieldStats>> {
        let Some(path) = self.stats_file(cell_grid) else {
            return Ok(None);
        };
        let (width, height) = self.level0_size();
        FieldStats::read(&path, width, height, cell_grid, density).map(Some)
    }

    /// The statistics file stored for `grid_size`, if any.
    fn stats_file(&self, grid_size: u32) -> Option<PathBuf> {
        let info = self
            .manifest
            .tile_stats
            .iter()
            .find(|s| s.grid_size == grid_size)?;
        Some(self.dir.join(&info.file))
    }

    fn level0_size(&self) -> (u32, u32) {
        (self.manifest.width as u32, self.manifest.height as u32)
    }

    fn level_file(&self, lod: u32) -> Result<(File, PathBuf)> {
        let info = self.manifest.levels.get(lod as usize).ok_or_else(|| {
            Error::invalid(
                self.dir.display().to_string(),
                format!("no level {lod} (levels 0..{})", self.manifest.levels.len()),
            )
        })?;
        let path = self.dir.join(&info.file);
        let mut f = File::open(&path).map_err(|e| Error::io(&path, e))?;
        let len = f.metadata().map_err(|e| Error::io(&path, e))?.len();
        let want = LEVEL_HEADER + info.nodes_x as u64 * info.nodes_y as u64 * info.record_size;
        if len != want {
            return Err(Error::invalid(
                path.display().to_string(),
                format!("{len} bytes, expected {want}: truncated or altered"),
            ));
        }
        let mut head = [0u8; LEVEL_HEADER as usize];
        std::io::Read::read_exact(&mut f, &mut head).map_err(|e| Error::io(&path, e))?;
        if &head[..8] != LEVEL_MAGIC {
            return Err(Error::invalid(
                path.display().to_string(),
                "not a vkterrain level file",
            ));
        }
        if head[..] != level_header(&self.layout, lod, self.layers)[..] {
            return Err(Error::invalid(
                path.display().to_string(),
                "level header (version, level, nodes, node size, layers) disagrees with the manifest",
            ));
        }
        Ok((f, path))
    }

    /// Opens level `lod`'s file after checking its size and magic (for repeated
    /// [`super::pyramid::read_node_from`] calls).
    pub fn open_level(&self, lod: u32) -> Result<(File, PathBuf)> {
        self.level_file(lod)
    }

    /// Reads one node alone (one seek, one read of its record).
    pub fn read_node(&self, lod: u32, x: u32, y: u32) -> Result<Node> {
        let (mut f, path) = self.level_file(lod)?;
        read_node_from(&mut f, &path, &self.layout, lod, self.layers, x, y)
    }

    /// Level `lod`'s valid samples as one raster (row 0 = south), with albedo if present.
    pub fn level_raster(&self, lod: u32) -> Result<LevelRaster> {
        let (mut f, path) = self.level_file(lod)?;
        let (w, h) = self.layout.level_size(lod);
        let (nx, ny) = self.layout.nodes(lod);
        let c = self.layout.center as u64;
        let mut heights = vec![0f32; (w * h) as usize];
        let mut rgba = self.layers.albedo.then(|| vec![0u8; (w * h * 4) as usize]);
        for y in 0..ny {
            for x in 0..nx {
                let n = read_node_from(&mut f, &path, &self.layout, lod, self.layers, x, y)?;
                let s = self.layout.side() as usize;
                let b = self.layout.border as usize;
                for j in 0..c.min(h - y as u64 * c) {
                    for i in 0..c.min(w - x as u64 * c) {
                        let (gu, gv) = (x as u64 * c + i, y as u64 * c + j);
                        let src = (j as usize + b) * s + i as usize + b;
                        let dst = (gv * w + gu) as usize;
                        heights[dst] = n.heights[src];
                        if let Some(a) = rgba.as_mut() {
                            a[dst * 4..dst * 4 + 4].copy_from_slice(&n.rgba[src * 4..src * 4 + 4]);
                        }
                    }
                }
            }
        }
        Ok((w as u32, h as u32, heights, rgba))
    }
}

/// Default bound on the samples of a level assembled into one [`Heightmap`].
pub const DEFAULT_MAX_SAMPLES: u64 = 4097 * 4097;

/// How a grid whose samples are not square in metres (a geographic grid) is loaded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LoadGrid {
    /// Resampled east-west to the north-south spacing: a square grid for the flat world
    /// (`[render] earth = "flat"`, the evaluator).
    #[default]
    SquareMetres,
    /// The data set's own samples, every one of them (the ellipsoid's geolocation lattice
    /// places them): `spacing` is the smallest metric spacing anywhere on the grid (LOD
    /// distances measured with it err on the fine side), `axis_spacing` the stated ones.
    Native,
}

/// Loads level `lod` (or, without one, the finest level of at most `max_samples` samples
/// that fits [`super::MAX_SIDE`]) as a [`Heightmap`] for the brute-force renderer. Coarser levels
/// have `2^lod` times the spacing; non-square spacing (geographic data) is resampled
/// east-west to the north-south spacing ([`LoadGrid::SquareMetres`]; [`load_as`] chooses).
pub fn load(dir: &Path, lod: Option<u32>, max_samples: u64) -> Result<Heightmap> {
    load_as(dir, lod, max_samples, LoadGrid::SquareMetres)
}

/// Non-square grids are resampled for the flat world and kept native on the ellipsoid.
pub use crate::geo::is_square;

/// The LOD metric of a native grid whose stated metres between samples are `[sx, sy]`
/// (`height` rows, georeferenced by `georef`): the smallest metric spacing anywhere on it, so
/// distances measured with it are never longer than true ones. A geographic grid's stated
/// east-west spacing holds at its centre latitude and shrinks with cos(latitude) towards the
/// pole.
pub fn native_lod_spacing(georef: Option<&Georef>, height: u64, [sx, sy]: [f64; 2]) -> f64 {
    use super::crs::CrsKind;
    let ew = match georef {
        Some(g) if g.crs.kind == CrsKind::Geographic => {
            let deg = g.crs.unit_size.to_degrees();
            let last = height.max(1) as f64 - 1.0;
            let (a, b) = (g.at(0.0, 0.0)[1] * deg, g.at(0.0, last)[1] * deg);
            let (centre, pole) = ((a + b) / 2.0, a.abs().max(b.abs()).min(89.999));
            sx * pole.to_radians().cos() / centre.to_radians().cos()
        }
        _ => sx,
    };
    ew.min(sy)
}

/// The level [`load_as`] loads: `lod` where it exists and fits [`super::MAX_SIDE`] per side,
/// else (None) the finest whose samples fit `max_samples` too, or the coarsest.
fn load_level(ds: &Dataset, dir: &Path, lod: Option<u32>, max_samples: u64) -> Result<u32> {
    let levels = ds.manifest.levels.len() as u32;
    let Some(l) = lod else {
        let fits = |l: u32| {
            let (w, h) = ds.layout.level_size(l);
            w <= super::MAX_SIDE as u64 && h <= super::MAX_SIDE as u64 && w * h <= max_samples
        };
        return Ok((0..levels).find(|&l| fits(l)).unwrap_or(levels - 1));
    };
    if l >= levels {
        return Err(Error::invalid(
            "dataset.lod",
            format!("{l} but {} has levels 0..{levels}", dir.display()),
        ));
    }
    let (w, h) = ds.layout.level_size(l);
    if w > super::MAX_SIDE as u64 || h > super::MAX_SIDE as u64 {
        return Err(Error::invalid(
            "dataset.lod",
            format!("level {l} is {w}x{h}, over {} per side", super::MAX_SIDE),
        ));
    }
    Ok(l)
}

/// `heights` (`w` x `h`, spacing `sx` east-west, `sy` north-south) resampled linearly along
/// each row to spacing `sy`: the new width and samples.
fn resample_east_west([w, h]: [u32; 2], heights: &[f32], [sx, sy]: [f64; 2]) -> (u32, Vec<f32>) {
    let w2 = (((w - 1) as f64 * sx / sy).round() as u32 + 1).max(2);
    let mut out = Vec::with_capacity(w2 as usize * h as usize);
    for r in 0..h as usize {
        let row = &heights[r * w as usize..(r + 1) * w as usize];
        for c in 0..w2 {
            let g = (c as f64 * sy / sx).min((w - 1) as f64);
            let c0 = g.floor() as usize;
            let c1 = (c0 + 1).min(w as usize - 1);
            let f = g - c0 as f64;
            out.push((row[c0] as f64 * (1.0 - f) + row[c1] as f64 * f) as f32);
        }
    }
    (w2, out)
}

/// [`load`] with the grid's loading chosen by `grid`.
pub fn load_as(
    dir: &Path,
    lod: Option<u32>,
    max_samples: u64,
    grid: LoadGrid,
) -> Result<Heightmap> {
    let ds = Dataset::open(dir)?;
    let lod = load_level(&ds, dir, lod, max_samples)?;
    let (w, h, heights, rgba) = ds.level_raster(lod)?;
    let scale = (1u64 << lod) as f64;
    let [sx, sy] = ds.manifest.spacing.map(|s| s * scale);
    let square = is_square([sx, sy]);
    let label = if lod == 0 {
        String::new()
    } else {
        format!(" level {lod}")
    };
    let name = format!("{}{label} ({})", ds.manifest.name, ds.manifest.content);
    let albedo = rgba.map(|rgba| Albedo {
        width: w,
        height: h,
        rgba,
    });
    if grid == LoadGrid::Native && !square {
        let lod_spacing =
            native_lod_spacing(ds.manifest.georef.as_ref(), ds.manifest.height, [sx, sy]);
        let mut map = Heightmap::new(name, w, h, lod_spacing, heights)?;
        map.axis_spacing = [sx, sy];
        map.source_step = [scale, scale];
        map.albedo = albedo;
        return Ok(map);
    }
    // The flat world draws a square-sampled grid, so a geographic (or otherwise non-square)
    // native grid is resampled east-west to the north-south spacing here, at load time. The
    // data set itself keeps the native grid ([`LoadGrid::Native`] loads it).
    let (w2, heights) = if !square {
        resample_east_west([w, h], &heights, [sx, sy])
    } else {
        (w, heights)
    };
    let mut map = Heightmap::new(name, w2, h, sy, heights)?;
    map.source_step = [scale * sy / sx, scale];
    map.albedo = albedo;
    Ok(map)
}

//! `vkterrain preprocess`: sources -> void filling -> node pyramid -> tile statistics ->
//! manifest, written atomically: everything goes to `<out>.partial/` (claimed with a lock,
//! removed on any failure), renamed to `<out>` once complete. Levels are built in parallel
//! (rayon), each record with bounded memory; the output is the same bit for bit for any
//! number of threads.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::crs::Georef;
use super::gdal_in::{self, ReadOptions};
use super::interp::GridCell;
use super::manifest::{self, LevelInfo, Manifest, StatsInfo, datum};
use super::output::{self, PartialDir, human_bytes};
use super::procedural::{self, ProceduralParams};
use super::pyramid::{
    self, Block, LayerSet, Layout, LeafSource, LevelInput, LevelRows, MAX_SIDE_SAMPLES,
};
use super::source::Raster;
use super::stats::TileStats;
use super::{voids, xyz};
use crate::error::{Error, Result};

/// What to preprocess.
#[derive(Clone, Debug)]
pub enum Input {
    /// DEM files GDAL reads: one raster, or several forming a mosaic.
    Files(Vec<PathBuf>),
    /// The procedural generator (`size x size` samples).
    Procedural(ProceduralParams),
    /// A raster already in memory (voids `NaN`): tests and library users.
    Raster(Raster),
    /// XYZ terrain tiles over a bounding box at one zoom level.
    Xyz(xyz::XyzRequest),
}

#[derive(Clone, Debug)]
pub struct Options {
    pub input: Input,
    pub out: PathBuf,
    pub albedo: Option<PathBuf>,
    /// Metres between samples (required without georeferencing, overrides it otherwise).
    pub spacing: Option<f64>,
    /// Metres per unit (PNG; scales other sources too when given).
    pub vertical_scale: Option<f64>,
    pub center_size: u32,
    pub border_size: u32,
    /// Amplify a real DEM `k` times with procedural detail below its resolution.
    pub amplify: Option<(u32, u64)>,
    /// Replace an existing data set at `out` (never anything else).
    pub force: bool,
    /// Target CRS of a warped mosaic (`EPSG:xxxx`, WKT or PROJ string).
    pub crs: Option<String>,
    /// UDLOD tile sizes whose statistics are stored.
    pub stats_grid_sizes: Vec<u32>,
    /// Datum of the heights when the source does not say (`manifest::datum`).
    pub vertical_datum: Option<String>,
    /// Bytes of memory a raster source may use (default: what the system has available).
    pub memory_budget: Option<u64>,
}

/// The tile size whose statistics are stored unless told otherwise (the cells of UDLOD's
/// default split field, grid 4 with two nodes per side; grid 4 with one node per corner folds
/// them too; other sizes are computed from level 0 at start-up, or stored with
/// `--stats-grid-sizes`).
pub const DEFAULT_STATS_GRID_SIZES: [u32; 1] = [2];

/// The smallest stored grid size whose file keeps level 0's tiles. UDLOD never reads them (it
/// skips level 0), chunked LOD reads its own chunks' (`chunk_quads`, 16 by default, computed
/// from level 0 where not stored); at grid 2 they would be three quarters of the file, about 3
/// bytes per level-0 sample (docs/dataset-format.md).
pub const FINEST_STORED_FROM_GRID: u32 = 4;

impl Default for Options {
    fn default() -> Self {
        Options {
            input: Input::Procedural(ProceduralParams::default()),
            out: PathBuf::from("dataset"),
            albedo: None,
            spacing: None,
            vertical_scale: None,
            center_size: 256,
            border_size: 2,
            amplify: None,
            force: false,
            crs: None,
            stats_grid_sizes: DEFAULT_STATS_GRID_SIZES.to_vec(),
            vertical_datum: None,
            memory_budget: None,
        }
    }
}

/// Progress reports (the CLI draws bars; tests pass [`NoProgress`]). Called from worker
/// threads, hence `Sync` and `&self`.
pub trait Progress: Sync {
    fn stage(&self, _what: &str) {}
    /// A counted step: `total` units (nodes or rows) follow.
    fn level(&self, _what: &str, _total: u64) {}
    fn advance(&self, _n: u64) {}
    fn level_done(&self) {}
    /// Something looked wrong in the data (processing continues).
    fn warning(&self, _line: &str) {}
}

pub struct NoProgress;
impl Progress for NoProgress {}

/// What a run produced.
#[derive(Clone, Debug)]
pub struct Summary {
    pub out: PathBuf,
    pub name: String,
    pub content: String,
    pub width: u64,
    pub height: u64,
    pub levels: u32,
    pub nodes: u64,
    pub bytes: u64,
    pub voids_filled: u64,
    /// Bytes of the input files read (0 for procedural).
    pub source_bytes: u64,
    pub seconds: f64,
    pub height_range: [f32; 2],
    pub warnings: Vec<String>,
}

/// Reads the DEM inputs into one raster (voids still `NaN`), `vertical_scale` applied.
pub fn read_inputs(
    paths: &[PathBuf],
    spacing: Option<f64>,
    vertical_scale: Option<f64>,
) -> Result<Raster> {
    read_inputs_with(
        paths,
        &ReadOptions {
            spacing,
            ..Default::default()
        },
        vertical_scale,
    )
}

fn read_inputs_with(
    paths: &[PathBuf],
    ropts: &ReadOptions,
    vertical_scale: Option<f64>,
) -> Result<Raster> {
    let mut raster = gdal_in::read(paths, ropts)?;
    if let Some(vs) = vertical_scale {
        for h in &mut raster.heights {
            *h = (*h as f64 * vs) as f32;
        }
        raster
            .provenance
            .push(format!("heights multiplied by --vertical-scale {vs}"));
    }
    super::source::plausibility_warnings(&mut raster);
    Ok(raster)
}

/// An RGBA image placed over the DEM: `at(fx, fy)` samples it bilinearly at the fraction
/// `(fx, fy)` of the DEM's sample extent (0 = first sample, 1 = last; y north).
pub struct AlbedoSampler {
    width: u32,
    height: u32,
    /// Row 0 = south.
    rgba: Vec<u8>,
    /// Pixel coordinate (centre-based) of fraction 0 and per unit fraction, x and y.
    map: [f64; 4],
}

impl AlbedoSampler {
    /// Loads `path` and aligns it with `dem`: by its world file (`.pgw`, `.jgw`, `.wld`, ...,
    /// read by GDAL) when both are georeferenced, else by extent (the image spans the DEM exactly, so their
    /// aspect ratios must agree within 2 %).
    pub fn open(path: &Path, dem: &Raster) -> Result<Self> {
        let img = image::ImageReader::open(path)
            .map_err(|e| Error::io(path, e))?
            .with_guessed_format()
            .map_err(|e| Error::io(path, e))?
            .decode()
            .map_err(|e| Error::invalid(path.display().to_string(), e.to_string()))?;
        let rgba8 = img.to_rgba8();
        let (aw, ah) = rgba8.dimensions();
        if aw < 2 || ah < 2 {
            return Err(Error::invalid(
                path.display().to_string(),
                format!("imagery {aw}x{ah} is too small"),
            ));
        }
        let raw = rgba8.as_raw();
        let mut rgba = Vec::with_capacity(raw.len());
        for r in (0..ah as usize).rev() {
            rgba.extend_from_slice(&raw[r * aw as usize * 4..(r + 1) * aw as usize * 4]);
        }
        // GDAL reads the image's world file (.pgw, .jgw, .wld, ...), if any.
        let world = super::gdal_in::image_transform(path);
        let map = match (world, dem.bounds()) {
            (Some(t), Some([x0, y0, x1, y1])) => {
                if t[2] != 0.0 || t[4] != 0.0 || t[1] == 0.0 || t[5] == 0.0 {
                    return Err(Error::invalid(
                        path.display().to_string(),
                        format!("imagery georeferencing {t:?} is rotated"),
                    ));
                }
                // Pixel centre (col, row from north): x = t0 + (col + 0.5) t1, y = t3 + (row + 0.5) t5.
                let px = |x: f64| (x - t[0]) / t[1] - 0.5;
                let py_south = |y: f64| (ah - 1) as f64 - ((y - t[3]) / t[5] - 0.5);
                let (c0, c1) = (px(x0), px(x1));
                let (r0, r1) = (py_south(y0), py_south(y1));
                let inside = |v: f64, n: u32| v >= -0.5 - 1e-6 && v <= n as f64 - 0.5 + 1e-6;
                if !(inside(c0, aw) && inside(c1, aw) && inside(r0, ah) && inside(r1, ah)) {
                    return Err(Error::invalid(
                        path.display().to_string(),
                        format!(
                            "imagery (georeferenced by its world file) does not cover the DEM extent {x0},{y0}..{x1},{y1}"
                        ),
                    ));
                }
                [c0, c1 - c0, r0, r1 - r0]
            }
            _ => {
                let dem_aspect = dem.spacing[0] * (dem.width - 1) as f64
                    / (dem.spacing[1] * (dem.height - 1) as f64);
                let img_aspect = aw as f64 / ah as f64;
                if (dem_aspect / img_aspect - 1.0).abs() > 0.02 {
                    return Err(Error::invalid(
                        path.display().to_string(),
                        format!(
                            "imagery {aw}x{ah} (aspect {img_aspect:.3}) does not cover the DEM extent (aspect {dem_aspect:.3}); give imagery spanning exactly the DEM or a world file"
                        ),
                    ));
                }
                // Image edges coincide with the outermost samples.
                [-0.5, aw as f64, -0.5, ah as f64]
            }
        };
        Ok(AlbedoSampler {
            width: aw,
            height: ah,
            rgba,
            map,
        })
    }

    pub fn at(&self, fx: f64, fy: f64) -> [u8; 4] {
        let cell = GridCell::at(
            self.map[0] + fx * self.map[1],
            self.map[2] + fy * self.map[3],
            self.width,
            self.height,
        );
        let w = self.width as usize;
        std::array::from_fn(|ch| {
            let p = |x: u32, y: u32| self.rgba[(y as usize * w + x as usize) * 4 + ch] as f64;
            cell.bilinear(p).round() as u8
        })
    }
}

/// Leaves from an in-memory raster (void-filled), optionally amplified.
struct RasterLeaves<'a> {
    layout: Layout,
    heights: &'a [f32],
    mask: &'a [u8],
    w: u32,
    h: u32,
    albedo: Option<&'a AlbedoSampler>,
    /// `(factor, seed, wavelength, amplitude, spacing)` for amplification.
    amplify: Option<(u32, u64, f64, f64, [f64; 2])>,
}

impl RasterLeaves<'_> {
    fn texel(&self, u: u64, v: u64) -> (f32, u8) {
        match self.amplify {
            None => {
                let k = v as usize * self.w as usize + u as usize;
                (self.heights[k], self.mask[k])
            }
            Some((f, seed, wl, amp, sp)) => {
                let (gx, gy) = (u as f64 / f as f64, v as f64 / f as f64);
                let s =
                    |x: u32, y: u32| self.heights[y as usize * self.w as usize + x as usize] as f64;
                let base = GridCell::at(gx, gy, self.w, self.h).bilinear(s);
                let d = procedural::detail(seed, u as f64 * sp[0], v as f64 * sp[1], wl, amp);
                let near = gy.round() as usize * self.w as usize + gx.round() as usize;
                ((base + d) as f32, self.mask[near])
            }
        }
    }
}

impl LeafSource for RasterLeaves<'_> {
    fn texels(&self, cols: &[u64], rows: &[u64], layers: LayerSet, out: &mut Block) -> Result<()> {
        let (lw, lh) = (self.layout.width, self.layout.height);
        out.heights.clear();
        out.mask.clear();
        out.rgba.clear();
        for &v in rows {
            for &u in cols {
                let (h, m) = self.texel(u, v);
                out.heights.push(h);
                if layers.mask {
                    out.mask.push(m);
                }
                if let (true, Some(a)) = (layers.albedo, self.albedo) {
                    out.rgba.extend_from_slice(
                        &a.at(u as f64 / (lw - 1) as f64, v as f64 / (lh - 1) as f64),
                    );
                }
            }
        }
        Ok(())
    }
}

/// Leaves computed by the procedural generator texel by texel (nothing of level-0 size).
struct ProceduralLeaves {
    params: ProceduralParams,
}

impl LeafSource for ProceduralLeaves {
    fn texels(&self, cols: &[u64], rows: &[u64], _: LayerSet, out: &mut Block) -> Result<()> {
        out.heights.clear();
        out.mask.clear();
        out.rgba.clear();
        let s = self.params.spacing;
        for &v in rows {
            for &u in cols {
                out.heights
                    .push(procedural::height(&self.params, u as f64 * s, v as f64 * s) as f32);
            }
        }
        Ok(())
    }
}

/// The level-0 source after stage 1.
struct Source {
    raster: Option<Raster>,
    mask: Vec<u8>,
    params: Option<ProceduralParams>,
    source_bytes: u64,
    voids_filled: u64,
}

fn check_options(opts: &Options) -> Result<()> {
    if let Some(vs) = opts.vertical_scale
        && !(vs.is_finite() && vs > 0.0)
    {
        return Err(Error::invalid(
            "--vertical-scale",
            format!("{vs} is not positive"),
        ));
    }
    if let Some((k, _)) = opts.amplify
        && !(2..=64).contains(&k)
    {
        return Err(Error::invalid(
            "--amplify",
            format!("factor {k} is outside 2..=64"),
        ));
    }
    for &g in &opts.stats_grid_sizes {
        if !(2..=64).contains(&g) || g % 2 != 0 {
            return Err(Error::invalid(
                "--stats-grid-sizes",
                format!("{g} is not an even tile size within 2..=64 (UDLOD's grid_size)"),
            ));
        }
    }
    if let Some(d) = &opts.vertical_datum
        && (d.is_empty() || d.len() > 64 || !d.chars().all(|c| c.is_ascii_graphic()))
    {
        return Err(Error::invalid(
            "--vertical-datum",
            format!("{d:?} is not a datum name (e.g. egm96, egm2008, ellipsoid, unknown)"),
        ));
    }
    if let Input::Procedural(p) = &opts.input {
        if p.size < 2 || p.size as u64 > MAX_SIDE_SAMPLES {
            return Err(Error::invalid(
                "--size",
                format!(
                    "{} is outside 2..={MAX_SIDE_SAMPLES} samples per side (the format's limit)",
                    p.size
                ),
            ));
        }
        if !(p.spacing.is_finite() && p.spacing > 0.0) {
            return Err(Error::invalid(
                "--spacing",
                format!("{} m is not positive", p.spacing),
            ));
        }
        if opts.albedo.is_some() || opts.amplify.is_some() {
            return Err(Error::invalid(
                "--procedural",
                "takes neither --albedo nor --amplify",
            ));
        }
    }
    Layout::new(2, 2, opts.center_size, opts.border_size).map(|_| ())
}

/// Stage 1: the level-0 source (rasters read and void-filled).
fn read_source(opts: &Options, progress: &dyn Progress) -> Result<Source> {
    let mut source_bytes = 0u64;
    let mut raster = match &opts.input {
        Input::Files(paths) => {
            progress.stage("reading sources (GDAL)");
            for p in paths {
                source_bytes += std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
            }
            let ropts = ReadOptions {
                spacing: opts.spacing,
                crs: opts.crs.clone(),
                memory_budget: opts.memory_budget,
            };
            Some(read_inputs_with(paths, &ropts, opts.vertical_scale)?)
        }
        Input::Xyz(req) => {
            progress.stage("fetching XYZ tiles");
            let (mut r, bytes) = xyz::read_raster(req, opts.memory_budget)?;
            super::source::plausibility_warnings(&mut r);
            source_bytes = bytes;
            Some(r)
        }
        Input::Raster(r) => {
            let mut r = r.clone();
            if let Some(s) = opts.spacing {
                r.spacing = [s, s];
            }
            Some(r)
        }
        Input::Procedural(_) => None,
    };
    let (mut mask, mut voids_filled) = (Vec::new(), 0);
    if let Some(r) = raster.as_mut() {
        for w in &r.warnings {
            progress.warning(w);
        }
        progress.stage("filling voids");
        let (m, n) = voids::fill(&r.name, &mut r.heights, r.width, r.height)?;
        if n > 0 {
            r.provenance.push(format!(
                "{n} void samples filled by push-pull interpolation (void_mask layer = 1)"
            ));
        }
        voids_filled = n;
        mask = m;
    }
    let params = match &opts.input {
        Input::Procedural(p) => Some(*p),
        _ => None,
    };
    Ok(Source {
        raster,
        mask,
        params,
        source_bytes,
        voids_filled,
    })
}

/// Describes the data set to build: its extent, grid and provenance.
struct Plan {
    width: u64,
    height: u64,
    spacing: [f64; 2],
    name: String,
    georef: Option<Georef>,
    vertical_datum: String,
    nodata: Option<f64>,
    provenance: Vec<String>,
    warnings: Vec<String>,
    content: &'static str,
}

fn plan(opts: &Options, src: &Source) -> Result<Plan> {
    Ok(match (&src.raster, &src.params) {
        (Some(r), _) => {
            let (w, h, sp, content) = match opts.amplify {
                Some((k, _)) => (
                    (r.width as u64 - 1) * k as u64 + 1,
                    (r.height as u64 - 1) * k as u64 + 1,
                    [r.spacing[0] / k as f64, r.spacing[1] / k as f64],
                    "amplified",
                ),
                None => (r.width as u64, r.height as u64, r.spacing, "real"),
            };
            let georef = match (opts.amplify, &r.georef) {
                (Some((k, _)), Some(g)) => {
                    let [sx, sy] = g.step();
                    Some(Georef::north_up(
                        g.crs.clone(),
                        g.origin(),
                        [sx / k as f64, sy / k as f64],
                    ))
                }
                (_, g) => g.clone(),
            };
            Plan {
                width: w,
                height: h,
                spacing: sp,
                name: if content == "amplified" {
                    format!("{} (amplified with procedural detail)", r.name)
                } else {
                    r.name.clone()
                },
                georef,
                vertical_datum: r.vertical_datum.clone(),
                nodata: r.nodata,
                provenance: r.provenance.clone(),
                warnings: r.warnings.clone(),
                content,
            }
        }
        (None, Some(p)) => Plan {
            width: p.size as u64,
            height: p.size as u64,
            spacing: [p.spacing, p.spacing],
            name: format!(
                "procedural size={} seed={} spacing={} m",
                p.size, p.seed, p.spacing
            ),
            georef: None,
            vertical_datum: datum::LOCAL.into(),
            nodata: None,
            provenance: vec![format!(
                "procedural generator (style {:?}, seed {}, max height {} m, feature size {} m)",
                p.style, p.seed, p.max_height, p.feature_size
            )],
            warnings: Vec::new(),
            content: "procedural",
        },
        _ => unreachable!("one source"),
    })
}

/// Bytes the data set will take: every level file plus the statistics files.
pub fn estimate_bytes(layout: &Layout, layers: LayerSet, grid_sizes: &[u32]) -> Result<u64> {
    let mut total = 0u64;
    for lod in 0..layout.levels() {
        let (nx, ny) = layout.nodes(lod);
        total = total.saturating_add(
            pyramid::LEVEL_HEADER
                + (nx as u64 * ny as u64).saturating_mul(layout.record_size(layers)),
        );
    }
    for &g in grid_sizes {
        total = total.saturating_add(TileStats::stored_size(
            layout.width.min(u32::MAX as u64) as u32,
            layout.height.min(u32::MAX as u64) as u32,
            g,
            g >= FINEST_STORED_FROM_GRID,
        )?);
    }
    Ok(total)
}

/// The albedo image, aligned to the DEM source (it has nothing to align to without one).
fn open_albedo(opts: &Options, src: &Source) -> Result<Option<AlbedoSampler>> {
    Ok(match (&opts.albedo, &src.raster) {
        (Some(a), Some(r)) => Some(AlbedoSampler::open(a, r)?),
        (Some(_), None) => {
            return Err(Error::invalid("--albedo", "needs a DEM source"));
        }
        _ => None,
    })
}

impl Plan {
    /// Records what the options add to the source: a vertical datum given on the command line
    /// (it replaces the source's), and where the albedo came from.
    fn note_options(&mut self, opts: &Options, albedo: Option<&AlbedoSampler>) {
        if let Some(d) = &opts.vertical_datum {
            self.provenance.push(format!(
                "vertical datum {d} given by --vertical-datum (the source said {})",
                self.vertical_datum
            ));
            self.vertical_datum = d.clone();
        }
        if let (Some(a), Some(p)) = (&opts.albedo, albedo) {
            self.provenance.push(format!(
                "albedo {} ({}x{}) aligned by {}",
                a.display(),
                p.width,
                p.height,
                if p.map == [-0.5, p.width as f64, -0.5, p.height as f64] {
                    "extent"
                } else {
                    "world file"
                }
            ));
        }
    }

    /// [`RasterLeaves::amplify`] for `--amplify` over a DEM; the provenance says loudly that the
    /// detail below the source's resolution is invented.
    fn amplification(
        &mut self,
        opts: &Options,
        src: &Source,
    ) -> Option<(u32, u64, f64, f64, [f64; 2])> {
        match (opts.amplify, &src.raster) {
            (Some((k, seed)), Some(r)) => {
                let wl = r.spacing[0].min(r.spacing[1]);
                let amp = 0.05 * wl;
                self.provenance.push(format!(
                    "AMPLIFIED: bilinear upsampling x{k} plus procedural detail (seed {seed}, wavelength {wl:.2} m, amplitude {amp:.2} m) below the source resolution; not measured data"
                ));
                Some((k, seed, wl, amp, self.spacing))
            }
            _ => None,
        }
    }
}

/// Refuses before anything is written when the output's file system has less than `need` free.
fn check_free_space(opts: &Options, need: u64) -> Result<()> {
    let parent = opts
        .out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if let Some(free) = output::free_bytes(parent)
        && need > free
    {
        return Err(Error::invalid(
            opts.out.display().to_string(),
            format!(
                "the data set needs {} on disk, {} is free there (nothing was written)",
                human_bytes(need),
                human_bytes(free)
            ),
        ));
    }
    Ok(())
}

/// What stage 2 wrote: the level files and level 0's height range.
struct WrittenLevels {
    levels: Vec<LevelInfo>,
    nodes: u64,
    bytes: u64,
    range: [f32; 2],
}

/// Stage 2: the level files in `tmp`, finest first; each coarser level reads only the previous
/// level file.
fn write_levels(
    tmp: &Path,
    layout: Layout,
    layers: LayerSet,
    leaves: &dyn LeafSource,
    progress: &dyn Progress,
) -> Result<WrittenLevels> {
    let mut levels = Vec::new();
    let (mut nodes, mut bytes) = (0u64, 0u64);
    let mut range = [f32::INFINITY, f32::NEG_INFINITY];
    for lod in 0..layout.levels() {
        let (nx, ny) = layout.nodes(lod);
        progress.level(&format!("level {lod:>2}"), nx as u64 * ny as u64);
        let file = manifest::level_file(lod);
        let path = tmp.join(&file);
        let child = tmp.join(manifest::level_file(lod.saturating_sub(1)));
        let input = if lod == 0 {
            LevelInput::Leaves(leaves)
        } else {
            LevelInput::Child(&child)
        };
        let stats =
            pyramid::write_level(&path, &layout, lod, layers, input, &|n| progress.advance(n))?;
        progress.level_done();
        if lod == 0 {
            range = [stats.min, stats.max];
        }
        let (w, h) = layout.level_size(lod);
        levels.push(LevelInfo {
            lod,
            width: w,
            height: h,
            nodes_x: nx,
            nodes_y: ny,
            file,
            record_size: layout.record_size(layers),
            bytes: stats.bytes,
        });
        nodes += stats.nodes;
        bytes += stats.bytes;
    }
    Ok(WrittenLevels {
        levels,
        nodes,
        bytes,
        range,
    })
}

/// Stage 3: UDLOD's tile statistics from the written level 0; with the bytes written.
fn write_tile_stats(
    tmp: &Path,
    layout: Layout,
    layers: LayerSet,
    row_spacing: f64,
    grid_sizes: &[u32],
    progress: &dyn Progress,
) -> Result<(Vec<StatsInfo>, u64)> {
    let mut tile_stats = Vec::new();
    let mut bytes = 0u64;
    let rows = LevelRows::open(
        &tmp.join(manifest::level_file(0)),
        layout,
        layers,
        row_spacing,
    )?;
    for &g in grid_sizes {
        progress.level(&format!("stats g{g:>2}"), layout.height);
        let mut stats = TileStats::compute(&rows, g, &|n| progress.advance(n))?;
        progress.level_done();
        if g < FINEST_STORED_FROM_GRID {
            stats = stats.without_finest();
        }
        let file = manifest::stats_file(g);
        let n = stats.write(&tmp.join(&file))?;
        bytes += n;
        tile_stats.push(StatsInfo {
            grid_size: g,
            file,
            bytes: n,
        });
    }
    Ok((tile_stats, bytes))
}

/// The manifest describing the written files.
fn manifest_of(
    plan: &Plan,
    layout: &Layout,
    layers: LayerSet,
    written: WrittenLevels,
    tile_stats: Vec<StatsInfo>,
    voids_filled: u64,
) -> Manifest {
    Manifest {
        format: manifest::FORMAT.into(),
        version: manifest::VERSION,
        name: plan.name.clone(),
        width: plan.width,
        height: plan.height,
        spacing: plan.spacing,
        extent: [
            (plan.width - 1) as f64 * plan.spacing[0],
            (plan.height - 1) as f64 * plan.spacing[1],
        ],
        georef: plan.georef.clone(),
        vertical_datum: plan.vertical_datum.clone(),
        nodata: plan.nodata.filter(|v| v.is_finite()),
        center_size: layout.center,
        border_size: layout.border,
        levels: written.levels,
        layers: manifest::Layers {
            height: "f32le".into(),
            void_mask: layers.mask,
            albedo: layers.albedo.then(|| "rgba8_srgb".into()),
        },
        height_range: written.range,
        voids_filled,
        content: plan.content.into(),
        provenance: plan.provenance.clone(),
        warnings: plan.warnings.clone(),
        tile_stats,
        created_by: format!("vkterrain {}", env!("CARGO_PKG_VERSION")),
    }
}

/// Writes the manifest into `tmp` (temp + rename), returning its size: it comes last, so a
/// directory with a manifest has all its files.
fn write_manifest(tmp: &Path, m: &Manifest) -> Result<u64> {
    m.check("manifest being written")?;
    let json = serde_json::to_string_pretty(m).expect("manifest serialises");
    let mtmp = tmp.join("manifest.json.tmp");
    write_synced(&mtmp, json.as_bytes())?;
    std::fs::rename(&mtmp, tmp.join(manifest::FILE_NAME)).map_err(|e| Error::io(&mtmp, e))?;
    Ok(json.len() as u64)
}

/// Runs the whole pipeline.
pub fn run(opts: &Options, progress: &dyn Progress) -> Result<Summary> {
    let t0 = Instant::now();
    check_options(opts)?;
    output::check_target(&opts.out, opts.force)?;
    let src = read_source(opts, progress)?;
    let albedo = open_albedo(opts, &src)?;
    let mut plan = plan(opts, &src)?;
    plan.note_options(opts, albedo.as_ref());
    let layout = Layout::new(plan.width, plan.height, opts.center_size, opts.border_size)?;
    let layers = LayerSet {
        mask: src.raster.is_some(),
        albedo: albedo.is_some(),
    };
    let amplify = plan.amplification(opts, &src);
    check_free_space(
        opts,
        estimate_bytes(&layout, layers, &opts.stats_grid_sizes)?,
    )?;
    let partial = PartialDir::claim(&opts.out)?;
    let tmp = partial.path.clone();

    let leaves: Box<dyn LeafSource + '_> = match (&src.raster, src.params) {
        (Some(r), _) => Box::new(RasterLeaves {
            layout,
            heights: &r.heights,
            mask: &src.mask,
            w: r.width,
            h: r.height,
            albedo: albedo.as_ref(),
            amplify,
        }),
        (None, Some(p)) => Box::new(ProceduralLeaves { params: p }),
        _ => unreachable!("one source"),
    };
    let written = write_levels(&tmp, layout, layers, &*leaves, progress)?;
    drop(leaves);
    let (nodes, range) = (written.nodes, written.range);
    let (tile_stats, stats_bytes) = write_tile_stats(
        &tmp,
        layout,
        layers,
        plan.spacing[1],
        &opts.stats_grid_sizes,
        progress,
    )?;
    let mut bytes = written.bytes + stats_bytes;
    let m = manifest_of(
        &plan,
        &layout,
        layers,
        written,
        tile_stats,
        src.voids_filled,
    );
    // Manifest last, then the directory rename publishes the data set.
    bytes += write_manifest(&tmp, &m)?;
    partial.publish(opts.force)?;
    Ok(Summary {
        out: opts.out.clone(),
        name: plan.name,
        content: plan.content.into(),
        width: plan.width,
        height: plan.height,
        levels: layout.levels(),
        nodes,
        bytes,
        voids_filled: src.voids_filled,
        source_bytes: src.source_bytes,
        seconds: t0.elapsed().as_secs_f64(),
        height_range: range,
        warnings: plan.warnings,
    })
}

fn write_synced(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let mut f = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    f.write_all(bytes).map_err(|e| Error::io(path, e))?;
    f.sync_all().map_err(|e| Error::io(path, e))
}

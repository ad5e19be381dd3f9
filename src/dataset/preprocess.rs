//! `vkterrain preprocess`: sources -> void filling -> node pyramid -> manifest, written
//! atomically (everything goes to `<out>.partial/`, renamed to `<out>` once complete).

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::interp::GridCell;
use super::manifest::{self, LevelInfo, Manifest};
use super::procedural::{self, ProceduralParams};
use super::pyramid::{self, Block, LayerSet, Layout, LeafSource};
use super::source::Raster;
use super::{geotiff, srtm, voids};
use crate::error::{Error, Result};

/// What to preprocess.
#[derive(Clone, Debug)]
pub enum Input {
    /// DEM files: SRTM tiles (a mosaic), one GeoTIFF or one 16-bit PNG.
    Files(Vec<PathBuf>),
    /// The procedural generator (`size x size` samples).
    Procedural(ProceduralParams),
    /// A raster already in memory (voids `NaN`): tests and library users.
    Raster(Raster),
}

#[derive(Clone, Debug)]
pub struct Options {
    pub input: Input,
    pub out: PathBuf,
    pub albedo: Option<PathBuf>,
    /// Metres between samples (required for PNG, overrides georeferencing otherwise).
    pub spacing: Option<f64>,
    /// Metres per unit (PNG; scales other sources too when given).
    pub vertical_scale: Option<f64>,
    pub center_size: u32,
    pub border_size: u32,
    /// Amplify a real DEM `k` times with procedural detail below its resolution.
    pub amplify: Option<(u32, u64)>,
    /// Replace an existing data set at `out`.
    pub force: bool,
}

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
        }
    }
}

/// Progress callbacks (the CLI draws bars; tests pass [`NoProgress`]).
pub trait Progress {
    fn stage(&mut self, _what: &str) {}
    fn level(&mut self, _lod: u32, _nodes: u64) {}
    fn advance(&mut self, _n: u64) {}
    fn level_done(&mut self) {}
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
}

fn ext_of(p: &Path) -> String {
    let s = p.to_string_lossy().to_ascii_lowercase();
    if s.ends_with(".hgt.zip") {
        "hgt.zip".into()
    } else {
        p.extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default()
    }
}

/// Reads the DEM inputs into one raster (voids still `NaN`).
pub fn read_inputs(
    paths: &[PathBuf],
    spacing: Option<f64>,
    vertical_scale: Option<f64>,
) -> Result<Raster> {
    let first = paths
        .first()
        .ok_or_else(|| Error::invalid("preprocess", "no input files"))?;
    let kind = ext_of(first);
    if let Some(p) = paths.iter().find(|p| {
        let k = ext_of(p);
        let srtm = |k: &str| matches!(k, "hgt" | "hgt.zip" | "zip");
        !(k == kind || srtm(&k) && srtm(&kind))
    }) {
        return Err(Error::invalid(
            p.display().to_string(),
            format!("cannot mix {} with .{kind} inputs", ext_of(p)),
        ));
    }
    if let Some(s) = spacing
        && !(s.is_finite() && s > 0.0)
    {
        return Err(Error::invalid(
            "--spacing",
            format!("{s} m is not a positive number"),
        ));
    }
    let mut raster = match kind.as_str() {
        "hgt" | "hgt.zip" | "zip" => {
            let mut r = srtm::mosaic(paths)?;
            if let Some(s) = spacing {
                r.spacing = [s, s];
                r.provenance
                    .push(format!("spacing overridden to {s} m by --spacing"));
            }
            r
        }
        "tif" | "tiff" => {
            if paths.len() > 1 {
                return Err(Error::invalid(
                    paths[1].display().to_string(),
                    "only one GeoTIFF per data set is supported (mosaics: SRTM tiles)",
                ));
            }
            geotiff::read(first, spacing)?
        }
        "png" => {
            if paths.len() > 1 {
                return Err(Error::invalid(
                    paths[1].display().to_string(),
                    "only one PNG height map per data set",
                ));
            }
            let s = spacing.ok_or_else(|| {
                Error::invalid(
                    first.display().to_string(),
                    "a PNG height map has no georeferencing: pass --spacing",
                )
            })?;
            let vs = vertical_scale.unwrap_or(1.0);
            let m = super::load_png16(first, s, vs, None)?;
            return Ok(Raster {
                name: m.name,
                width: m.width,
                height: m.height,
                spacing: [s, s],
                heights: m.heights,
                georef: None,
                provenance: vec![format!(
                    "16-bit PNG {} ({}x{}), {vs} m per unit, {s} m spacing (given)",
                    first.display(),
                    m.width,
                    m.height
                )],
            });
        }
        other => {
            return Err(Error::invalid(
                first.display().to_string(),
                format!(
                    "unknown input type .{other} (expected .hgt, .hgt.zip, .tif, .tiff or .png)"
                ),
            ));
        }
    };
    if let Some(vs) = vertical_scale {
        if !(vs.is_finite() && vs > 0.0) {
            return Err(Error::invalid(
                "--vertical-scale",
                format!("{vs} is not positive"),
            ));
        }
        for h in &mut raster.heights {
            *h = (*h as f64 * vs) as f32;
        }
        raster
            .provenance
            .push(format!("heights multiplied by --vertical-scale {vs}"));
    }
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
    /// Loads `path` and aligns it with `dem`: by a world file (`.pgw`, `.jgw`, `.wld`, ...)
    /// when both are georeferenced, else by extent (the image spans the DEM exactly, so their
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
        let world = ["pgw", "jgw", "pngw", "jpgw", "wld"]
            .iter()
            .map(|e| path.with_extension(e))
            .find(|p| p.is_file());
        let map = match (world, dem.bounds()) {
            (Some(wf), Some([x0, y0, x1, y1])) => {
                let [a, _, _, e, c, f] = geotiff::read_world_file(&wf)?;
                // Pixel centre (col, row from north): x = a*col + c, y = f + e*row.
                let px = |x: f64| (x - c) / a;
                let py_south = |y: f64| (ah - 1) as f64 - (y - f) / e;
                let (c0, c1) = (px(x0), px(x1));
                let (r0, r1) = (py_south(y0), py_south(y1));
                let inside = |v: f64, n: u32| v >= -0.5 - 1e-6 && v <= n as f64 - 0.5 + 1e-6;
                if !(inside(c0, aw) && inside(c1, aw) && inside(r0, ah) && inside(r1, ah)) {
                    return Err(Error::invalid(
                        path.display().to_string(),
                        format!(
                            "imagery (world file {}) does not cover the DEM extent {x0},{y0}..{x1},{y1}",
                            wf.display()
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

impl LeafSource for RasterLeaves<'_> {
    fn leaf(&self, x: u32, y: u32, out: &mut Block) -> Result<()> {
        let c = self.layout.center as u64;
        let (lw, lh) = (self.layout.width, self.layout.height);
        out.heights.clear();
        out.mask.clear();
        out.rgba.clear();
        for j in 0..c {
            let v = (y as u64 * c + j).min(lh - 1);
            for i in 0..c {
                let u = (x as u64 * c + i).min(lw - 1);
                let (h, m) = match self.amplify {
                    None => {
                        let k = v as usize * self.w as usize + u as usize;
                        (self.heights[k], self.mask[k])
                    }
                    Some((f, seed, wl, amp, sp)) => {
                        let (gx, gy) = (u as f64 / f as f64, v as f64 / f as f64);
                        let s = |x: u32, y: u32| {
                            self.heights[y as usize * self.w as usize + x as usize] as f64
                        };
                        let base = GridCell::at(gx, gy, self.w, self.h).bilinear(s);
                        let d =
                            procedural::detail(seed, u as f64 * sp[0], v as f64 * sp[1], wl, amp);
                        let near = gy.round() as usize * self.w as usize + gx.round() as usize;
                        ((base + d) as f32, self.mask[near])
                    }
                };
                out.heights.push(h);
                out.mask.push(m);
                if let Some(a) = self.albedo {
                    out.rgba.extend_from_slice(
                        &a.at(u as f64 / (lw - 1) as f64, v as f64 / (lh - 1) as f64),
                    );
                }
            }
        }
        Ok(())
    }
}

/// Leaves computed by the procedural generator, node by node (bounded memory).
struct ProceduralLeaves {
    layout: Layout,
    params: ProceduralParams,
}

impl LeafSource for ProceduralLeaves {
    fn leaf(&self, x: u32, y: u32, out: &mut Block) -> Result<()> {
        let c = self.layout.center as u64;
        let n = self.params.size as u64;
        out.heights.clear();
        out.mask.clear();
        out.rgba.clear();
        for j in 0..c {
            let v = (y as u64 * c + j).min(n - 1);
            for i in 0..c {
                let u = (x as u64 * c + i).min(n - 1);
                let (px, py) = (
                    u as f64 * self.params.spacing,
                    v as f64 * self.params.spacing,
                );
                out.heights
                    .push(procedural::height(&self.params, px, py) as f32);
            }
        }
        Ok(())
    }
}

/// Prepares `<out>.partial/` (removing a stale one: reruns start clean) after checking `out`.
fn prepare_dirs(out: &Path, force: bool) -> Result<PathBuf> {
    if out.exists() {
        let is_dataset = out.join(manifest::FILE_NAME).is_file();
        let empty = out.is_dir()
            && std::fs::read_dir(out)
                .map_err(|e| Error::io(out, e))?
                .next()
                .is_none();
        if !force && !empty {
            return Err(Error::invalid(
                out.display().to_string(),
                if is_dataset {
                    "a data set already exists here; pass --force to replace it"
                } else {
                    "exists and is not an empty directory; pass --force to replace it"
                },
            ));
        }
    }
    let mut name = out
        .file_name()
        .ok_or_else(|| Error::invalid(out.display().to_string(), "not a directory name"))?
        .to_os_string();
    name.push(".partial");
    let tmp = out.with_file_name(name);
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
    }
    std::fs::create_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
    Ok(tmp)
}

/// Runs the whole pipeline.
pub fn run(opts: &Options, progress: &mut dyn Progress) -> Result<Summary> {
    let t0 = Instant::now();
    let mut source_bytes = 0u64;
    let mut voids_filled = 0u64;
    // Stage 1: the level-0 source.
    let mut raster = None;
    let mut mask = Vec::new();
    let mut params = None;
    match &opts.input {
        Input::Files(paths) => {
            progress.stage("reading sources");
            for p in paths {
                source_bytes += std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
            }
            let mut r = read_inputs(paths, opts.spacing, opts.vertical_scale)?;
            progress.stage("filling voids");
            let (m, n) = voids::fill(&r.name, &mut r.heights, r.width, r.height)?;
            if n > 0 {
                r.provenance.push(format!(
                    "{n} void samples filled by push-pull interpolation (void_mask layer = 1)"
                ));
            }
            voids_filled = n;
            mask = m;
            raster = Some(r);
        }
        Input::Raster(r) => {
            let mut r = r.clone();
            if let Some(s) = opts.spacing {
                r.spacing = [s, s];
            }
            let (m, n) = voids::fill(&r.name, &mut r.heights, r.width, r.height)?;
            voids_filled = n;
            mask = m;
            raster = Some(r);
        }
        Input::Procedural(p) => {
            if p.size < 2 {
                return Err(Error::invalid("--size", format!("{} is below 2", p.size)));
            }
            if opts.albedo.is_some() || opts.amplify.is_some() {
                return Err(Error::invalid(
                    "--procedural",
                    "takes neither --albedo nor --amplify",
                ));
            }
            params = Some(*p);
        }
    }
    let albedo = match (&opts.albedo, &raster) {
        (Some(a), Some(r)) => Some(AlbedoSampler::open(a, r)?),
        _ => None,
    };
    let (width, height, spacing, name, georef, mut provenance, content) = match (&raster, &params) {
        (Some(r), _) => {
            let (w, h, sp, content) = match opts.amplify {
                Some((k, _)) => {
                    if !(2..=64).contains(&k) {
                        return Err(Error::invalid(
                            "--amplify",
                            format!("factor {k} is outside 2..=64"),
                        ));
                    }
                    (
                        (r.width as u64 - 1) * k as u64 + 1,
                        (r.height as u64 - 1) * k as u64 + 1,
                        [r.spacing[0] / k as f64, r.spacing[1] / k as f64],
                        "amplified",
                    )
                }
                None => (r.width as u64, r.height as u64, r.spacing, "real"),
            };
            let name = if content == "amplified" {
                format!("{} (amplified with procedural detail)", r.name)
            } else {
                r.name.clone()
            };
            (
                w,
                h,
                sp,
                name,
                r.georef.clone(),
                r.provenance.clone(),
                content,
            )
        }
        (None, Some(p)) => (
            p.size as u64,
            p.size as u64,
            [p.spacing, p.spacing],
            format!(
                "procedural size={} seed={} spacing={} m",
                p.size, p.seed, p.spacing
            ),
            None,
            vec![format!(
                "procedural generator (style {:?}, seed {}, max height {} m, feature size {} m)",
                p.style, p.seed, p.max_height, p.feature_size
            )],
            "procedural",
        ),
        _ => unreachable!("one source"),
    };
    if let (Some(a), Some(p)) = (&opts.albedo, &albedo) {
        provenance.push(format!(
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
    let layout = Layout::new(width, height, opts.center_size, opts.border_size)?;
    let layers = LayerSet {
        mask: raster.is_some(),
        albedo: albedo.is_some(),
    };
    let amplify = match (opts.amplify, &raster) {
        (Some((k, seed)), Some(r)) => {
            let wl = r.spacing[0].min(r.spacing[1]);
            let amp = 0.05 * wl;
            provenance.push(format!(
                "AMPLIFIED: bilinear upsampling x{k} plus procedural detail (seed {seed}, wavelength {wl:.2} m, amplitude {amp:.2} m) below the source resolution; not measured data"
            ));
            Some((k, seed, wl, amp, spacing))
        }
        _ => None,
    };
    let tmp = prepare_dirs(&opts.out, opts.force)?;

    // Stage 2: levels, finest first; each coarser level reads only the previous level file.
    let leaves: Box<dyn LeafSource + '_> = match (&raster, params) {
        (Some(r), _) => Box::new(RasterLeaves {
            layout,
            heights: &r.heights,
            mask: &mask,
            w: r.width,
            h: r.height,
            albedo: albedo.as_ref(),
            amplify,
        }),
        (None, Some(p)) => Box::new(ProceduralLeaves { layout, params: p }),
        _ => unreachable!("one source"),
    };
    let mut levels = Vec::new();
    let (mut nodes, mut bytes) = (0u64, 0u64);
    let mut range = [f32::INFINITY, f32::NEG_INFINITY];
    for lod in 0..layout.levels() {
        let (nx, ny) = layout.nodes(lod);
        progress.level(lod, nx as u64 * ny as u64);
        let file = format!("L{lod}.bin");
        let path = tmp.join(&file);
        let stats = if lod == 0 {
            let mut centre = |x: u32, y: u32| {
                let mut b = Block::default();
                leaves.leaf(x, y, &mut b)?;
                if !layers.mask {
                    b.mask.clear();
                }
                Ok(b)
            };
            pyramid::write_level(&path, &layout, 0, layers, &mut centre, &mut |n| {
                progress.advance(n)
            })?
        } else {
            let child_path = tmp.join(format!("L{}.bin", lod - 1));
            let mut child =
                std::fs::File::open(&child_path).map_err(|e| Error::io(&child_path, e))?;
            let mut centre = |x: u32, y: u32| {
                pyramid::parent_block(&mut child, &child_path, &layout, lod, layers, x, y)
            };
            pyramid::write_level(&path, &layout, lod, layers, &mut centre, &mut |n| {
                progress.advance(n)
            })?
        };
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
    let m = Manifest {
        format: manifest::FORMAT.into(),
        version: manifest::VERSION,
        name: name.clone(),
        width,
        height,
        spacing,
        extent: [
            (width - 1) as f64 * spacing[0],
            (height - 1) as f64 * spacing[1],
        ],
        georef,
        center_size: layout.center,
        border_size: layout.border,
        levels,
        layers: manifest::Layers {
            height: "f32le".into(),
            void_mask: layers.mask,
            albedo: layers.albedo.then(|| "rgba8_srgb".into()),
        },
        height_range: range,
        voids_filled,
        content: content.into(),
        provenance,
        created_by: format!("vkterrain {}", env!("CARGO_PKG_VERSION")),
    };
    // Manifest last (temp + rename), then the directory rename publishes the data set.
    let json = serde_json::to_string_pretty(&m).expect("manifest serialises");
    let mtmp = tmp.join("manifest.json.tmp");
    std::fs::write(&mtmp, json).map_err(|e| Error::io(&mtmp, e))?;
    std::fs::rename(&mtmp, tmp.join(manifest::FILE_NAME)).map_err(|e| Error::io(&mtmp, e))?;
    if opts.out.exists() {
        std::fs::remove_dir_all(&opts.out).map_err(|e| Error::io(&opts.out, e))?;
    }
    std::fs::rename(&tmp, &opts.out).map_err(|e| Error::io(&opts.out, e))?;
    Ok(Summary {
        out: opts.out.clone(),
        name,
        content: content.into(),
        width,
        height,
        levels: layout.levels(),
        nodes,
        bytes: bytes + std::fs::metadata(opts.out.join(manifest::FILE_NAME)).map_or(0, |m| m.len()),
        voids_filled,
        source_bytes,
        seconds: t0.elapsed().as_secs_f64(),
        height_range: range,
    })
}

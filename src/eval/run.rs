//! One evaluation: a scenario rendered by several methods and parameter values, every frame
//! measured on the GPU against the exact level-0 surface and against the brute-force reference
//! frame of the same cameras, plus the temporal metrics (popping, swimming) and FLIP.
//! `vkterrain eval` and `benches/eval.rs` drive it.
//!
//! The reference and every variant render side by side, frame by frame (frame `k` of the
//! reference, then frame `k` of each variant), one frame in flight each: the GPU metrics
//! ([`super::gpu`]) compare each variant's frame with the reference frame still on the GPU,
//! nothing waits for a whole run to be stored, and every frame's pass timestamps contain only
//! its own work (the speed axis: the method's GPU time, prepass + terrain pass).

use std::sync::Arc;
use std::time::Instant;

use crossbeam_channel::{Receiver, Sender, unbounded};
use serde::Serialize;

use super::check::{CpuFrame, CrossCheck};
use super::coarse::{self, CoarseErrors, CoarseSummary, TileLevels};
use super::flip::{self, FlipStats};
use super::gpu::reference::ViewCone;
use super::gpu::{EvalShared, FrameShape, GpuAnalysis, GpuFrameMetrics, Role};
use super::metrics::{ErrorHistogram, GeometricError, OnEarth, Summary, SwimTracker};
use super::oracle::Oracle;
use crate::config::Config;
use crate::dataset::Terrain;
use crate::driver::Gpu;
use crate::error::{Error, Result};
use crate::geo::Lattice;
use crate::lod::{MethodConfig, MethodKind};
use crate::readback::FrameView;
use crate::render::stats::Percentiles;
use crate::render::{FrameRequest, RenderOptions, Renderer};
use crate::scene::Scenario;
use crate::slots::ViewSlot;

/// At most this many measured frames (evenly spaced) get the triangle oracle (seconds per
/// frame on large data sets).
const ORACLE_FRAMES: usize = 12;

/// One method with one parameter setting.
#[derive(Clone, Debug)]
pub struct Variant {
    /// The method with this variant's settings.
    pub method: MethodConfig,
    /// `method` or `method key=value,...`.
    pub label: String,
    pub params: Vec<(String, f64)>,
}

impl Variant {
    pub fn kind(&self) -> MethodKind {
        self.method.kind()
    }
}

/// The variants of `methods` under `sweeps` (the Cartesian product of the sweeps a method
/// takes; one variant for a method no sweep applies to). A method starts from `base`'s settings
/// when `base` is that method, else from its defaults. Every setting is validated; an unknown
/// key or one no listed method takes is an error.
pub fn variants(
    methods: &[MethodKind],
    sweeps: &[(String, Vec<f64>)],
    base: &MethodConfig,
) -> Result<Vec<Variant>> {
    let takes = |kind: MethodKind, key: &str| {
        MethodConfig::sweep_keys(kind)
            .iter()
            .any(|(k, _)| *k == key)
    };
    for (key, _) in sweeps {
        if !methods.iter().any(|&m| takes(m, key)) {
            return Err(Error::invalid(
                "sweep",
                format!("no listed method takes parameter {key:?}"),
            ));
        }
    }
    let mut out = Vec::new();
    for &kind in methods {
        let mut combos: Vec<Vec<(String, f64)>> = vec![Vec::new()];
        for (key, values) in sweeps.iter().filter(|(k, _)| takes(kind, k)) {
            combos = combos
                .into_iter()
                .flat_map(|c| {
                    values.iter().map(move |&v| {
                        let mut c = c.clone();
                        c.push((key.clone(), v));
                        c
                    })
                })
                .collect();
        }
        for params in combos {
            let mut method = base.clone().with_kind(kind);
            for (k, v) in &params {
                method.apply_sweep(k, *v)?;
            }
            method.validate()?;
            out.push(Variant {
                label: variant_label(&method, &params),
                method,
                params,
            });
        }
    }
    Ok(out)
}

/// `method` alone, `pgm COLSxROWS` for a PGM grid scale, else `method key=value,...`.
fn variant_label(method: &MethodConfig, params: &[(String, f64)]) -> String {
    let name = method.kind().name();
    if params.is_empty() {
        return name.to_string();
    }
    if let MethodConfig::Pgm(s) = method
        && params.iter().any(|(k, _)| k == "grid_scale")
    {
        // Other swept keys (e.g. warp_rows) stay in the label, or variants would share one.
        let grid = format!("pgm {}x{}", s.grid_cols, s.grid_rows);
        let rest: Vec<String> = params
            .iter()
            .filter(|(k, _)| k != "grid_scale")
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        return if rest.is_empty() {
            grid
        } else {
            format!("{grid} {}", rest.join(","))
        };
    }
    let p: Vec<String> = params.iter().map(|(k, v)| format!("{k}={v}")).collect();
    format!("{name} {}", p.join(","))
}

/// Per-frame measurements of one variant.
#[derive(Clone, Debug, Serialize)]
pub struct FrameRow {
    pub variant: String,
    pub method: String,
    pub frame: u64,
    /// GPU time of the method's own passes, prepass + terrain pass (ms, timestamps).
    pub gpu_ms: f64,
    pub gpu_prepass_ms: f64,
    pub gpu_terrain_ms: f64,
    /// GPU time after the terrain pass: the frame analysis and the readback copy (ms).
    pub gpu_eval_ms: f64,
    pub cpu_record_ms: f64,
    pub triangles: u64,
    /// The tiles the method drew over the frame's views (`LodMethod::tiles`: UDLOD's; None
    /// for a method without tiles).
    pub tiles: Option<u64>,
    /// Tiles the method's budget could not hold this frame (UDLOD's `max_tiles`; 0: none).
    pub budget_overflow: u64,
    /// Percentiles to one histogram bin (1.2%, never understated); count, mean, max exact.
    pub error: GeometricError,
    /// Sky pixels inside the reference's silhouette, and those of them seen through the
    /// surface (`metrics::Holes`).
    pub holes: usize,
    pub cracks: usize,
    /// How far the method's skyline lies below the reference's (px, `metrics::Holes`).
    pub silhouette_px: u32,
    pub psnr_db: f64,
    pub ssim: f64,
    /// 99th percentile of the per-pixel change of the error image since the previous frame.
    pub popping_p99_px: f64,
    /// FLIP against the reference frame (sampled frames only).
    pub flip: Option<FlipStats>,
    /// The triangle oracle's count for this frame at the variant's tau (UDLOD variants, on
    /// the frames the oracle runs on: `eval::oracle`).
    pub oracle_triangles: Option<u64>,
    /// The pixels drawn coarser than level 0 (methods that report their tiles, on the
    /// oracle's frames: `eval::coarse`).
    pub coarse: Option<CoarseSummary>,
}

/// Summary of one variant over the frames after warm-up.
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    pub variant: String,
    pub method: String,
    pub params: Vec<(String, f64)>,
    pub frames: usize,
    /// The speed axis: GPU time of the method's passes per frame (prepass + terrain, ms).
    pub gpu_ms: Percentiles,
    pub gpu_prepass_ms_median: f64,
    pub gpu_terrain_ms_median: f64,
    /// GPU time of the frame analysis and the readback copy per frame (median, ms).
    pub gpu_eval_ms_median: f64,
    pub triangles_median: f64,
    /// Median of the measured frames' [`FrameRow::tiles`] (None: a method without tiles).
    pub tiles_median: Option<f64>,
    /// Measured frames whose LOD budget overflowed (coarser than the settings ask: UDLOD's
    /// `max_tiles`); eval warns when it is not 0.
    pub budget_overflow_frames: usize,
    /// Over all pixels of all measured frames (percentiles to 1.2%, never understated).
    pub error: GeometricError,
    pub holes_total: usize,
    pub cracks_total: usize,
    /// The largest silhouette drop of any frame (px).
    pub silhouette_px_max: u32,
    pub psnr_db_mean: f64,
    pub ssim_mean: f64,
    /// Means over the measured frames FLIP was computed for (`flip_frames`; None: none).
    pub flip_mean: Option<f64>,
    pub flip_p99_mean: Option<f64>,
    pub flip_frames: usize,
    /// Of the per-frame 99th percentiles.
    pub popping_px: Summary,
    /// Per fixed world point: range of its height error (metres) and that range in pixels.
    pub swimming_m: Summary,
    pub swimming_px: Summary,
    /// Median over the oracle's frames of the oracle's triangle count, and of this variant's
    /// triangles divided by it (UDLOD variants only).
    pub oracle_triangles_median: Option<f64>,
    pub oracle_ratio_median: Option<f64>,
    /// Over the coarse pixels of the oracle's frames (`eval::coarse`; None: a method without
    /// tiles).
    pub coarse: Option<CoarseSummary>,
}

/// A frame kept for the side-by-side images.
pub struct ImageFrame {
    pub variant: String,
    pub frame: u64,
    pub width: u32,
    pub height: u32,
    pub reference: Arc<Vec<u8>>,
    pub method: Vec<u8>,
    /// Signed screen-space error per pixel (`EVAL_NO_ERROR_PX`: none).
    pub error_px: Vec<f32>,
    /// FLIP error map, magma-coloured RGBA8.
    pub flip: Option<Vec<u8>>,
}

#[derive(Serialize)]
pub struct Evaluation {
    pub dataset: String,
    pub scenario: String,
    pub device: String,
    pub width: u32,
    pub height: u32,
    pub views: usize,
    pub frames: u32,
    pub warmup: usize,
    pub clipmap: bool,
    /// Where the terrain was drawn and measured: "ellipsoid" (the WGS84 ellipsoid through the
    /// geolocation lattice) or "flat" (the grid on the tangent plane, or no world frame).
    pub earth: String,
    pub reference: String,
    /// How the speed axis was measured.
    pub timing: String,
    /// FLIP of every this many measured frames (0: image frames only).
    pub flip_every: u32,
    /// The command that regenerates this evaluation.
    pub command: String,
    /// Wall time of the whole evaluation and of its frame loop (s).
    pub wall_s: f64,
    /// Level-0 reference tiles read.
    pub reference_tiles_loaded: u64,
    pub summaries: Vec<RunSummary>,
    pub rows: Vec<FrameRow>,
    /// GPU metrics against the CPU path on the same frames (`--cross-check`).
    pub cross_check: Option<CrossCheck>,
    #[serde(skip)]
    pub images: Vec<ImageFrame>,
}

/// What the runner reports while it works (progress bars in the CLI).
pub trait Progress {
    fn start(&mut self, label: &str, frames: u64);
    fn advance(&mut self);
    fn finish(&mut self);
}

impl Progress for () {
    fn start(&mut self, _: &str, _: u64) {}
    fn advance(&mut self) {}
    fn finish(&mut self) {}
}

/// Settings of one evaluation run.
pub struct EvalSetup<'a> {
    pub gpu: &'a Arc<Gpu>,
    /// The configuration renderers are opened from (data set, clipmap, `[render]`, extra
    /// views); each variant brings its own `[method]`.
    pub config: &'a Config,
    pub data: &'a Terrain,
    pub scenario: &'a Scenario,
    pub frames: u32,
    pub warmup: usize,
    /// Resolution and views (frames in flight are 1 while evaluating).
    pub options: RenderOptions,
    /// Frames written as side-by-side images (FLIP is computed for them too).
    pub image_frames: Vec<u64>,
    /// FLIP of every this many measured frames (0: the image frames only).
    pub flip_every: u32,
    /// Also measure every frame on the CPU from read-back depth and compare (slow).
    pub cross_check: bool,
    /// Most memory for the level-0 reference tiles (MiB).
    pub reference_mib: u64,
    /// The command that regenerates this evaluation (written into report.md).
    pub command: String,
}

impl EvalSetup<'_> {
    fn flip_frame(&self, k: u64) -> bool {
        self.image_frames.contains(&k)
            || (self.flip_every > 0
                && k >= self.warmup as u64
                && (k - self.warmup as u64) % self.flip_every as u64 == 0)
    }

    fn requests(&self, k: u64) -> Vec<FrameRequest> {
        FrameRequest::with_extra_views(self.scenario.camera(k), &self.config.render.extra_views)
    }
}

/// A delivered frame as the evaluator keeps it: RGBA (sampled frames only), depth (with
/// `--cross-check`), timings, and triangles, the LOD budget's overflow and tiles.
type Delivered = (
    Vec<u8>,
    Option<Vec<f32>>,
    crate::readback::FrameTimings,
    (u64, u64, Option<u64>),
);

/// A finished FLIP computation: run, frame, statistics, coloured map (image frames).
type FlipDone = (usize, u64, FlipStats, Option<Vec<u8>>);

/// One renderer of the evaluation and what it accumulates.
struct Run {
    label: String,
    method: MethodConfig,
    params: Vec<(String, f64)>,
    /// Listed among the summaries (the reference is only when brute force is a variant).
    reported: bool,
    renderer: Renderer,
    results: Receiver<GpuFrameMetrics>,
    rows: Vec<FrameRow>,
    errors: ErrorHistogram,
    swim: SwimTracker,
    images: Vec<ImageFrame>,
    cpu: Option<super::check::CpuRun>,
    /// Read-back depth of the last frame (with `--cross-check`, and for methods that report
    /// their tiles: `eval::coarse`).
    depth: Option<Arc<Vec<f32>>>,
    /// The coarse pixels of the measured frames among the oracle's.
    coarse: CoarseErrors,
}

/// The reference frame of the current iteration, as far as the variants need it on the host.
#[derive(Default)]
struct ReferenceFrame {
    rgba: Option<Arc<Vec<u8>>>,
    depth: Option<Arc<Vec<f32>>>,
}

/// Renders the reference (brute force) and every variant, and measures them.
pub fn evaluate(
    setup: &EvalSetup<'_>,
    variants: &[Variant],
    progress: &mut dyn Progress,
) -> Result<Evaluation> {
    let started = Instant::now();
    let gpu = setup.gpu;
    let shape = shape_of(setup);
    let renderers = 1 + variants
        .iter()
        .filter(|v| v.method != MethodConfig::Brute {})
        .count();
    // The renderers' own lattice (None: the flat world): the exact surface is placed as they
    // place the terrain (docs/eval.md, "On the earth").
    let lattice = setup.config.open_lattice(setup.data, setup.options.earth)?;
    let shared = EvalShared::new(
        gpu,
        setup.data,
        lattice.as_ref(),
        shape,
        setup.frames as u64,
        renderers,
        setup.reference_mib << 20,
    )?;
    let (flip_tx, flip_rx) = unbounded::<FlipDone>();
    let mut runs = open_runs(setup, &shared, variants)?;
    progress.start(
        &format!("{} renderers", runs.len()),
        setup.frames as u64 * runs.len() as u64,
    );
    let mut flips_pending = 0usize;
    let mut oracle: Option<Oracle> = None;
    for k in 0..setup.frames as u64 {
        let requests = setup.requests(k);
        shared.prepare(k, &view_cones(&shape, &requests))?;
        let mut reference = ReferenceFrame::default();
        for (i, run) in runs.iter_mut().enumerate() {
            let spawned = run.frame(setup, k, &requests, &mut reference, i, &flip_tx)?;
            if sampled_frame(setup, k) {
                run.measure_coarse(setup, lattice.as_ref(), &requests, k)?;
            }
            // The oracle refines in the flat grid's frame (its frustum and distances): on the
            // earth it would count for the wrong place, so it is left out there (docs/eval.md).
            if lattice.is_none()
                && let Some(count) = oracle_count(setup, &mut oracle, &run.method, k, &requests)
                && let Some(row) = run.rows.last_mut()
            {
                row.oracle_triangles = Some(count);
            }
            flips_pending += spawned;
            progress.advance();
        }
        // Bound the frames waiting for FLIP (each holds two images).
        while flips_pending > 2 * rayon::current_num_threads() {
            let done = flip_rx
                .recv()
                .map_err(|_| Error::invalid("flip", "worker lost"))?;
            apply_flip(&mut runs, done);
            flips_pending -= 1;
        }
    }
    progress.finish();
    drop(flip_tx);
    for done in flip_rx.iter() {
        apply_flip(&mut runs, done);
    }
    let wall_s = started.elapsed().as_secs_f64();
    let tiles_loaded = shared
        .surface
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .tiles_loaded;
    finish(setup, runs, wall_s, (tiles_loaded, lattice.is_some()))
}

/// The reference (brute force: reported when it is one of the variants) and every other
/// variant's run, in that order.
fn open_runs(
    setup: &EvalSetup<'_>,
    shared: &Arc<EvalShared>,
    variants: &[Variant],
) -> Result<Vec<Run>> {
    let brute = MethodConfig::Brute {};
    let others: Vec<&Variant> = variants.iter().filter(|v| v.method != brute).collect();
    let mut runs = Vec::with_capacity(1 + others.len());
    let reference = variants.iter().find(|v| v.method == brute);
    runs.push(open_run(
        setup,
        shared,
        Role::Reference,
        reference.map_or("reference (brute force)", |v| v.label.as_str()),
        &brute,
        &[],
        reference.is_some(),
    )?);
    for v in &others {
        runs.push(open_run(
            setup,
            shared,
            Role::Variant,
            &v.label,
            &v.method,
            &v.params,
            true,
        )?);
    }
    Ok(runs)
}

/// Each view's camera and aspect ratio (its share of the frame's columns).
fn view_cones(shape: &FrameShape, requests: &[FrameRequest]) -> Vec<ViewCone> {
    requests
        .iter()
        .enumerate()
        .map(|(v, r)| ViewCone {
            camera: r.camera,
            aspect: crate::render::view_columns(shape.width, shape.views, v).1 as f64
                / shape.height as f64,
        })
        .collect()
}

fn open_run(
    setup: &EvalSetup<'_>,
    shared: &Arc<EvalShared>,
    role: Role,
    label: &str,
    method: &MethodConfig,
    params: &[(String, f64)],
    reported: bool,
) -> Result<Run> {
    let mut config = setup.config.clone();
    config.method = method.clone();
    let mut options = setup.options.clone();
    options.frames_in_flight = 1;
    options.readback_depth = setup.cross_check || reports_tiles(method);
    let mut renderer = config.open_renderer(setup.gpu, setup.data, options)?;
    let (analysis, rx) = GpuAnalysis::new(shared, role, setup.image_frames.clone())?;
    renderer.set_analysis(Box::new(analysis))?;
    Ok(Run {
        label: label.to_string(),
        method: method.clone(),
        params: params.to_vec(),
        reported,
        renderer,
        results: rx,
        rows: Vec::new(),
        errors: ErrorHistogram::default(),
        swim: SwimTracker::new(),
        images: Vec::new(),
        cpu: setup
            .cross_check
            .then(|| super::check::CpuRun::new(shape_of(setup), shared.lattice().cloned())),
        depth: None,
        coarse: CoarseErrors::default(),
    })
}

/// Whether `method` reports the tiles it drew ([`crate::lod::LodMethod::drawn_tiles`]), which
/// the coarse pixels need (with read-back depth).
fn reports_tiles(method: &MethodConfig) -> bool {
    matches!(method, MethodConfig::Udlod(_))
}

fn shape_of(setup: &EvalSetup<'_>) -> FrameShape {
    FrameShape {
        width: setup.options.width,
        height: setup.options.height,
        views: setup.options.views,
    }
}

impl Run {
    /// Renders and measures frame `k`; returns how many FLIP computations it started.
    fn frame(
        &mut self,
        setup: &EvalSetup<'_>,
        k: u64,
        requests: &[FrameRequest],
        reference: &mut ReferenceFrame,
        index: usize,
        flip_tx: &Sender<FlipDone>,
    ) -> Result<usize> {
        let is_reference = index == 0;
        let flip_frame = setup.flip_frame(k);
        let keep_rgba = flip_frame || setup.cross_check;
        let ((rgba, depth, timings, counts), gpu) = self.render_frame(k, requests, keep_rgba)?;
        let rgba = Arc::new(rgba);
        let depth = depth.map(Arc::new);
        self.depth = depth.clone();
        if is_reference {
            reference.rgba = keep_rgba.then(|| rgba.clone());
            reference.depth = depth.clone();
        }
        if let Some(cpu) = &mut self.cpu {
            let views = super::check::views_of(&setup.options, requests);
            cpu.measure(
                setup.data,
                &views,
                k,
                &CpuFrame {
                    rgba: &rgba,
                    depth: depth.as_deref().map(Vec::as_slice),
                    reference_rgba: reference.rgba.as_deref().map(Vec::as_slice),
                    reference_depth: reference.depth.as_deref().map(Vec::as_slice),
                },
                &gpu,
            )?;
        }
        self.swim.extend_to(gpu.swim.len());
        self.swim.record(&gpu.swim);
        let (flip, spawned) = if is_reference && flip_frame {
            // The reference against itself: identical images.
            (Some(FlipStats::default()), 0)
        } else if flip_frame && let Some(r) = reference.rgba.clone() {
            spawn_flip(setup, (r, rgba.clone()), index, k, flip_tx);
            (None, 1)
        } else {
            (None, 0)
        };
        if let Some(error_px) = gpu.error_image.clone()
            && let Some(r) = &reference.rgba
        {
            self.images.push(ImageFrame {
                variant: self.label.clone(),
                frame: k,
                width: setup.options.width,
                height: setup.options.height,
                reference: r.clone(),
                method: rgba.to_vec(),
                error_px,
                flip: None,
            });
        }
        if k >= setup.warmup as u64 {
            self.errors.metres.merge(&gpu.metres);
            self.errors.pixels.merge(&gpu.pixels);
        }
        let row = self.row(k, &timings, counts, &gpu, flip);
        self.rows.push(row);
        Ok(spawned)
    }

    /// Renders frame `k` and takes its delivered images (colour only when `keep_rgba`) and
    /// its GPU metrics, which must be this frame's and wholly on the reference tiles.
    fn render_frame(
        &mut self,
        k: u64,
        requests: &[FrameRequest],
        keep_rgba: bool,
    ) -> Result<(Delivered, GpuFrameMetrics)> {
        let mut delivered: Option<Delivered> = None;
        let mut sink = |f: &FrameView<'_>| {
            delivered = Some((
                if keep_rgba {
                    f.rgba.to_vec()
                } else {
                    Vec::new()
                },
                f.depth.map(<[f32]>::to_vec),
                f.timings,
                (f.triangles, f.budget_overflow, f.tiles),
            ));
            Ok(())
        };
        self.renderer.render_views(requests, &mut sink)?;
        let delivered = delivered
            .ok_or_else(|| Error::invalid("eval", format!("frame {k} was not delivered")))?;
        let gpu = self
            .results
            .try_recv()
            .map_err(|_| Error::invalid("eval", format!("frame {k} has no GPU metrics")))?;
        if gpu.index != k || gpu.missing_reference > 0 {
            return Err(Error::invalid(
                "eval",
                format!(
                    "frame {k}: GPU metrics of frame {} with {} pixels off the reference tiles",
                    gpu.index, gpu.missing_reference
                ),
            ));
        }
        Ok((delivered, gpu))
    }

    /// Frame `k`'s row of `frames.csv`.
    fn row(
        &self,
        k: u64,
        timings: &crate::readback::FrameTimings,
        (triangles, budget_overflow, tiles): (u64, u64, Option<u64>),
        gpu: &GpuFrameMetrics,
        flip: Option<FlipStats>,
    ) -> FrameRow {
        FrameRow {
            variant: self.label.clone(),
            method: self.method.kind().name().to_string(),
            frame: k,
            gpu_ms: timings.gpu_prepass_ms + timings.gpu_terrain_ms,
            gpu_prepass_ms: timings.gpu_prepass_ms,
            gpu_terrain_ms: timings.gpu_terrain_ms,
            gpu_eval_ms: timings.gpu_readback_ms,
            cpu_record_ms: timings.cpu_record_ms,
            triangles,
            tiles,
            budget_overflow,
            error: GeometricError {
                metres: gpu.metres.summary(),
                pixels: gpu.pixels.summary(),
            },
            holes: gpu.holes.all,
            cracks: gpu.holes.cracks,
            silhouette_px: gpu.holes.silhouette_px,
            psnr_db: gpu.psnr_db(),
            ssim: gpu.ssim(),
            popping_p99_px: gpu.popping.summary().p99,
            flip,
            oracle_triangles: None,
            coarse: None,
        }
    }

    /// Measures the coarse pixels of the frame just rendered (`eval::coarse`) into its row and,
    /// after warm-up, into the run's pool; nothing for a method without tiles.
    fn measure_coarse(
        &mut self,
        setup: &EvalSetup<'_>,
        lattice: Option<&Lattice>,
        requests: &[FrameRequest],
        k: u64,
    ) -> Result<()> {
        let Some(depth) = self.depth.clone() else {
            return Ok(());
        };
        let mut levels = Vec::with_capacity(requests.len());
        for v in 0..requests.len() {
            // One frame in flight (open_run): view v's slot is frame slot 0's.
            match self.renderer.method().drawn_tiles(ViewSlot(v))? {
                Some(drawn) => levels.push(TileLevels::new(&drawn)),
                None => return Ok(()),
            }
        }
        let views = super::check::views_of(&setup.options, requests);
        let shape = (setup.options.width, setup.options.height);
        let errors = match lattice {
            None => coarse::measure(setup.data, &views, &levels, shape, &depth),
            Some(lattice) => {
                let surface = OnEarth {
                    surface: setup.data,
                    lattice,
                };
                coarse::measure(&surface, &views, &levels, shape, &depth)
            }
        };
        if k >= setup.warmup as u64 {
            self.coarse.merge(&errors);
        }
        if let Some(row) = self.rows.last_mut() {
            row.coarse = errors.summary();
        }
        Ok(())
    }
}

/// FLIP of frame `k` of run `index` (reference and method RGBA) on the rayon pool; the result
/// arrives on `flip_tx`. Every FLIP runs in strips over the pool: on a many-core host (the GPU
/// machine, where one FLIP of a 1080p frame takes longer than the whole frame loop of a short
/// run) whole-image FLIPs, one per worker, outlasted the frame loop and became the run's tail;
/// on lavapipe's two cores strips share the cores with the rendering as whole images did
/// (docs/eval.md, "What an evaluation adds").
fn spawn_flip(
    setup: &EvalSetup<'_>,
    (r, m): (Arc<Vec<u8>>, Arc<Vec<u8>>),
    index: usize,
    k: u64,
    flip_tx: &Sender<FlipDone>,
) {
    let (w, h) = (setup.options.width, setup.options.height);
    let with_map = setup.image_frames.contains(&k);
    let tx = flip_tx.clone();
    rayon::spawn(move || {
        let map = flip::error_map_parallel(&r, &m, w, h);
        let stats = FlipStats::of(&map);
        let colours = with_map.then(|| flip::magma_rgba(&map, w, h));
        let _ = tx.send((index, k, stats, colours));
    });
}

/// The triangle oracle's count for frame `k` of a UDLOD run at its tau (`eval::oracle`): on at
/// most [`ORACLE_FRAMES`] evenly spaced measured frames, for one view over a height map held in
/// memory (the oracle needs level 0 whole; clipmap evaluations get no oracle column).
fn oracle_count(
    setup: &EvalSetup<'_>,
    oracle: &mut Option<Oracle>,
    method: &MethodConfig,
    k: u64,
    requests: &[FrameRequest],
) -> Option<u64> {
    let (MethodConfig::Udlod(s), Terrain::Grid(data), [request]) = (method, setup.data, requests)
    else {
        return None;
    };
    if !sampled_frame(setup, k) {
        return None;
    }
    let o = oracle.get_or_insert_with(|| Oracle::new(data));
    let (w, h) = (setup.options.width, setup.options.height);
    Some(o.count(data, &request.camera, w, h, s.tau_px).triangles)
}

/// Whether frame `k` is one of the at most [`ORACLE_FRAMES`] evenly spaced measured frames the
/// oracle and the coarse pixels are measured on.
fn sampled_frame(setup: &EvalSetup<'_>, k: u64) -> bool {
    let warmup = setup.warmup as u64;
    let measured = (setup.frames as u64).saturating_sub(warmup);
    let stride = measured.div_ceil(ORACLE_FRAMES as u64).max(1);
    k >= warmup && (k - warmup) % stride == 0
}

fn apply_flip(runs: &mut [Run], (run, frame, stats, colours): FlipDone) {
    let r = &mut runs[run];
    if let Some(row) = r.rows.iter_mut().find(|row| row.frame == frame) {
        row.flip = Some(stats);
    }
    if let Some(img) = r.images.iter_mut().find(|i| i.frame == frame) {
        img.flip = colours;
    }
}

/// Summaries, rows and images of every run.
fn finish(
    setup: &EvalSetup<'_>,
    runs: Vec<Run>,
    wall_s: f64,
    (reference_tiles_loaded, on_earth): (u64, bool),
) -> Result<Evaluation> {
    let focal = setup.scenario.camera(0).focal_px(setup.options.height);
    let mut summaries = Vec::new();
    let mut rows = Vec::new();
    let mut images = Vec::new();
    let mut check = setup.cross_check.then(CrossCheck::default);
    for mut run in runs {
        let (swimming_m, swimming_px) = run.swim.summary(focal);
        if let (Some(check), Some(cpu)) = (&mut check, run.cpu.take()) {
            check.add_run(&run.label, cpu, swimming_px, focal);
        }
        if !run.reported {
            continue;
        }
        summaries.push(run_summary(&run, setup.warmup, (swimming_m, swimming_px)));
        rows.append(&mut run.rows);
        images.append(&mut run.images);
    }
    let clipmap = setup.config.clipmap.enabled;
    Ok(Evaluation {
        dataset: setup.data.name().to_string(),
        scenario: setup.scenario.name.clone(),
        device: setup.gpu.info.name.clone(),
        width: setup.options.width,
        height: setup.options.height,
        views: setup.options.views,
        frames: setup.frames,
        warmup: setup.warmup,
        clipmap,
        earth: if on_earth { "ellipsoid" } else { "flat" }.into(),
        reference: reference_text(on_earth, clipmap),
        timing: "GPU time of each method's own passes (prepass + terrain pass) from timestamps; frames are measured one at a time, so no other work is inside them".into(),
        flip_every: setup.flip_every,
        command: setup.command.clone(),
        wall_s,
        reference_tiles_loaded,
        summaries,
        rows,
        cross_check: check,
        images,
    })
}

/// One reported run's summary over its measured frames (after `warmup`).
fn run_summary(
    run: &Run,
    warmup: usize,
    (swimming_m, swimming_px): (Summary, Summary),
) -> RunSummary {
    let measured: Vec<&FrameRow> = run.rows.iter().skip(warmup).collect();
    let pick = |g: fn(&FrameRow) -> f64| Percentiles::of(measured.iter().map(|r| g(r)).collect());
    let mut popping: Vec<f64> = measured.iter().skip(1).map(|r| r.popping_p99_px).collect();
    let flips: Vec<FlipStats> = measured.iter().filter_map(|r| r.flip).collect();
    let mean_of = |f: fn(&FlipStats) -> f64| {
        (!flips.is_empty()).then(|| flips.iter().map(f).sum::<f64>() / flips.len() as f64)
    };
    let finite_mean = |g: fn(&FrameRow) -> f64| {
        let v: Vec<f64> = measured
            .iter()
            .map(|r| g(r))
            .filter(|x| x.is_finite())
            .collect();
        if v.is_empty() {
            f64::INFINITY
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    RunSummary {
        variant: run.label.clone(),
        method: run.method.kind().name().to_string(),
        params: run.params.clone(),
        frames: measured.len(),
        gpu_ms: pick(|r| r.gpu_ms),
        gpu_prepass_ms_median: pick(|r| r.gpu_prepass_ms).median,
        gpu_terrain_ms_median: pick(|r| r.gpu_terrain_ms).median,
        gpu_eval_ms_median: pick(|r| r.gpu_eval_ms).median,
        triangles_median: pick(|r| r.triangles as f64).median,
        tiles_median: tiles_median(&measured),
        budget_overflow_frames: measured.iter().filter(|r| r.budget_overflow > 0).count(),
        error: run.errors.summary(),
        holes_total: measured.iter().map(|r| r.holes).sum(),
        cracks_total: measured.iter().map(|r| r.cracks).sum(),
        silhouette_px_max: measured.iter().map(|r| r.silhouette_px).max().unwrap_or(0),
        psnr_db_mean: finite_mean(|r| r.psnr_db),
        ssim_mean: finite_mean(|r| r.ssim),
        flip_mean: mean_of(|f| f.mean),
        flip_p99_mean: mean_of(|f| f.p99),
        flip_frames: flips.len(),
        popping_px: Summary::of(&mut popping),
        swimming_m,
        swimming_px,
        oracle_triangles_median: oracle_median(&measured, |_, o| o as f64),
        coarse: run.coarse.summary(),
        oracle_ratio_median: oracle_median(&measured, |r, o| r.triangles as f64 / o.max(1) as f64),
    }
}

/// What the errors and images are measured against, in words (report.md's "Reference").
fn reference_text(on_earth: bool, clipmap: bool) -> String {
    format!(
        "geometric errors against level 0 of the data, exactly: the full-resolution mesh brute force draws (every sample a vertex{}), evaluated on the GPU from reference tiles read from level 0{}; images (PSNR, SSIM, FLIP, holes) against brute force rendered with the same cameras{}",
        if on_earth {
            ", on the WGS84 ellipsoid where the renderers' geolocation lattice places it: each pixel's point mapped back to the grid through the lattice, heights along its up"
        } else {
            ""
        },
        if clipmap {
            " (the pyramid's, never a clipmap level)"
        } else {
            ""
        },
        if clipmap {
            " through the same clipmap"
        } else {
            ""
        }
    )
}

/// The median of the rows' tiles (None when no row has them).
fn tiles_median(rows: &[&FrameRow]) -> Option<f64> {
    let v: Vec<f64> = rows
        .iter()
        .filter_map(|r| r.tiles.map(|t| t as f64))
        .collect();
    (!v.is_empty()).then(|| Percentiles::of(v).median)
}

/// Median of `value(row, oracle triangles)` over the rows the oracle ran on (`None` when it
/// ran on none: not a UDLOD variant).
fn oracle_median(rows: &[&FrameRow], value: impl Fn(&FrameRow, u64) -> f64) -> Option<f64> {
    let v: Vec<f64> = rows
        .iter()
        .filter_map(|r| r.oracle_triangles.map(|o| value(r, o)))
        .collect();
    (!v.is_empty()).then(|| Percentiles::of(v).median)
}

#[cfg(test)]
mod label_tests {
    use super::*;

    #[test]
    fn pgm_labels_keep_every_swept_key_but_the_grid_scale() {
        let pgm = MethodConfig::Pgm(Default::default());
        let g = |warp: f64| {
            variant_label(
                &pgm,
                &[("grid_scale".into(), 1.0), ("warp_rows".into(), warp)],
            )
        };
        // Two variants that differ only in warp_rows must not share a label (they did).
        assert_ne!(g(0.0), g(1.0));
        assert!(
            g(0.0).starts_with("pgm ") && g(0.0).ends_with(" warp_rows=0"),
            "{}",
            g(0.0)
        );
        let only_grid = variant_label(&pgm, &[("grid_scale".into(), 1.0)]);
        assert!(!only_grid.contains('='), "{only_grid}");
    }
}

//! One evaluation: a scenario rendered by several methods and parameter values, every frame
//! measured against the exact surface and against the brute-force reference image, plus the
//! temporal metrics (popping, swimming). `vkterrain eval` and `benches/eval.rs` drive it.

use std::sync::Arc;

use serde::Serialize;

use super::metrics::{self, ErrorHistogram, GeometricError, Summary, SwimTracker};
use super::oracle::Oracle;
use crate::dataset::Heightmap;
use crate::driver::Gpu;
use crate::error::{Error, Result};
use crate::lod::{MethodConfig, MethodKind};
use crate::readback::{FrameView, OwnedFrame};
use crate::render::stats::Percentiles;
use crate::render::{RenderOptions, Renderer};
use crate::scene::Scenario;

/// Every this many frames, swimming starts tracking the points a 12 x 8 pixel grid of the
/// reference frame sees.
const SWIM_SEED_EVERY: usize = 8;

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
        return format!("pgm {}x{}", s.grid_cols, s.grid_rows);
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
    /// Interval between this frame's delivery and the previous one (ms; 0 for the first).
    pub frame_ms: f64,
    pub gpu_prepass_ms: f64,
    pub gpu_terrain_ms: f64,
    pub cpu_record_ms: f64,
    pub triangles: u64,
    pub error: GeometricError,
    pub holes: usize,
    pub psnr_db: f64,
    pub ssim: f64,
    /// 99th percentile of the per-pixel change of the error image since the previous frame.
    pub popping_p99_px: f64,
    /// The triangle oracle's count for this frame at the variant's tau (UDLOD variants, on
    /// the frames the oracle runs on: `eval::oracle`).
    pub oracle_triangles: Option<u64>,
}

/// Summary of one variant over the frames after warm-up.
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    pub variant: String,
    pub method: String,
    pub params: Vec<(String, f64)>,
    pub frames: usize,
    pub frame_ms: Percentiles,
    pub gpu_prepass_ms_median: f64,
    pub gpu_terrain_ms_median: f64,
    pub triangles_median: f64,
    /// Over all pixels of all measured frames (percentiles to 1.2%, never understated).
    pub error: GeometricError,
    pub holes_total: usize,
    pub psnr_db_mean: f64,
    pub ssim_mean: f64,
    /// Of the per-frame 99th percentiles.
    pub popping_px: Summary,
    /// Per fixed world point: range of its height error (metres) and that range in pixels.
    pub swimming_m: Summary,
    pub swimming_px: Summary,
    /// Median over the oracle's frames of the oracle's triangle count, and of this variant's
    /// triangles divided by it (UDLOD variants only).
    pub oracle_triangles_median: Option<f64>,
    pub oracle_ratio_median: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Evaluation {
    pub dataset: String,
    pub scenario: String,
    pub device: String,
    pub width: u32,
    pub height: u32,
    pub frames: u32,
    pub warmup: usize,
    pub reference: String,
    pub summaries: Vec<RunSummary>,
    pub rows: Vec<FrameRow>,
    /// Frames kept for images: (variant, frame index, reference, method) — not serialized.
    #[serde(skip)]
    pub images: Vec<(String, u64, Arc<OwnedFrame>, Arc<OwnedFrame>)>,
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
    /// Shared with every renderer of the run (never copied).
    pub data: &'a Arc<Heightmap>,
    pub scenario: &'a Scenario,
    pub frames: u32,
    pub warmup: usize,
    pub options: RenderOptions,
    /// Frames to keep for side-by-side images.
    pub image_frames: Vec<u64>,
}

fn render_all(
    setup: &EvalSetup<'_>,
    method: &MethodConfig,
    progress: &mut dyn Progress,
    label: &str,
) -> Result<(Vec<OwnedFrame>, Vec<crate::render::stats::FrameRecord>)> {
    let mut options = setup.options.clone();
    options.readback_depth = true;
    let mut frames = Vec::with_capacity(setup.frames as usize);
    let records;
    {
        let mut renderer = Renderer::new(setup.gpu, setup.data, method.clone(), options)?;
        progress.start(label, setup.frames as u64);
        let mut sink = |f: &FrameView<'_>| {
            frames.push(OwnedFrame::copy_of(f));
            Ok(())
        };
        for k in 0..setup.frames as u64 {
            renderer.render(setup.scenario.camera(k), &mut sink)?;
            progress.advance();
        }
        renderer.finish(&mut sink)?;
        records = renderer.stats.frames.clone();
        progress.finish();
    }
    Ok((frames, records))
}

/// Renders the reference (brute force) and every variant, and measures them.
pub fn evaluate(
    setup: &EvalSetup<'_>,
    variants: &[Variant],
    progress: &mut dyn Progress,
) -> Result<Evaluation> {
    let (reference, _) = render_all(
        setup,
        &MethodConfig::Brute {},
        progress,
        "reference (brute force)",
    )?;
    let reference: Vec<Arc<OwnedFrame>> = reference.into_iter().map(Arc::new).collect();
    let (w, h) = (setup.options.width, setup.options.height);
    let focal = setup.scenario.camera(0).focal_px(h);
    let mut summaries = Vec::new();
    let mut oracle: Option<Oracle> = None;
    let measured_frames = (setup.frames as usize).saturating_sub(setup.warmup);
    let oracle_stride = measured_frames.div_ceil(ORACLE_FRAMES).max(1);
    let mut rows = Vec::new();
    let mut images = Vec::new();
    for v in variants {
        let (frames, records) = render_all(setup, &v.method, progress, &v.label)?;
        let mut swim = SwimTracker::new();
        let mut previous_error: Option<Vec<Option<f64>>> = None;
        let mut all_errors = ErrorHistogram::default();
        let mut my_rows = Vec::new();
        for (k, f) in frames.into_iter().enumerate() {
            let depth = f.depth.as_ref().expect("depth read back");
            let r = &reference[k];
            let errors = metrics::pixel_errors(&f.camera, w, h, depth, setup.data);
            let image = metrics::error_image(&f.camera, w, h, depth, setup.data);
            let popping = match &previous_error {
                Some(prev) => {
                    let mut p = metrics::popping(prev, &image, depth, w, h);
                    Summary::of(&mut p).p99
                }
                None => 0.0,
            };
            previous_error = Some(image);
            if k % SWIM_SEED_EVERY == 0 {
                swim.seed(
                    &r.camera,
                    w,
                    h,
                    r.depth.as_ref().unwrap(),
                    setup.data,
                    12,
                    8,
                );
            }
            swim.observe(&f.camera, w, h, depth, setup.data);
            let rec = records.get(k);
            let oracle_triangles = match &v.method {
                MethodConfig::Udlod(s)
                    if k >= setup.warmup && (k - setup.warmup) % oracle_stride == 0 =>
                {
                    let o = oracle.get_or_insert_with(|| Oracle::new(setup.data));
                    Some(o.count(setup.data, &f.camera, w, h, s.tau_px).triangles)
                }
                _ => None,
            };
            let row = FrameRow {
                variant: v.label.clone(),
                method: v.kind().name().to_string(),
                frame: f.index,
                frame_ms: rec.map_or(0.0, |r| r.interval_ms),
                gpu_prepass_ms: f.timings.gpu_prepass_ms,
                gpu_terrain_ms: f.timings.gpu_terrain_ms,
                cpu_record_ms: f.timings.cpu_record_ms,
                triangles: f.triangles,
                error: GeometricError::of(&errors),
                holes: metrics::holes(r.depth.as_ref().unwrap(), depth, w, h),
                psnr_db: metrics::psnr(&r.rgba, &f.rgba),
                ssim: metrics::ssim(&r.rgba, &f.rgba, w, h),
                popping_p99_px: popping,
                oracle_triangles,
            };
            if k >= setup.warmup {
                all_errors.add(&errors);
            }
            if setup.image_frames.contains(&f.index) {
                images.push((v.label.clone(), f.index, r.clone(), Arc::new(f)));
            }
            my_rows.push(row);
        }
        let measured: Vec<&FrameRow> = my_rows.iter().skip(setup.warmup).collect();
        let pick =
            |g: fn(&FrameRow) -> f64| Percentiles::of(measured.iter().map(|r| g(r)).collect());
        let mut popping: Vec<f64> = measured.iter().skip(1).map(|r| r.popping_p99_px).collect();
        let (swimming_m, swimming_px) = swim.summary(focal);
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
        summaries.push(RunSummary {
            variant: v.label.clone(),
            method: v.kind().name().to_string(),
            params: v.params.clone(),
            frames: measured.len(),
            frame_ms: Percentiles::of(
                measured
                    .iter()
                    .map(|r| r.frame_ms)
                    .filter(|&x| x > 0.0)
                    .collect(),
            ),
            gpu_prepass_ms_median: pick(|r| r.gpu_prepass_ms).median,
            gpu_terrain_ms_median: pick(|r| r.gpu_terrain_ms).median,
            triangles_median: pick(|r| r.triangles as f64).median,
            error: all_errors.summary(),
            holes_total: measured.iter().map(|r| r.holes).sum(),
            psnr_db_mean: finite_mean(|r| r.psnr_db),
            ssim_mean: finite_mean(|r| r.ssim),
            popping_px: Summary::of(&mut popping),
            swimming_m,
            swimming_px,
            oracle_triangles_median: oracle_median(&measured, |_, o| o as f64),
            oracle_ratio_median: oracle_median(&measured, |r, o| {
                r.triangles as f64 / o.max(1) as f64
            }),
        });
        rows.extend(my_rows);
    }
    Ok(Evaluation {
        dataset: setup.data.name.clone(),
        scenario: setup.scenario.name.clone(),
        device: setup.gpu.info.name.clone(),
        width: w,
        height: h,
        frames: setup.frames,
        warmup: setup.warmup,
        reference: "brute force: the full-resolution mesh (every sample a vertex); errors are measured against the same mesh evaluated exactly on the CPU".into(),
        summaries,
        rows,
        images,
    })
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

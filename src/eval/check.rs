//! The cross-check (`vkterrain eval --cross-check`, `tests/eval_gpu.rs`): every frame measured a
//! second time on the CPU ([`super::metrics`], rows in parallel with rayon) from read-back
//! colour and depth, and compared with the GPU's numbers: histograms within one bin, means and
//! maxima to f32 precision, holes and PSNR exactly, SSIM to 1e-4, swimming to 5%.
//!
//! The GPU computes in f32, the CPU in f64: a height error is resolved to a few f32 ulps of
//! the distances involved, so values below the [`Floors`] (32 ulps of the far plane in metres;
//! 32 ulps of the focal length in pixels, the same bound projected: 0.005 px at 1080p) are f32
//! noise and compared as one bin.

use serde::Serialize;

use super::gpu::{FrameShape, GpuFrameMetrics};
use super::metrics::{
    self, Histogram, OnEarth, SWIM_SEED_EVERY, Summary, SwimTracker, ViewColumns,
};
use crate::dataset::Terrain;
use crate::error::{Error, Result};
use crate::geo::Lattice;
use crate::gpu_constants::EVAL_NO_ERROR_PX;
use crate::render::{FrameRequest, RenderOptions};

/// The views of one frame as the CPU metrics take them.
pub fn views_of(options: &RenderOptions, requests: &[FrameRequest]) -> Vec<ViewColumns> {
    requests
        .iter()
        .enumerate()
        .map(|(v, r)| {
            let (first, count) = crate::render::view_columns(options.width, options.views, v);
            ViewColumns {
                camera: r.camera,
                first,
                count,
            }
        })
        .collect()
}

/// A delivered frame and the reference frame of the same cameras, on the host.
pub struct CpuFrame<'a> {
    pub rgba: &'a [u8],
    pub depth: Option<&'a [f32]>,
    pub reference_rgba: Option<&'a [u8]>,
    pub reference_depth: Option<&'a [f32]>,
}

/// The measurements both paths produce for a frame.
#[derive(Clone, Debug, Default)]
pub struct FrameMeasures {
    pub metres: Histogram,
    pub pixels: Histogram,
    pub popping: Histogram,
    pub holes: metrics::Holes,
    pub psnr_db: f64,
    pub ssim: f64,
}

impl From<&GpuFrameMetrics> for FrameMeasures {
    fn from(g: &GpuFrameMetrics) -> Self {
        FrameMeasures {
            metres: g.metres.clone(),
            pixels: g.pixels.clone(),
            popping: g.popping.clone(),
            holes: g.holes,
            psnr_db: g.psnr_db(),
            ssim: g.ssim(),
        }
    }
}

/// A frame measured on the CPU ([`metrics`]): the measures and the signed screen-space error
/// image (for the next frame's popping, against `previous`).
pub fn cpu_measures<S: metrics::ExactSurface + ?Sized>(
    data: &S,
    views: &[ViewColumns],
    shape: FrameShape,
    frame: &CpuFrame<'_>,
    previous: Option<&[Option<f64>]>,
) -> Result<(FrameMeasures, Vec<Option<f64>>)> {
    let missing = || Error::invalid("cross-check", "needs read-back depth and colour");
    let depth = frame.depth.ok_or_else(missing)?;
    let reference_depth = frame.reference_depth.ok_or_else(missing)?;
    let reference_rgba = frame.reference_rgba.ok_or_else(missing)?;
    let (w, h) = (shape.width, shape.height);
    let errors = metrics::pixel_errors_views(views, w, h, depth, data);
    let mut cpu = FrameMeasures::default();
    let mut image = vec![None; (w * h) as usize];
    for e in &errors {
        cpu.metres.add(e.metres.abs());
        cpu.pixels.add(e.pixels);
        image[(e.y * w + e.x) as usize] = Some(e.pixels.copysign(e.metres));
    }
    if let Some(previous) = previous {
        for v in metrics::popping(previous, &image, depth, w, h) {
            cpu.popping.add(v);
        }
    }
    cpu.holes = metrics::holes(reference_depth, depth, w, h);
    cpu.psnr_db = metrics::psnr(reference_rgba, frame.rgba);
    cpu.ssim = metrics::ssim(reference_rgba, frame.rgba, w, h);
    Ok((cpu, image))
}

/// The CPU side of one renderer's cross-check.
pub struct CpuRun {
    shape: FrameShape,
    /// The renderers' geolocation lattice on the earth (None: the flat world).
    lattice: Option<Lattice>,
    previous: Option<Vec<Option<f64>>>,
    swim: SwimTracker,
    problems: Vec<String>,
    frames: usize,
}

impl CpuRun {
    /// A cross-check of frames of `shape`, on the earth through `lattice` (None: flat).
    pub fn new(shape: FrameShape, lattice: Option<Lattice>) -> Self {
        CpuRun {
            shape,
            lattice,
            previous: None,
            swim: SwimTracker::new(),
            problems: Vec::new(),
            frames: 0,
        }
    }

    /// Measures frame `k` on the CPU and compares it with the GPU's `gpu`.
    pub fn measure(
        &mut self,
        data: &Terrain,
        views: &[ViewColumns],
        k: u64,
        frame: &CpuFrame<'_>,
        gpu: &GpuFrameMetrics,
    ) -> Result<()> {
        match self.lattice.take() {
            None => self.measure_on(data, views, k, frame, gpu),
            Some(lattice) => {
                let surface = OnEarth {
                    surface: data,
                    lattice: &lattice,
                };
                let result = self.measure_on(&surface, views, k, frame, gpu);
                self.lattice = Some(lattice);
                result
            }
        }
    }

    fn measure_on<S: metrics::ExactSurface + ?Sized>(
        &mut self,
        data: &S,
        views: &[ViewColumns],
        k: u64,
        frame: &CpuFrame<'_>,
        gpu: &GpuFrameMetrics,
    ) -> Result<()> {
        let (cpu, image) = cpu_measures(data, views, self.shape, frame, self.previous.as_deref())?;
        let (w, h) = (self.shape.width, self.shape.height);
        let floors = Floors::of(views, h);
        if let Some(gpu_image) = &gpu.error_image
            && let Some(p) = compare_images(gpu_image, &image, w, floors.pixels)
        {
            self.problems.push(format!("frame {k}: {p}"));
        }
        self.previous = Some(image);
        let missing = || Error::invalid("cross-check", "needs read-back depth");
        let (depth, reference_depth) = (
            frame.depth.ok_or_else(missing)?,
            frame.reference_depth.ok_or_else(missing)?,
        );
        if k % SWIM_SEED_EVERY == 0 {
            self.swim.seed(views, w, h, reference_depth, data);
        }
        self.swim.observe(views, w, h, depth, data);
        for p in compare(&FrameMeasures::from(gpu), &cpu, floors) {
            self.problems.push(format!("frame {k}: {p}"));
        }
        self.frames += 1;
        Ok(())
    }
}

/// The outcome of a cross-check.
#[derive(Clone, Debug, Default, Serialize)]
pub struct CrossCheck {
    /// Frames compared (every renderer's).
    pub frames: usize,
    /// Swimming (mean px) per renderer: GPU, CPU.
    pub swimming_px: Vec<(String, f64, f64)>,
    /// Every difference beyond the tolerances (empty: the paths agree).
    pub problems: Vec<String>,
}

impl CrossCheck {
    /// Adds a renderer's CPU run; `gpu_swim` is the GPU path's swimming summary.
    pub fn add_run(&mut self, label: &str, cpu: CpuRun, gpu_swim: Summary, focal_px: f64) {
        self.frames += cpu.frames;
        let (_, cpu_swim) = cpu.swim.summary(focal_px);
        if !close(gpu_swim.mean, cpu_swim.mean, 0.05, 1e-4) || gpu_swim.count != cpu_swim.count {
            self.problems.push(format!(
                "{label}: swimming {:.5} px over {} points (GPU) vs {:.5} px over {} (CPU)",
                gpu_swim.mean, gpu_swim.count, cpu_swim.mean, cpu_swim.count
            ));
        }
        self.swimming_px
            .push((label.to_string(), gpu_swim.mean, cpu_swim.mean));
        self.problems
            .extend(cpu.problems.into_iter().map(|p| format!("{label}: {p}")));
    }
}

/// Pixels whose signed screen-space errors differ (GPU `EVAL_NO_ERROR_PX`: none) beyond f32
/// precision, when more than a few.
fn compare_images(gpu: &[f32], cpu: &[Option<f64>], width: u32, floor: f64) -> Option<String> {
    let differs = |(g, c): (&f32, &Option<f64>)| {
        let g = (*g < EVAL_NO_ERROR_PX).then_some(*g as f64);
        match (g, *c) {
            (Some(a), Some(b)) => !close(a, b, 1e-3, floor),
            (a, b) => a.is_some() != b.is_some(),
        }
    };
    let bad: Vec<usize> = gpu
        .iter()
        .zip(cpu)
        .enumerate()
        .filter(|(_, p)| differs(*p))
        .map(|(i, _)| i)
        .collect();
    let slack = (cpu.iter().flatten().count() / 1000).max(2);
    let &first = bad.first()?;
    (bad.len() > slack).then(|| {
        format!(
            "error image: {} pixels differ, first ({}, {}): {} vs {:?}",
            bad.len(),
            first as u32 % width,
            first as u32 / width,
            gpu[first],
            cpu[first]
        )
    })
}

fn close(a: f64, b: f64, relative: f64, absolute: f64) -> bool {
    (a == b) || (a - b).abs() <= relative * a.abs().max(b.abs()) + absolute
}

/// The f32 noise floors below which the GPU's values are not resolved (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floors {
    pub metres: f64,
    pub pixels: f64,
}

impl Floors {
    /// The floors of a frame of `views`, `height` pixels tall.
    pub fn of(views: &[ViewColumns], height: u32) -> Floors {
        let ulps = 32.0 * f32::EPSILON as f64;
        let far = views.iter().map(|v| v.camera.far).fold(0.0, f64::max);
        let focal = views
            .iter()
            .map(|v| v.camera.focal_px(height))
            .fold(0.0, f64::max);
        Floors {
            metres: ulps * far,
            pixels: ulps * focal,
        }
    }
}

/// Whether every value of `a` can be matched with a value of `b` at most one bin away (and the
/// other way round), allowing `slack` unmatched values, values up to `floor` counting as one
/// bin: the cumulative counts never fall more than `slack` behind the other's one bin earlier.
pub fn within_one_bin(a: &Histogram, b: &Histogram, slack: u64, floor: f64) -> bool {
    if a.count().abs_diff(b.count()) > slack {
        return false;
    }
    let first = Histogram::bin(floor);
    let (mut ca, mut cb, mut prev_a, mut prev_b) = (0u64, 0u64, 0u64, 0u64);
    for (i, (&na, &nb)) in a.bins().iter().zip(b.bins()).enumerate() {
        ca += na;
        cb += nb;
        if i < first {
            continue;
        }
        if ca + slack < prev_b || cb + slack < prev_a {
            return false;
        }
        (prev_a, prev_b) = (ca, cb);
    }
    true
}

/// The differences between the GPU's and the CPU's measures of one frame beyond the
/// tolerances.
pub fn compare(gpu: &FrameMeasures, cpu: &FrameMeasures, floors: Floors) -> Vec<String> {
    let mut out = Vec::new();
    for (name, g, c, floor) in [
        ("height error", &gpu.metres, &cpu.metres, floors.metres),
        (
            "screen-space error",
            &gpu.pixels,
            &cpu.pixels,
            floors.pixels,
        ),
        ("popping", &gpu.popping, &cpu.popping, 2.0 * floors.pixels),
    ] {
        // Pixels on the data's very edge may fall either way in f32 and f64.
        let slack = (c.count() / 1000).max(2);
        if !within_one_bin(g, c, slack, floor) {
            out.push(format!(
                "{name} histograms differ by more than one bin ({} vs {} values; p99 {:.4} vs {:.4})",
                g.count(),
                c.count(),
                g.quantile(0.99),
                c.quantile(0.99)
            ));
        }
        if name != "popping" {
            let (gs, cs) = (g.summary(), c.summary());
            if !close(gs.mean, cs.mean, 1e-3, floor) || !close(gs.max, cs.max, 1e-2, floor) {
                out.push(format!(
                    "{name}: mean {:.6} vs {:.6}, max {:.6} vs {:.6}",
                    gs.mean, cs.mean, gs.max, cs.max
                ));
            }
        }
    }
    if gpu.holes != cpu.holes {
        out.push(format!("holes {:?} vs {:?}", gpu.holes, cpu.holes));
    }
    if !(gpu.psnr_db == cpu.psnr_db || close(gpu.psnr_db, cpu.psnr_db, 1e-9, 1e-9)) {
        out.push(format!("PSNR {} vs {} dB", gpu.psnr_db, cpu.psnr_db));
    }
    if (gpu.ssim - cpu.ssim).abs() > 1e-4 {
        out.push(format!("SSIM {:.6} vs {:.6}", gpu.ssim, cpu.ssim));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn histogram(values: impl Iterator<Item = f64>) -> Histogram {
        let mut h = Histogram::default();
        values.for_each(|v| h.add(v));
        h
    }

    #[test]
    fn histograms_within_one_bin_and_not() {
        let values: Vec<f64> = (1..2000).map(|i| i as f64 * 0.0137).collect();
        let a = histogram(values.iter().copied());
        assert!(within_one_bin(&a, &a, 0, 0.0));
        // Every value moved by half a bin: at most one bin away.
        let half = histogram(values.iter().map(|v| v * 1.006));
        assert!(within_one_bin(&a, &half, 0, 0.0));
        // Negative control: three bins away.
        let three = histogram(values.iter().map(|v| v * 1.012f64.powi(3)));
        assert!(!within_one_bin(&a, &three, 2, 0.0));
        // ... unless all of it is below the floor.
        assert!(within_one_bin(&a, &three, 2, 100.0));
        // A few values missing: within the slack, not without.
        let fewer = histogram(values.iter().skip(5).copied());
        assert!(within_one_bin(&a, &fewer, 5, 0.0) && !within_one_bin(&a, &fewer, 2, 0.0));
    }

    #[test]
    fn compare_reports_what_differs() {
        let a = FrameMeasures {
            metres: histogram((1..500).map(|i| i as f64 * 0.01)),
            pixels: histogram((1..500).map(|i| i as f64 * 0.002)),
            popping: histogram((1..300).map(|i| i as f64 * 0.001)),
            holes: metrics::Holes {
                all: 3,
                cracks: 1,
                silhouette_px: 2,
            },
            psnr_db: 31.5,
            ssim: 0.93,
        };
        let floors = Floors {
            metres: 1e-3,
            pixels: 1e-4,
        };
        assert!(compare(&a, &a, floors).is_empty());
        let mut b = a.clone();
        b.pixels = histogram((1..500).map(|i| i as f64 * 0.002 * 1.05));
        b.holes.cracks = 2;
        b.ssim = 0.931;
        let problems = compare(&a, &b, floors);
        assert_eq!(problems.len(), 4, "{problems:?}");
    }
}

//! Frame statistics of a run: medians and percentiles over frames after warm-up.

use std::time::Instant;

use serde::Serialize;

use crate::readback::FrameTimings;

/// Per-frame records collected by the renderer.
#[derive(Default)]
pub struct RunStats {
    pub frames: Vec<FrameRecord>,
    last_delivery: Option<Instant>,
}

#[derive(Clone, Copy, Debug, Serialize)]
pub struct FrameRecord {
    pub timings: FrameTimings,
    pub triangles: u64,
    /// Host time between this frame's delivery and the previous one's: the frame time as a
    /// consumer sees it. 0 where there is no steady-state interval: the first frame, and frames
    /// drained by `Renderer::finish` (delivered back to back, without new frames behind them).
    pub interval_ms: f64,
    /// Delivered by `Renderer::finish` rather than in the render loop.
    pub drained: bool,
    /// Host time spent in the frame sink (e.g. copying into a ring).
    pub sink_ms: f64,
    /// The next frame was still executing on the GPU while this one was delivered.
    pub overlapped: bool,
}

impl RunStats {
    pub fn record(
        &mut self,
        timings: &FrameTimings,
        triangles: u64,
        overlapped: bool,
        sink_ms: f64,
        drained: bool,
    ) {
        let now = Instant::now();
        let interval_ms = match self.last_delivery {
            Some(t) if !drained => (now - t).as_secs_f64() * 1e3,
            _ => 0.0,
        };
        self.last_delivery = Some(now);
        self.frames.push(FrameRecord {
            timings: *timings,
            triangles,
            interval_ms,
            drained,
            sink_ms,
            overlapped,
        });
    }

    /// Summary over the frames after the first `warmup` (lavapipe compiles shaders lazily, so
    /// the first frames are not representative).
    pub fn summary(&self, warmup: usize) -> Summary {
        let frames = if self.frames.len() > warmup {
            &self.frames[warmup..]
        } else {
            &self.frames[..]
        };
        // The first delivered frame and drained ones have no steady-state interval.
        let intervals: Vec<f64> = frames
            .iter()
            .map(|f| f.interval_ms)
            .filter(|&v| v > 0.0)
            .collect::<Vec<_>>();
        let pick = |f: fn(&FrameRecord) -> f64| Percentiles::of(frames.iter().map(f).collect());
        Summary {
            frames: frames.len(),
            warmup: self.frames.len() - frames.len(),
            frame_intervals: intervals.len(),
            frame_ms: Percentiles::of(intervals),
            gpu_total_ms: pick(|f| f.timings.gpu_total_ms()),
            gpu_prepass_ms: pick(|f| f.timings.gpu_prepass_ms),
            gpu_terrain_ms: pick(|f| f.timings.gpu_terrain_ms),
            gpu_readback_ms: pick(|f| f.timings.gpu_readback_ms),
            cpu_record_ms: pick(|f| f.timings.cpu_record_ms),
            cpu_wait_ms: pick(|f| f.timings.cpu_wait_ms),
            sink_ms: pick(|f| f.sink_ms),
            triangles: Percentiles::of(frames.iter().map(|f| f.triangles as f64).collect()),
            overlapped_fraction: if frames.is_empty() {
                0.0
            } else {
                frames.iter().filter(|f| f.overlapped).count() as f64 / frames.len() as f64
            },
        }
    }
}

#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Percentiles {
    pub median: f64,
    pub p90: f64,
    pub p99: f64,
    pub max: f64,
    pub mean: f64,
}

impl Percentiles {
    /// Nearest-rank percentiles (no interpolation).
    pub fn of(mut v: Vec<f64>) -> Self {
        if v.is_empty() {
            return Percentiles::default();
        }
        v.sort_by(f64::total_cmp);
        let rank = |p: f64| nearest_rank(&v, p);
        Percentiles {
            median: rank(0.5),
            p90: rank(0.9),
            p99: rank(0.99),
            max: v[v.len() - 1],
            mean: v.iter().sum::<f64>() / v.len() as f64,
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub frames: usize,
    pub warmup: usize,
    /// Steady-state delivery intervals behind `frame_ms` (see [`FrameRecord::interval_ms`]).
    pub frame_intervals: usize,
    /// Interval between frame deliveries (what a consumer of the frames sees).
    pub frame_ms: Percentiles,
    pub gpu_total_ms: Percentiles,
    pub gpu_prepass_ms: Percentiles,
    pub gpu_terrain_ms: Percentiles,
    pub gpu_readback_ms: Percentiles,
    pub cpu_record_ms: Percentiles,
    pub cpu_wait_ms: Percentiles,
    pub sink_ms: Percentiles,
    pub triangles: Percentiles,
    /// Fraction of frames delivered while the next frame was still on the GPU.
    pub overlapped_fraction: f64,
}

/// Fewer steady-state intervals than this make no frame time worth printing.
pub const MIN_FRAME_INTERVALS: usize = 10;

/// Nearest-rank percentile `q` (0..=1) of ascending `sorted` values (not empty).
pub fn nearest_rank(sorted: &[f64], q: f64) -> f64 {
    sorted[((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1]
}

/// Peak resident set size of this process in bytes (`VmHWM` of `/proc/self/status`; `None`
/// where that file does not exist).
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

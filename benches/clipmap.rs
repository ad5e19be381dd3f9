//! The chunked clipmap under a fast flight (config/clipmap.toml: 300 m/s at 500 m above ground
//! over the 4097² procedural pyramid with 64-texel nodes, UDLOD meshing) against the same
//! flight with heights from one texture, and with a second (rear) camera drawn into the same
//! frames through the same atlas, in one process so the rows compare as ratios.
//!
//! Reports frame time (median, p99, max), the largest frame time among frames that uploaded
//! nodes divided by the median, the CPU time of record+submit (which includes the clipmap's
//! update), the atlas and staging memory against the configured budget, the most resident
//! nodes, frames drawn with fallback data, the device memory in use, and the streaming
//! counters.
//!
//! `make bench-clipmap` (= `make data-proc4k` then `cargo bench --bench clipmap`).
//! `VKTERRAIN_CLIPMAP_FRAMES=N` (default 300) and `VKTERRAIN_CLIPMAP_CONFIG=F` override;
//! results are also written to `target/bench/clipmap.json`.

use std::sync::Arc;

use clap::Parser;
use vkterrain::cli::render::{Prepared, RenderArgs, prepare};
use vkterrain::config::Config;
use vkterrain::dataset::Terrain;
use vkterrain::driver::Gpu;
use vkterrain::readback::FrameView;
use vkterrain::render::stats::{FrameRecord, Percentiles, nearest_rank};
use vkterrain::render::{FrameRequest, Renderer};

#[derive(Parser)]
struct Wrapper {
    #[command(flatten)]
    args: RenderArgs,
}

#[derive(serde::Serialize)]
struct Row {
    variant: String,
    frame_ms: Percentiles,
    cpu_record_ms: Percentiles,
    streaming_frames: usize,
    max_streaming_over_median: f64,
    /// Median of the frames that uploaded over the median of all frames.
    median_streaming_over_median: f64,
    /// The same ratio for frames that uploaded nothing: the machine's own noise.
    max_quiet_over_median: f64,
    fallback_frames: u64,
    max_resident_nodes: usize,
    atlas_capacity: u32,
    atlas_bytes: u64,
    staging_bytes: u64,
    /// Process resident memory at the end of the variant (lavapipe's "GPU" memory is host
    /// memory, so this includes the textures; the level-0 height map is held in both).
    rss_mib: f64,
    /// Device memory in live allocations of the renderer (atlas, targets, method buffers).
    gpu_mib: f64,
    counters: Option<vkterrain::clipmap::Counters>,
}

fn rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map(|kb| kb / 1024.0)
        .unwrap_or(0.0)
}

/// Frames before the statistics start.
const WARMUP: usize = 10;

fn main() -> anyhow::Result<()> {
    let root = env!("CARGO_MANIFEST_DIR");
    let config = std::env::var("VKTERRAIN_CLIPMAP_CONFIG")
        .unwrap_or_else(|_| format!("{root}/config/clipmap.toml"));
    let frames: u32 = std::env::var("VKTERRAIN_CLIPMAP_FRAMES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(300);
    let args = Wrapper::try_parse_from([
        "clipmap",
        "--config",
        &config,
        "--frames",
        &frames.to_string(),
    ])?
    .args;
    let p = match prepare(&args) {
        Ok(p) => p,
        Err(e) => {
            println!("skipping {config}: {e:#} (run `make data-proc4k` first)");
            return Ok(());
        }
    };
    let gpu: Arc<Gpu> = p.config.open_gpu()?;
    print_header(&p, &gpu);
    let mut rows = Vec::new();
    // The two-view variant adds a rear camera (same position, heading + 180 deg), each view
    // half the width, both through the one atlas. The clipmap variants run first, so their
    // RSS is not inflated by the one-texture run's freed memory.
    let rear = vkterrain::scene::ViewOffset {
        yaw_deg: 180.0,
        ..Default::default()
    };
    for (name, clipmap, extra_views) in [
        ("clipmap", true, vec![]),
        ("clipmap 2 views", true, vec![rear]),
        ("one texture", false, vec![]),
    ] {
        let mut config = p.config.clone();
        config.clipmap.enabled = clipmap;
        config.render.extra_views = extra_views;
        let row = run_variant(&gpu, &p, &config, name)?;
        row.print();
        rows.push(row);
    }
    let out = format!("{root}/target/bench");
    std::fs::create_dir_all(&out)?;
    std::fs::write(
        format!("{out}/clipmap.json"),
        serde_json::to_string_pretty(&rows)?,
    )?;
    Ok(())
}

fn print_header(p: &Prepared, gpu: &Gpu) {
    println!(
        "{} ({}x{}, {} frames of {}, {WARMUP} warm-up, method {}, device {})",
        p.data.name(),
        p.config.render.width,
        p.config.render.height,
        p.frames,
        p.scenario.name,
        p.config.method.kind().name(),
        gpu.info.name
    );
    println!(
        "{:<16} {:>9} {:>8} {:>8} {:>10} {:>12} {:>12} {:>12} {:>9} {:>9} {:>14} {:>10} {:>8} {:>8}",
        "variant",
        "median ms",
        "p99 ms",
        "max ms",
        "stream fr",
        "max strm/med",
        "med strm/med",
        "max quiet/med",
        "cpu rec",
        "fallback",
        "resident/cap",
        "atlas MiB",
        "RSS MiB",
        "GPU MiB"
    );
}

/// The flight drawn with `config` (the clipmap on or off, its extra views): its row.
fn run_variant(gpu: &Arc<Gpu>, p: &Prepared, config: &Config, name: &str) -> anyhow::Result<Row> {
    let cm = config.open_clipmap(None)?;
    // With the clipmap, level 0 is read node by node (`p.data`); one texture needs the
    // whole height map.
    let data: Terrain = if config.clipmap.enabled {
        p.data.clone()
    } else {
        config.open_terrain()?
    };
    let (capacity, atlas_bytes, layer_bytes) = cm
        .as_ref()
        .map(|c| (c.settings.atlas_capacity, c.atlas_bytes(), c.layer_bytes()))
        .unwrap_or((0, 0, 0));
    let options = config.render_options();
    let staging_bytes =
        layer_bytes * config.clipmap.max_uploads_per_frame as u64 * options.frames_in_flight as u64;
    let mut renderer = Renderer::with_clipmap(gpu, data, config.method.clone(), options, cm)?;
    let mut sink = |_: &FrameView<'_>| Ok(());
    // Per frame, the nodes uploaded; and the most resident at once.
    let mut uploads = Vec::with_capacity(p.frames as usize);
    let mut max_resident = 0;
    for frame in 0..p.frames as u64 {
        let before = renderer.clipmap().map(|c| c.counters.uploaded).unwrap_or(0);
        let views =
            FrameRequest::with_extra_views(p.scenario.camera(frame), &config.render.extra_views);
        renderer.render_views(&views, &mut sink)?;
        if let Some(c) = renderer.clipmap() {
            uploads.push(c.counters.uploaded - before);
            max_resident = max_resident.max(c.atlas.resident());
            assert!(c.atlas.resident() <= capacity as usize);
        } else {
            uploads.push(0);
        }
    }
    renderer.finish(&mut sink)?;
    let mut row = Row::of_frames(name, &renderer.stats.frames[WARMUP..], &uploads[WARMUP..]);
    row.fallback_frames = renderer
        .clipmap()
        .map(|c| c.counters.fallback_frames)
        .unwrap_or(0);
    row.counters = renderer.clipmap().map(|c| c.counters);
    row.max_resident_nodes = max_resident;
    row.atlas_capacity = capacity;
    row.atlas_bytes = atlas_bytes;
    row.staging_bytes = staging_bytes;
    row.rss_mib = rss_mib();
    row.gpu_mib = gpu.allocated_bytes() as f64 / (1u64 << 20) as f64;
    Ok(row)
}

impl Row {
    /// The frame-time columns of the frames after warm-up, `uploads` the nodes each uploaded;
    /// the memory and clipmap columns zero.
    fn of_frames(name: &str, recs: &[FrameRecord], uploads: &[u64]) -> Row {
        let frame_ms = Percentiles::of(recs.iter().map(|r| r.interval_ms).collect());
        let cpu_record_ms = Percentiles::of(recs.iter().map(|r| r.timings.cpu_record_ms).collect());
        let interval_where = |uploading: bool| -> Vec<f64> {
            recs.iter()
                .zip(uploads)
                .filter(|(_, u)| (**u > 0) == uploading)
                .map(|(r, _)| r.interval_ms)
                .collect()
        };
        let mut streaming = interval_where(true);
        streaming.sort_by(f64::total_cmp);
        let max_quiet = interval_where(false).into_iter().fold(0.0, f64::max);
        let mut sorted: Vec<f64> = recs.iter().map(|r| r.interval_ms).collect();
        sorted.sort_by(f64::total_cmp);
        let median = nearest_rank(&sorted, 0.5);
        let (max_streaming_over_median, median_streaming_over_median) = match streaming.last() {
            None => (0.0, 0.0),
            Some(max) => (max / median, nearest_rank(&streaming, 0.5) / median),
        };
        Row {
            variant: name.into(),
            frame_ms,
            cpu_record_ms,
            streaming_frames: streaming.len(),
            max_streaming_over_median,
            median_streaming_over_median,
            max_quiet_over_median: max_quiet / median,
            fallback_frames: 0,
            max_resident_nodes: 0,
            atlas_capacity: 0,
            atlas_bytes: 0,
            staging_bytes: 0,
            rss_mib: 0.0,
            gpu_mib: 0.0,
            counters: None,
        }
    }

    fn print(&self) {
        println!(
            "{:<16} {:>9.1} {:>8.1} {:>8.1} {:>10} {:>12.2} {:>12.2} {:>12.2} {:>9.2} {:>9} {:>14} {:>10.2} {:>8.0} {:>8.1}",
            self.variant,
            self.frame_ms.median,
            self.frame_ms.p99,
            self.frame_ms.max,
            self.streaming_frames,
            self.max_streaming_over_median,
            self.median_streaming_over_median,
            self.max_quiet_over_median,
            self.cpu_record_ms.median,
            self.fallback_frames,
            format!("{}/{}", self.max_resident_nodes, self.atlas_capacity),
            self.atlas_bytes as f64 / (1u64 << 20) as f64,
            self.rss_mib,
            self.gpu_mib
        );
        if let Some(c) = &self.counters {
            println!(
                "{:<16} {c:?}; staging {:.2} MiB",
                "",
                self.staging_bytes as f64 / (1u64 << 20) as f64
            );
        }
    }
}

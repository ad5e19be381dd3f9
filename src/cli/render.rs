//! `vkterrain render`: the main job. Renders a scenario headless, writes selected frames as PNG
//! and prints a summary (also written as `summary.json`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use clap::Args;

use crate::config::Config;
use crate::dataset::{Level0, Terrain};
use crate::driver::Gpu;
use crate::lod::MethodKind;
use crate::output::png::PngSink;
use crate::readback::FrameSink;
use crate::render::stats::Summary;
use crate::render::{FrameRequest, Renderer};
use crate::scene::Scenario;

#[derive(Args, Debug, Clone, Default)]
pub struct RenderArgs {
    /// Configuration file (TOML); built-in defaults without one.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Number of frames (default: the scenario's).
    #[arg(long)]
    pub frames: Option<u32>,
    /// Output directory for PNGs and summary.json (default: the config's `output.dir`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// LOD method (the config's `[method] name` otherwise).
    #[arg(long, value_enum)]
    pub method: Option<MethodKind>,
    #[arg(long)]
    pub frames_in_flight: Option<u32>,
    /// Scenario file (default: the config's `scenario.path`).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Device override: index or name substring.
    #[arg(long)]
    pub device: Option<String>,
    /// UDLOD screen-space error target in pixels (overrides `[method] tau_px`).
    #[arg(long)]
    pub tau_px: Option<f64>,
    /// UDLOD error-field cap (overrides `[method] error_field_max`; 1 = distance-only).
    #[arg(long)]
    pub error_field_max: Option<f64>,
    /// UDLOD: draw by vertex pulling (no index buffer) instead of the indexed grid.
    #[arg(long)]
    pub vertex_pulling: bool,
    /// Frames excluded from the timing summary (lavapipe compiles shaders lazily).
    #[arg(long, default_value_t = 5)]
    pub warmup: usize,
    /// The terrain's geometry on the earth (overrides `[render] earth`): `ellipsoid` or
    /// `flat` (data sets without a world frame are always flat).
    #[arg(long, value_enum)]
    pub earth: Option<crate::render::EarthGeometry>,
}

/// Everything a render run needs, checked before any output exists.
pub struct Prepared {
    pub config: Config,
    /// The whole grid, or with `[clipmap] enabled` the tile pyramid read node by node (level 0
    /// is then never held whole on the host).
    pub data: Terrain,
    pub scenario: Scenario,
    pub frames: u32,
    pub out_dir: PathBuf,
}

impl RenderArgs {
    /// The config file with this command line's overrides applied and checked.
    pub fn config(&self) -> anyhow::Result<Config> {
        let mut config = Config::load(self.config.as_deref())?;
        let r = &mut config.render;
        r.width = self.width.unwrap_or(r.width);
        r.height = self.height.unwrap_or(r.height);
        r.frames_in_flight = self.frames_in_flight.unwrap_or(r.frames_in_flight);
        if let Some(m) = self.method {
            config.method = config.method.with_kind(m);
        }
        if self.vertex_pulling {
            config.method.udlod_mut("--vertex-pulling")?.vertex_pulling = true;
        }
        if let Some(m) = self.error_field_max {
            config
                .method
                .udlod_mut("--error-field-max")?
                .error_field_max = m;
        }
        if let Some(t) = self.tau_px {
            config.method.udlod_mut("--tau-px")?.tau_px = t;
        }
        if let Some(d) = &self.device {
            config.device.select = Some(d.clone());
        }
        if let Some(e) = self.earth {
            config.render.earth = e;
        }
        config.validate()?;
        Ok(config)
    }
}

/// Loads and checks config, data set and scenario; creates nothing.
pub fn prepare(args: &RenderArgs) -> anyhow::Result<Prepared> {
    let config = args.config()?;
    let data = config.open_terrain()?;
    let scenario = config.open_scenario(args.scenario.as_deref(), &data)?;
    let frames = args.frames.unwrap_or(scenario.frames);
    if frames == 0 {
        anyhow::bail!("--frames must be at least 1");
    }
    let out_dir = match &args.out {
        Some(p) => p.clone(),
        None => config.resolve(&config.output.dir),
    };
    Ok(Prepared {
        config,
        data,
        scenario,
        frames,
        out_dir,
    })
}

/// Frame indices to write: negative entries count from the end.
pub fn png_frames(selection: &[i64], frames: u32) -> Vec<u64> {
    let mut out: Vec<u64> = selection
        .iter()
        .filter_map(|&i| {
            let i = if i < 0 { frames as i64 + i } else { i };
            (0..frames as i64).contains(&i).then_some(i as u64)
        })
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// Renders `p`'s scenario into `renderer`, every frame's views (the camera and the config's
/// extra views) delivered to `sink`, the frames still in flight included.
pub(super) fn render_flight(
    renderer: &mut Renderer,
    p: &Prepared,
    sink: &mut dyn FrameSink,
) -> anyhow::Result<()> {
    for frame in 0..p.frames as u64 {
        let views = FrameRequest::with_extra_views_on(
            p.scenario.camera(frame),
            &p.config.render.extra_views,
            renderer.earth_frame(),
        );
        renderer.render_views(&views, sink)?;
    }
    renderer.finish(sink)?;
    Ok(())
}

pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    let p = prepare(args)?;
    let gpu = p.config.open_gpu()?;
    let mut renderer = p
        .config
        .open_renderer(&gpu, &p.data, p.config.render_options())?;

    let created_dir = !p.out_dir.exists();
    std::fs::create_dir_all(&p.out_dir)
        .with_context(|| format!("{}: cannot create", p.out_dir.display()))?;
    let mut sink = PngSink::new(
        &p.out_dir,
        png_frames(&p.config.output.png_frames, p.frames),
    );
    let result = render_flight(&mut renderer, &p, &mut sink);
    let written = sink.finish();
    let written = match result.and_then(|()| written.map_err(anyhow::Error::from)) {
        Ok(w) => w,
        Err(e) => {
            // Nothing half-written: remove this run's frames (and the directory if we made it).
            cleanup(&p.out_dir, created_dir);
            return Err(e);
        }
    };
    check_validation(&gpu)?;

    let summary = renderer
        .stats
        .summary(args.warmup.min(p.frames.saturating_sub(1) as usize));
    let report = report(&gpu, &renderer, &p, &summary, &written);
    print!("{report}");
    let json = serde_json::json!({
        "device": gpu.info.name,
        "device_type": gpu.info.type_name(),
        "dataset": p.data.name(),
        "method": renderer.method_name(),
        "scenario": p.scenario.name,
        "width": renderer.options.width,
        "height": renderer.options.height,
        "frames_in_flight": renderer.options.frames_in_flight,
        "views": renderer.options.views,
        "readback_path": renderer.readback_path,
        "summary": summary,
        "pngs": written,
        "per_frame": renderer.stats.frames,
        "peak_rss_bytes": crate::render::stats::peak_rss_bytes(),
        "clipmap": renderer.clipmap().map(|c| serde_json::json!({
            "counters": c.counters,
            "tiles": c.tile_counts(),
            "atlas_bytes": c.atlas_bytes(),
            "resident_nodes": c.atlas.resident(),
        })),
    });
    crate::output::write_atomic(
        &p.out_dir.join("summary.json"),
        serde_json::to_string_pretty(&json)?.as_bytes(),
    )?;
    Ok(())
}

fn cleanup(dir: &Path, created: bool) {
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with("frame_") && name.ends_with(".png") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
    if created {
        let _ = std::fs::remove_dir(dir);
    }
}

/// Fails when the validation layers reported anything.
pub fn check_validation(gpu: &Arc<Gpu>) -> anyhow::Result<()> {
    if let Some(log) = gpu.validation()
        && log.count() > 0
    {
        let first = log.messages().into_iter().next().unwrap_or_default();
        anyhow::bail!(
            "{} Vulkan validation message(s); first: {}",
            log.count(),
            first.replace('\n', " ")
        );
    }
    Ok(())
}

/// The summary `render` prints: what ran, then what it measured, then the files written.
fn report(gpu: &Gpu, r: &Renderer, p: &Prepared, s: &Summary, written: &[PathBuf]) -> String {
    use std::fmt::Write;
    let mut o = what_ran(gpu, r, p);
    o.push_str(&measured(s));
    for w in written {
        let _ = writeln!(o, "wrote:           {}", w.display());
    }
    o
}

/// Device, data set, method, clipmap, scenario, views and resolution.
fn what_ran(gpu: &Gpu, r: &Renderer, p: &Prepared) -> String {
    use std::fmt::Write;
    let mut o = String::new();
    let _ = writeln!(
        o,
        "device:          {} ({})",
        gpu.info.name,
        gpu.info.type_name()
    );
    let _ = writeln!(
        o,
        "dataset:         {} ({}x{} samples, {} m)",
        p.data.name(),
        p.data.width(),
        p.data.height(),
        p.data.spacing()
    );
    let _ = writeln!(o, "method:          {}", r.method_name());
    if let Some(c) = r.clipmap() {
        o.push_str(&clipmap_lines(c));
    }
    let _ = writeln!(o, "scenario:        {}", p.scenario.name);
    if r.options.views > 1 {
        let _ = writeln!(
            o,
            "views:           {} cameras side by side in each frame (one atlas)",
            r.options.views
        );
    }
    let _ = writeln!(
        o,
        "resolution:      {}x{}, {} frame(s) in flight, readback {:?}, {}",
        r.options.width,
        r.options.height,
        r.options.frames_in_flight,
        r.readback_path,
        if gpu.modern {
            "dynamic rendering + sync2"
        } else {
            "render pass + classic barriers"
        }
    );
    o
}

/// The clipmap's atlas and loading counters (and an XYZ source's tile counters).
fn clipmap_lines(c: &crate::clipmap::Clipmap) -> String {
    use std::fmt::Write;
    let mut o = String::new();
    let k = &c.counters;
    let _ = writeln!(
        o,
        "clipmap:         atlas {} layers ({:.1} MiB), {} resident; {} loaded, {} load errors, {} deferred, {} evictions, {} frames with fallback data",
        c.settings.atlas_capacity,
        c.atlas_bytes() as f64 / (1u64 << 20) as f64,
        c.atlas.resident(),
        k.loaded,
        k.load_errors,
        k.deferred,
        k.evictions,
        k.fallback_frames
    );
    if let Some(t) = c.tile_counts() {
        let _ = writeln!(
            o,
            "xyz tiles:       {} fetched ({:.1} MB), {} from the disk cache, {} local; {} errors, {} timeouts, {} corrupt; {} evicted from the cache",
            t.fetched,
            t.bytes as f64 / 1e6,
            t.cache_hits,
            t.local,
            t.errors,
            t.timeouts,
            t.corrupt,
            t.evicted
        );
    }
    o
}

/// Frame count, triangles, frame time, GPU and CPU time per pass, overlap and host memory.
fn measured(s: &Summary) -> String {
    use std::fmt::Write;
    let mut o = String::new();
    let _ = writeln!(
        o,
        "frames:          {} ({} warm-up excluded below)",
        s.frames + s.warmup,
        s.warmup
    );
    let _ = writeln!(o, "triangles/frame: {:.0} (median)", s.triangles.median);
    if s.frame_intervals >= crate::render::stats::MIN_FRAME_INTERVALS {
        let _ = writeln!(
            o,
            "frame time:      median {:.2} ms, p99 {:.2} ms, max {:.2} ms ({} intervals)",
            s.frame_ms.median, s.frame_ms.p99, s.frame_ms.max, s.frame_intervals
        );
    } else {
        let _ = writeln!(
            o,
            "frame time:      not measured: {} steady-state intervals after warm-up, {} needed (render more frames)",
            s.frame_intervals,
            crate::render::stats::MIN_FRAME_INTERVALS
        );
    }
    let _ = writeln!(
        o,
        "GPU per pass:    prepass {:.2} ms, terrain {:.2} ms, readback {:.2} ms (medians), total p99 {:.2} ms",
        s.gpu_prepass_ms.median,
        s.gpu_terrain_ms.median,
        s.gpu_readback_ms.median,
        s.gpu_total_ms.p99
    );
    let _ = writeln!(
        o,
        "CPU per frame:   record+submit {:.2} ms, wait {:.2} ms, sink {:.2} ms (medians)",
        s.cpu_record_ms.median, s.cpu_wait_ms.median, s.sink_ms.median
    );
    let _ = writeln!(
        o,
        "overlap:         {:.0}% of frames delivered while the next was on the GPU",
        s.overlapped_fraction * 100.0
    );
    if let Some(b) = crate::render::stats::peak_rss_bytes() {
        let _ = writeln!(
            o,
            "host memory:     peak RSS {:.0} MiB (VmHWM)",
            b as f64 / (1u64 << 20) as f64
        );
    }
    o
}

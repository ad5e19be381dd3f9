//! `vkterrain bench`: frame-time benchmark of one LOD method over the scenario, for several
//! resolutions and numbers of frames in flight, in one process and one device context so the
//! rows compare as ratios (the machines are noisy; absolute numbers drift between runs).
//! `benches/frame_time.rs` runs the same code under `cargo bench`.

use std::fmt::Write;
use std::path::Path;
use std::sync::Arc;

use clap::Args;

use super::render::Prepared;
use crate::driver::Gpu;
use crate::render::stats::Summary;

#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    #[command(flatten)]
    pub render: super::render::RenderArgs,
    /// Resolutions, comma separated.
    #[arg(long, default_value = "1280x720,1920x1080", value_delimiter = ',')]
    pub resolutions: Vec<String>,
    /// Frames in flight to compare, comma separated.
    #[arg(
        long = "compare-frames-in-flight",
        default_value = "1,2",
        value_delimiter = ','
    )]
    pub compare_frames_in_flight: Vec<u32>,
    /// Write the results as JSON here as well.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
}

#[derive(serde::Serialize)]
pub struct BenchRow {
    pub width: u32,
    pub height: u32,
    pub frames_in_flight: u32,
    pub summary: Summary,
}

fn parse_resolution(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s
        .trim()
        .split_once('x')
        .ok_or_else(|| anyhow::anyhow!("resolution {s:?} is not WIDTHxHEIGHT"))?;
    Ok((w.parse()?, h.parse()?))
}

pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    let p = super::render::prepare(&args.render)?;
    let resolutions = checked_resolutions(args, &p)?;
    let gpu = p.config.open_gpu()?;
    let warmup = args.render.warmup.min(p.frames.saturating_sub(2) as usize);
    let mut rows = Vec::new();
    print!("{}", header(&gpu, &p, warmup));
    for &(w, h) in &resolutions {
        for &n in &args.compare_frames_in_flight {
            let s = measure(&gpu, &p, (w, h), n, warmup)?;
            println!("{}", row_line((w, h), n, &s));
            rows.push(BenchRow {
                width: w,
                height: h,
                frames_in_flight: n,
                summary: s,
            });
        }
    }
    super::render::check_validation(&gpu)?;
    if let Some(path) = &args.json {
        write_json(path, &gpu, &p, warmup, &rows)?;
    }
    Ok(())
}

/// `args`' resolutions, after checking that the config accepts each and the renderer each
/// number of frames in flight (before the device is opened).
fn checked_resolutions(args: &BenchArgs, p: &Prepared) -> anyhow::Result<Vec<(u32, u32)>> {
    let resolutions = args
        .resolutions
        .iter()
        .map(|r| parse_resolution(r))
        .collect::<anyhow::Result<Vec<_>>>()?;
    for &(w, h) in &resolutions {
        let mut c = p.config.clone();
        c.render.width = w;
        c.render.height = h;
        c.validate()?;
    }
    for &n in &args.compare_frames_in_flight {
        crate::render::check_frames_in_flight(n as usize)?;
    }
    Ok(resolutions)
}

/// What runs (device, data set, method, scenario, frames) and the table's column heads.
fn header(gpu: &Gpu, p: &Prepared, warmup: usize) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "device {} ({}); dataset {}; method {}; scenario {}; {} frames, {} warm-up excluded",
        gpu.info.name,
        gpu.info.type_name(),
        p.data.name(),
        p.config.method.kind().name(),
        p.scenario.name,
        p.frames,
        warmup
    );
    let _ = writeln!(
        out,
        "{:>10} {:>3} {:>10} {:>10} {:>10} {:>10} {:>10} {:>8}",
        "resolution", "N", "triangles", "median ms", "p99 ms", "gpu ms", "readback", "overlap"
    );
    out
}

/// Renders the scenario once at `w`x`h` with `frames_in_flight` frames in flight, every frame
/// read by the host, and summarizes the frame times after `warmup` frames.
fn measure(
    gpu: &Arc<Gpu>,
    p: &Prepared,
    (w, h): (u32, u32),
    frames_in_flight: u32,
    warmup: usize,
) -> anyhow::Result<Summary> {
    let mut options = p.config.render_options();
    options.width = w;
    options.height = h;
    options.frames_in_flight = frames_in_flight as usize;
    let mut renderer = p.config.open_renderer(gpu, &p.data, options)?;
    // The sink touches every row so the host really reads the frame (as a consumer would).
    let mut checksum = 0u64;
    let mut sink = |f: &crate::readback::FrameView<'_>| {
        checksum = checksum.wrapping_add(
            f.rgba
                .chunks(f.row_stride)
                .map(|r| r[0] as u64)
                .sum::<u64>(),
        );
        Ok(())
    };
    super::render::render_flight(&mut renderer, p, &mut sink)?;
    Ok(renderer.stats.summary(warmup))
}

/// One row of the table: resolution, frames in flight, and `s`'s medians, p99 and overlap.
fn row_line((w, h): (u32, u32), frames_in_flight: u32, s: &Summary) -> String {
    format!(
        "{:>10} {:>3} {:>10.0} {:>10.2} {:>10.2} {:>10.2} {:>10.3} {:>7.0}%",
        format!("{w}x{h}"),
        frames_in_flight,
        s.triangles.median,
        s.frame_ms.median,
        s.frame_ms.p99,
        s.gpu_total_ms.median,
        s.gpu_readback_ms.median,
        s.overlapped_fraction * 100.0
    )
}

/// Writes what ran and the `rows` as JSON to `path` (atomically).
fn write_json(
    path: &Path,
    gpu: &Gpu,
    p: &Prepared,
    warmup: usize,
    rows: &[BenchRow],
) -> anyhow::Result<()> {
    let json = serde_json::json!({
        "device": gpu.info.name,
        "device_type": gpu.info.type_name(),
        "dataset": p.data.name(),
        "method": p.config.method.kind().name(),
        "scenario": p.scenario.name,
        "frames": p.frames,
        "warmup": warmup,
        "rows": rows,
    });
    crate::output::write_atomic(path, serde_json::to_string_pretty(&json)?.as_bytes())?;
    Ok(())
}

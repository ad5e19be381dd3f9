//! UDLOD against brute force on real and procedural data, one process per run so the rows are
//! comparable as ratios: frame time, triangles, tiles, prepass and terrain GPU time, the
//! screen-space geometric error against the exact surface, and the colour difference (PSNR)
//! against brute force's image of the same frame, for tau = 0.5, 1, 2, 4 px (error field on)
//! and tau = 1 distance-only, and tau = 1 drawn by vertex pulling instead of the indexed grid.
//!
//! `cargo bench --bench udlod` uses config/default.toml, config/puget.toml and
//! config/srtm.toml (data sets that are missing are skipped with the command that makes them).
//! `VKTERRAIN_UDLOD_CONFIGS=a.toml,b.toml` and `VKTERRAIN_UDLOD_FRAMES=N` override; results are
//! also written to `target/bench/udlod.json`.

use std::sync::Arc;

use anyhow::Context as _;
use clap::Parser;
use vkterrain::cli::render::{Prepared, RenderArgs, prepare};
use vkterrain::driver::Gpu;
use vkterrain::eval::metrics::{self, GeometricError, PixelError};
use vkterrain::lod::{MethodConfig, MethodKind, UdlodSettings};
use vkterrain::readback::{FrameView, OwnedFrame};
use vkterrain::render::Renderer;
use vkterrain::render::stats::Percentiles;

#[derive(Parser)]
struct Wrapper {
    #[command(flatten)]
    args: RenderArgs,
}

#[derive(serde::Serialize)]
struct Row {
    dataset: String,
    variant: String,
    frame_ms_median: f64,
    frame_ms_p99: f64,
    triangles_median: f64,
    /// Median of the tiles each frame drew after the warm-up (`FrameView::tiles`; 0 for brute
    /// force): not triangles over a full tile's, since collapsed and dropped quadrants draw
    /// fewer.
    tiles_median: f64,
    prepass_ms_median: f64,
    terrain_ms_median: f64,
    error: GeometricError,
    psnr_db_vs_brute: f64,
}

const SAMPLE_EVERY: u64 = 4;
/// Frames before the statistics start.
const WARMUP: usize = 4;

fn main() -> anyhow::Result<()> {
    let root = env!("CARGO_MANIFEST_DIR");
    let configs: Vec<String> = std::env::var("VKTERRAIN_UDLOD_CONFIGS")
        .map(|s| s.split(',').map(String::from).collect())
        .unwrap_or_else(|_| {
            ["default", "puget", "srtm"]
                .iter()
                .map(|c| format!("{root}/config/{c}.toml"))
                .collect()
        });
    let frames: u32 = std::env::var("VKTERRAIN_UDLOD_FRAMES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(24);
    let mut rows = Vec::new();
    for config in &configs {
        rows.extend(bench_config(config, frames)?);
    }
    std::fs::create_dir_all(format!("{root}/target/bench"))?;
    std::fs::write(
        format!("{root}/target/bench/udlod.json"),
        serde_json::to_string_pretty(&rows)?,
    )?;
    Ok(())
}

/// Every variant on one config's data set and flight, a printed row each (none when the data
/// set is missing).
fn bench_config(config: &str, frames: u32) -> anyhow::Result<Vec<Row>> {
    let args =
        Wrapper::try_parse_from(["udlod", "--config", config, "--frames", &frames.to_string()])?
            .args;
    let p = match prepare(&args) {
        Ok(p) => p,
        Err(e) => {
            println!("skipping {config}: {e:#} (see the config's header for how to make its data)");
            return Ok(Vec::new());
        }
    };
    let gpu: Arc<Gpu> = p.config.open_gpu()?;
    println!(
        "\n{} ({}x{}, {} frames of {}, {WARMUP} warm-up, device {})",
        p.data.name(),
        p.config.render.width,
        p.config.render.height,
        frames,
        p.scenario.name,
        gpu.info.name
    );
    println!(
        "{:<24} {:>9} {:>9} {:>10} {:>7} {:>9} {:>9} {:>9} {:>9} {:>8}",
        "variant",
        "median ms",
        "p99 ms",
        "triangles",
        "tiles",
        "prepass",
        "terrain",
        "err p99.9",
        "err max",
        "PSNR dB"
    );
    let base = match &p.config.method {
        MethodConfig::Udlod(s) => s.clone(),
        _ => UdlodSettings::default(),
    };
    // Brute force first: the other variants' PSNR is against its images.
    let mut brute_images: Vec<OwnedFrame> = Vec::new();
    let mut rows = Vec::new();
    for (name, method) in variants(&base) {
        let (row, sampled) = bench_variant(&gpu, &p, name, &method, &brute_images)?;
        row.print();
        if method.kind() == MethodKind::Brute {
            brute_images = sampled;
        }
        rows.push(row);
    }
    Ok(rows)
}

/// Brute force, UDLOD at tau 0.5-4, and at tau 1 by vertex pulling and distance-only.
fn variants(base: &UdlodSettings) -> Vec<(String, MethodConfig)> {
    let at = |tau_px: f64| UdlodSettings {
        tau_px,
        ..base.clone()
    };
    let mut variants: Vec<(String, MethodConfig)> = vec![("brute".into(), MethodConfig::Brute {})];
    for tau in [0.5, 1.0, 2.0, 4.0] {
        variants.push((format!("udlod tau {tau}"), at(tau).into()));
    }
    variants.push((
        "udlod tau 1 pulled".into(),
        UdlodSettings {
            vertex_pulling: true,
            ..at(1.0)
        }
        .into(),
    ));
    variants.push((
        "udlod tau 1 distance-only".into(),
        UdlodSettings {
            error_field_max: 1.0,
            ..at(1.0)
        }
        .into(),
    ));
    variants
}

/// One variant over the flight: its row (PSNR against `brute_images`, the same frames) and
/// the frames it sampled.
fn bench_variant(
    gpu: &Arc<Gpu>,
    p: &Prepared,
    name: String,
    method: &MethodConfig,
    brute_images: &[OwnedFrame],
) -> anyhow::Result<(Row, Vec<OwnedFrame>)> {
    let mut options = p.config.render_options();
    options.readback_depth = true;
    let mut renderer = Renderer::new(gpu, &p.data, method.clone(), options)
        .with_context(|| format!("{name} on {}", p.data.name()))?;
    let mut sampled: Vec<OwnedFrame> = Vec::new();
    let mut tiles = Vec::new();
    let mut sink = |f: &FrameView<'_>| {
        if f.index as usize >= WARMUP {
            tiles.push(f.tiles.unwrap_or(0) as f64);
            if f.index % SAMPLE_EVERY == 0 {
                sampled.push(OwnedFrame::copy_of(f));
            }
        }
        Ok(())
    };
    for frame in 0..p.frames as u64 {
        renderer.render(p.scenario.camera(frame), &mut sink)?;
    }
    renderer.finish(&mut sink)?;
    let s = renderer.stats.summary(WARMUP);
    drop(renderer);
    let grid = p.data.require_grid("udlod bench")?;
    let errors: Vec<PixelError> = sampled
        .iter()
        .flat_map(|f| {
            let depth = f.depth.as_ref().expect("readback_depth is on");
            metrics::pixel_errors(&f.camera, f.width, f.height, depth, &**grid)
        })
        .collect();
    let psnr_values: Vec<f64> = sampled
        .iter()
        .zip(brute_images)
        .map(|(a, b)| metrics::psnr(&b.rgba, &a.rgba))
        .collect();
    // Brute force against no images: no values, infinity (its own reference).
    let psnr_db = if method.kind() == MethodKind::Brute {
        f64::INFINITY
    } else {
        psnr_values.iter().sum::<f64>() / psnr_values.len().max(1) as f64
    };
    let row = Row {
        dataset: p.data.name().to_string(),
        variant: name,
        frame_ms_median: s.frame_ms.median,
        frame_ms_p99: s.frame_ms.p99,
        triangles_median: s.triangles.median,
        tiles_median: Percentiles::of(tiles).median,
        prepass_ms_median: s.gpu_prepass_ms.median,
        terrain_ms_median: s.gpu_terrain_ms.median,
        error: GeometricError::of(&errors),
        psnr_db_vs_brute: psnr_db,
    };
    Ok((row, sampled))
}

impl Row {
    fn print(&self) {
        println!(
            "{:<24} {:>9.1} {:>9.1} {:>10.0} {:>7.0} {:>9.2} {:>9.1} {:>9.3} {:>9.3} {:>8.1}",
            self.variant,
            self.frame_ms_median,
            self.frame_ms_p99,
            self.triangles_median,
            self.tiles_median,
            self.prepass_ms_median,
            self.terrain_ms_median,
            self.error.pixels.p999,
            self.error.pixels.max,
            self.psnr_db_vs_brute
        );
    }
}

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
use vkterrain::cli::render::{RenderArgs, prepare};
use vkterrain::driver::Gpu;
use vkterrain::eval::metrics::{self, GeometricError, PixelError};
use vkterrain::lod::{MethodConfig, MethodKind, UdlodSettings};
use vkterrain::readback::{FrameView, OwnedFrame};
use vkterrain::render::Renderer;

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
    tiles_median: f64,
    prepass_ms_median: f64,
    terrain_ms_median: f64,
    error: GeometricError,
    psnr_db_vs_brute: f64,
}

const SAMPLE_EVERY: u64 = 4;

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
    let warmup = 4usize;
    let mut rows = Vec::new();
    for config in &configs {
        let args = Wrapper::try_parse_from([
            "udlod",
            "--config",
            config,
            "--frames",
            &frames.to_string(),
        ])?
        .args;
        let p = match prepare(&args) {
            Ok(p) => p,
            Err(e) => {
                println!(
                    "skipping {config}: {e:#} (see the config's header for how to make its data)"
                );
                continue;
            }
        };
        let grid = p.data.require_grid("udlod bench")?.clone();
        let gpu: Arc<Gpu> = p.config.open_gpu()?;
        println!(
            "\n{} ({}x{}, {} frames of {}, {warmup} warm-up, device {})",
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
        let mut variants: Vec<(String, MethodConfig)> =
            vec![("brute".into(), MethodConfig::Brute {})];
        for tau in [0.5, 1.0, 2.0, 4.0] {
            variants.push((
                format!("udlod tau {tau}"),
                UdlodSettings {
                    tau_px: tau,
                    ..base.clone()
                }
                .into(),
            ));
        }
        variants.push((
            "udlod tau 1 pulled".into(),
            UdlodSettings {
                tau_px: 1.0,
                vertex_pulling: true,
                ..base.clone()
            }
            .into(),
        ));
        variants.push((
            "udlod tau 1 distance-only".into(),
            UdlodSettings {
                tau_px: 1.0,
                error_field_max: 1.0,
                ..base.clone()
            }
            .into(),
        ));
        let mut brute_images: Vec<OwnedFrame> = Vec::new();
        for (name, method) in variants {
            let mut options = p.config.render_options();
            options.readback_depth = true;
            let mut renderer = Renderer::new(&gpu, &p.data, method.clone(), options)
                .with_context(|| format!("{name} on {}", p.data.name()))?;
            let mut sampled: Vec<OwnedFrame> = Vec::new();
            let mut sink = |f: &FrameView<'_>| {
                if f.index as usize >= warmup && f.index % SAMPLE_EVERY == 0 {
                    sampled.push(OwnedFrame::copy_of(f));
                }
                Ok(())
            };
            for frame in 0..frames as u64 {
                renderer.render(p.scenario.camera(frame), &mut sink)?;
            }
            renderer.finish(&mut sink)?;
            let s = renderer.stats.summary(warmup);
            drop(renderer);
            let errors: Vec<PixelError> = sampled
                .iter()
                .flat_map(|f| {
                    metrics::pixel_errors(
                        &f.camera,
                        f.width,
                        f.height,
                        f.depth.as_ref().unwrap(),
                        &*grid,
                    )
                })
                .collect();
            let error = GeometricError::of(&errors);
            if method.kind() == MethodKind::Brute {
                brute_images = sampled.clone();
            }
            let psnr_values: Vec<f64> = sampled
                .iter()
                .zip(&brute_images)
                .map(|(a, b)| metrics::psnr(&b.rgba, &a.rgba))
                .collect();
            let psnr_db = psnr_values.iter().sum::<f64>() / psnr_values.len().max(1) as f64;
            let tiles = match &method {
                MethodConfig::Udlod(u) => s.triangles.median / ((u.grid_size as f64).powi(2) * 2.0),
                _ => 0.0,
            };
            println!(
                "{:<24} {:>9.1} {:>9.1} {:>10.0} {:>7.0} {:>9.2} {:>9.1} {:>9.3} {:>9.3} {:>8.1}",
                name,
                s.frame_ms.median,
                s.frame_ms.p99,
                s.triangles.median,
                tiles,
                s.gpu_prepass_ms.median,
                s.gpu_terrain_ms.median,
                error.pixels.p999,
                error.pixels.max,
                psnr_db
            );
            rows.push(Row {
                dataset: p.data.name().to_string(),
                variant: name,
                frame_ms_median: s.frame_ms.median,
                frame_ms_p99: s.frame_ms.p99,
                triangles_median: s.triangles.median,
                tiles_median: tiles,
                prepass_ms_median: s.gpu_prepass_ms.median,
                terrain_ms_median: s.gpu_terrain_ms.median,
                error,
                psnr_db_vs_brute: psnr_db,
            });
        }
    }
    std::fs::create_dir_all(format!("{root}/target/bench"))?;
    std::fs::write(
        format!("{root}/target/bench/udlod.json"),
        serde_json::to_string_pretty(&rows)?,
    )?;
    Ok(())
}

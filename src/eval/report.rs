//! Writes an [`Evaluation`]: `results.json`, `frames.csv`, `summary.csv`, charts (SVG + PNG),
//! side-by-side images (reference | method | error heat map) and `report.md`, into a
//! directory that appears only when complete (`<dir>.partial` renamed at the end).

use std::fmt::Write as _;
use std::path::Path;

use super::chart::{Chart, Series, pareto_front};
use super::run::Evaluation;
use crate::dataset::Heightmap;
use crate::error::{Error, Result};
use crate::output::png::write_png;
use crate::output::write_atomic;

fn io(path: &Path, e: std::io::Error) -> Error {
    Error::invalid(path.display().to_string(), e.to_string())
}

/// Heat map of the screen-space error: black (0) over red to yellow (>= `full_px`), grey sky.
fn heat(error_px: Option<f64>, full_px: f64) -> [u8; 3] {
    match error_px {
        None => [96, 96, 96],
        Some(e) => {
            let t = (e.abs() / full_px).clamp(0.0, 1.0);
            let r = (t * 2.0).min(1.0);
            let g = (t * 2.0 - 1.0).max(0.0);
            [(255.0 * r) as u8, (255.0 * g) as u8, 0]
        }
    }
}

/// Writes everything for `eval` into `dir` (must not exist unless `force`).
pub fn write(eval: &Evaluation, data: &Heightmap, dir: &Path, force: bool) -> Result<()> {
    if dir.exists() && !force {
        return Err(Error::invalid(
            dir.display().to_string(),
            "exists (use --force to replace it)",
        ));
    }
    let partial = dir.with_extension("partial");
    if partial.exists() {
        std::fs::remove_dir_all(&partial).map_err(|e| io(&partial, e))?;
    }
    std::fs::create_dir_all(partial.join("images")).map_err(|e| io(&partial, e))?;
    let result = write_into(eval, data, &partial);
    if let Err(e) = result {
        let _ = std::fs::remove_dir_all(&partial);
        return Err(e);
    }
    if dir.exists() {
        std::fs::remove_dir_all(dir).map_err(|e| io(dir, e))?;
    }
    std::fs::rename(&partial, dir).map_err(|e| io(dir, e))
}

fn write_into(eval: &Evaluation, data: &Heightmap, dir: &Path) -> Result<()> {
    let json = serde_json::to_string_pretty(eval)
        .map_err(|e| Error::invalid("results.json", e.to_string()))?;
    write_atomic(&dir.join("results.json"), json.as_bytes())?;

    let mut csv = String::from(
        "variant,method,frame,frame_ms,gpu_prepass_ms,gpu_terrain_ms,cpu_record_ms,triangles,err_px_mean,err_px_p99,err_px_p999,err_px_max,err_m_mean,err_m_p999,err_m_max,holes,psnr_db,ssim,popping_p99_px,oracle_triangles\n",
    );
    for r in &eval.rows {
        let _ = writeln!(
            csv,
            "{},{},{},{:.3},{:.3},{:.3},{:.3},{},{:.5},{:.5},{:.5},{:.5},{:.4},{:.4},{:.4},{},{:.3},{:.5},{:.5},{}",
            r.variant,
            r.method,
            r.frame,
            r.frame_ms,
            r.gpu_prepass_ms,
            r.gpu_terrain_ms,
            r.cpu_record_ms,
            r.triangles,
            r.error.pixels.mean,
            r.error.pixels.p99,
            r.error.pixels.p999,
            r.error.pixels.max,
            r.error.metres.mean,
            r.error.metres.p999,
            r.error.metres.max,
            r.holes,
            r.psnr_db,
            r.ssim,
            r.popping_p99_px,
            optional(r.oracle_triangles.map(|v| v as f64), 0)
        );
    }
    write_atomic(&dir.join("frames.csv"), csv.as_bytes())?;

    let mut sum = String::from(
        "variant,method,frames,frame_ms_median,frame_ms_p90,frame_ms_p99,frame_ms_max,triangles_median,err_px_mean,err_px_p99,err_px_p999,err_px_max,err_m_p999,holes,psnr_db,ssim,popping_px_median,popping_px_max,swimming_px_mean,swimming_px_p90,swimming_m_mean,oracle_triangles_median,oracle_ratio_median\n",
    );
    for s in &eval.summaries {
        let _ = writeln!(
            sum,
            "{},{},{},{:.3},{:.3},{:.3},{:.3},{:.0},{:.5},{:.5},{:.5},{:.5},{:.4},{},{:.3},{:.5},{:.5},{:.5},{:.5},{:.5},{:.4},{},{}",
            s.variant,
            s.method,
            s.frames,
            s.frame_ms.median,
            s.frame_ms.p90,
            s.frame_ms.p99,
            s.frame_ms.max,
            s.triangles_median,
            s.error.pixels.mean,
            s.error.pixels.p99,
            s.error.pixels.p999,
            s.error.pixels.max,
            s.error.metres.p999,
            s.holes_total,
            s.psnr_db_mean,
            s.ssim_mean,
            s.popping_px.median,
            s.popping_px.max,
            s.swimming_px.mean,
            s.swimming_px.p99,
            s.swimming_m.mean,
            optional(s.oracle_triangles_median, 0),
            optional(s.oracle_ratio_median, 3)
        );
    }
    write_atomic(&dir.join("summary.csv"), sum.as_bytes())?;

    // Charts: one series per method over its parameter sweep.
    let mut methods: Vec<&str> = eval.summaries.iter().map(|s| s.method.as_str()).collect();
    methods.dedup();
    let series_of = |f: &dyn Fn(&super::run::RunSummary) -> (f64, f64)| -> Vec<Series> {
        methods
            .iter()
            .map(|m| Series {
                name: m.to_string(),
                points: eval
                    .summaries
                    .iter()
                    .filter(|s| s.method == *m)
                    .map(f)
                    .collect(),
                markers: true,
                line: true,
            })
            .collect()
    };
    let time_vs_error: Vec<(f64, f64)> = eval
        .summaries
        .iter()
        .map(|s| (s.error.pixels.p999, s.frame_ms.median))
        .collect();
    let front = pareto_front(&time_vs_error);
    Chart {
        title: format!(
            "Frame time vs error ({}, {}x{})",
            eval.scenario, eval.width, eval.height
        ),
        x_label: "screen-space error, 99.9th percentile (px)".into(),
        y_label: "frame time, median (ms)".into(),
        series: series_of(&|s| (s.error.pixels.p999, s.frame_ms.median)),
        highlight: front.iter().map(|&i| time_vs_error[i]).collect(),
        log_x: false,
    }
    .write(dir, "frame_time_vs_error")?;
    Chart {
        title: "Triangles vs error".into(),
        x_label: "screen-space error, 99.9th percentile (px)".into(),
        y_label: "triangles per frame (median)".into(),
        series: series_of(&|s| (s.error.pixels.p999, s.triangles_median)),
        ..Default::default()
    }
    .write(dir, "triangles_vs_error")?;
    Chart {
        title: "Error over time".into(),
        x_label: "frame".into(),
        y_label: "screen-space error, 99th percentile (px)".into(),
        series: eval
            .summaries
            .iter()
            .map(|s| Series {
                name: s.variant.clone(),
                points: eval
                    .rows
                    .iter()
                    .filter(|r| r.variant == s.variant)
                    .map(|r| (r.frame as f64, r.error.pixels.p99))
                    .collect(),
                markers: false,
                line: true,
            })
            .collect(),
        ..Default::default()
    }
    .write(dir, "error_over_time")?;

    // Side-by-side images.
    let mut image_links = Vec::new();
    for (variant, frame, reference, method) in &eval.images {
        let (w, h) = (method.width, method.height);
        let errors =
            super::metrics::error_image(&method.camera, w, h, method.depth.as_ref().unwrap(), data);
        let mut out = vec![0u8; (3 * w * h * 4) as usize];
        for y in 0..h {
            for x in 0..w {
                let src = ((y * w + x) * 4) as usize;
                for (panel, px) in [
                    (
                        0,
                        [
                            reference.rgba[src],
                            reference.rgba[src + 1],
                            reference.rgba[src + 2],
                        ],
                    ),
                    (
                        1,
                        [method.rgba[src], method.rgba[src + 1], method.rgba[src + 2]],
                    ),
                    (2, heat(errors[(y * w + x) as usize], 2.0)),
                ] {
                    let dst = ((y * 3 * w + panel * w + x) * 4) as usize;
                    out[dst..dst + 3].copy_from_slice(&px);
                    out[dst + 3] = 255;
                }
            }
        }
        let name = format!(
            "images/{}_f{frame:04}.png",
            variant.replace([' ', '=', ','], "_")
        );
        write_png(&dir.join(&name), 3 * w, h, &out)?;
        image_links.push((variant.clone(), *frame, name));
    }

    let mut md = String::new();
    let _ = writeln!(md, "# Evaluation: {} on {}\n", eval.scenario, eval.dataset);
    let _ = writeln!(
        md,
        "{}x{}, {} frames ({} warm-up excluded from summaries), device {}.\nReference: {}.\nDefinitions of every metric: `docs/metrics.md`.\n",
        eval.width, eval.height, eval.frames, eval.warmup, eval.device, eval.reference
    );
    md.push_str(&super::table::markdown(
        super::table::SUMMARY_COLUMNS,
        &eval.summaries,
    ));
    let pareto: Vec<&str> = front
        .iter()
        .map(|&i| eval.summaries[i].variant.as_str())
        .collect();
    let _ = writeln!(
        md,
        "\nPareto front (frame time vs 99.9th-percentile error): {}.\n",
        pareto.join(", ")
    );
    let _ = writeln!(
        md,
        "Charts: ![frame time vs error](frame_time_vs_error.svg) ![triangles vs error](triangles_vs_error.svg) ![error over time](error_over_time.svg)\n(PNG versions beside them, without labels.)\n"
    );
    let _ = writeln!(
        md,
        "## Images (reference | method | screen-space error, black 0 to yellow >= 2 px, grey sky)\n"
    );
    for (variant, frame, link) in image_links {
        let _ = writeln!(
            md,
            "- {variant}, frame {frame}: ![{variant} {frame}]({link})"
        );
    }
    write_atomic(&dir.join("report.md"), md.as_bytes())
}

/// A CSV cell for an optional number: empty when absent.
fn optional(v: Option<f64>, decimals: usize) -> String {
    v.map(|v| format!("{v:.decimals$}")).unwrap_or_default()
}

//! Writes an [`Evaluation`]: `results.json`, `frames.csv`, `summary.csv`, charts (SVG + PNG,
//! both with text), side-by-side images (reference | method | error heat map | FLIP map) and
//! `report.md` (device, resolution, data set, frames, the command that regenerates it), into a
//! directory that appears only when complete (`<dir>.partial` renamed at the end).

use std::fmt::Write as _;
use std::path::Path;

use super::chart::{Chart, Series, pareto_front};
use super::run::{Evaluation, FrameRow, RunSummary};
use crate::error::{Error, Result};
use crate::gpu_constants::EVAL_NO_ERROR_PX;
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
pub fn write(eval: &Evaluation, dir: &Path, force: bool) -> Result<()> {
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
    let result = write_into(eval, &partial);
    if let Err(e) = result {
        let _ = std::fs::remove_dir_all(&partial);
        return Err(e);
    }
    if dir.exists() {
        std::fs::remove_dir_all(dir).map_err(|e| io(dir, e))?;
    }
    std::fs::rename(&partial, dir).map_err(|e| io(dir, e))
}

fn write_into(eval: &Evaluation, dir: &Path) -> Result<()> {
    let json = serde_json::to_string_pretty(eval)
        .map_err(|e| Error::invalid("results.json", e.to_string()))?;
    write_atomic(&dir.join("results.json"), json.as_bytes())?;
    write_atomic(&dir.join("frames.csv"), frames_csv(eval).as_bytes())?;
    write_atomic(&dir.join("summary.csv"), summary_csv(eval).as_bytes())?;
    let front = write_charts(eval, dir)?;
    let images = write_images(eval, dir)?;
    write_atomic(
        &dir.join("report.md"),
        report_md(eval, &front, &images).as_bytes(),
    )
}

fn opt(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| format!("{v:.5}"))
}

/// One CSV field (RFC 4180): quoted, with its quotes doubled, when it holds a comma, a quote
/// or a line break (a variant label of several sweeps is `udlod tau_px=1,morph_range=0.5`).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn frames_csv(eval: &Evaluation) -> String {
    frames_csv_of(&eval.rows)
}

fn frames_csv_of(rows: &[FrameRow]) -> String {
    let mut csv = String::from(
        "variant,method,frame,gpu_ms,gpu_prepass_ms,gpu_terrain_ms,gpu_eval_ms,cpu_record_ms,triangles,tiles,err_px_mean,err_px_p99,err_px_p999,err_px_max,err_m_mean,err_m_p999,err_m_max,holes,cracks,silhouette_px,psnr_db,ssim,popping_p99_px,flip_mean,flip_p99,oracle_triangles,coarse_px_p999,coarse_share,level0_px_max\n",
    );
    for r in rows {
        let _ = writeln!(
            csv,
            "{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{},{},{:.5},{:.5},{:.5},{:.5},{:.4},{:.4},{:.4},{},{},{},{:.3},{:.5},{:.5},{},{},{},{},{},{}",
            csv_field(&r.variant),
            csv_field(&r.method),
            r.frame,
            r.gpu_ms,
            r.gpu_prepass_ms,
            r.gpu_terrain_ms,
            r.gpu_eval_ms,
            r.cpu_record_ms,
            r.triangles,
            optional(r.tiles.map(|v| v as f64), 0),
            r.error.pixels.mean,
            r.error.pixels.p99,
            r.error.pixels.p999,
            r.error.pixels.max,
            r.error.metres.mean,
            r.error.metres.p999,
            r.error.metres.max,
            r.holes,
            r.cracks,
            r.silhouette_px,
            r.psnr_db,
            r.ssim,
            r.popping_p99_px,
            opt(r.flip.map(|f| f.mean)),
            opt(r.flip.map(|f| f.p99)),
            optional(r.oracle_triangles.map(|v| v as f64), 0),
            opt(r.coarse.map(|c| c.p999_px)),
            opt(r.coarse.map(|c| c.share)),
            opt(r.coarse.map(|c| c.level0_max_px))
        );
    }
    csv
}

fn summary_csv(eval: &Evaluation) -> String {
    summary_csv_of(&eval.summaries)
}

fn summary_csv_of(summaries: &[RunSummary]) -> String {
    let mut sum = String::from(
        "variant,method,frames,gpu_ms_median,gpu_ms_p90,gpu_ms_p99,gpu_ms_max,triangles_median,tiles_median,err_px_mean,err_px_p99,err_px_p999,err_px_max,err_m_p999,holes,cracks,silhouette_px_max,psnr_db,ssim,flip_mean,flip_p99_mean,flip_frames,popping_px_median,popping_px_max,swimming_px_mean,swimming_px_p99,swimming_m_mean,oracle_triangles_median,oracle_ratio_median,budget_overflow_frames,coarse_px_p999,coarse_share,level0_px_max\n",
    );
    for s in summaries {
        let _ = writeln!(
            sum,
            "{},{},{},{:.3},{:.3},{:.3},{:.3},{:.0},{},{:.5},{:.5},{:.5},{:.5},{:.4},{},{},{},{:.3},{:.5},{},{},{},{:.5},{:.5},{:.5},{:.5},{:.4},{},{},{},{},{},{}",
            csv_field(&s.variant),
            csv_field(&s.method),
            s.frames,
            s.gpu_ms.median,
            s.gpu_ms.p90,
            s.gpu_ms.p99,
            s.gpu_ms.max,
            s.triangles_median,
            optional(s.tiles_median, 1),
            s.error.pixels.mean,
            s.error.pixels.p99,
            s.error.pixels.p999,
            s.error.pixels.max,
            s.error.metres.p999,
            s.holes_total,
            s.cracks_total,
            s.silhouette_px_max,
            s.psnr_db_mean,
            s.ssim_mean,
            opt(s.flip_mean),
            opt(s.flip_p99_mean),
            s.flip_frames,
            s.popping_px.median,
            s.popping_px.max,
            s.swimming_px.mean,
            s.swimming_px.p99,
            s.swimming_m.mean,
            optional(s.oracle_triangles_median, 0),
            optional(s.oracle_ratio_median, 3),
            s.budget_overflow_frames,
            opt(s.coarse.map(|c| c.p999_px)),
            opt(s.coarse.map(|c| c.share)),
            opt(s.coarse.map(|c| c.level0_max_px))
        );
    }
    sum
}

/// A sweep point's label: its parameter values (`pgm COLSxROWS` keeps its grid).
fn point_label(s: &RunSummary) -> String {
    if s.params.is_empty() {
        return String::new();
    }
    if s.method == "pgm" && s.params.iter().any(|(k, _)| k == "grid_scale") {
        return s.variant.trim_start_matches("pgm ").to_string();
    }
    s.params
        .iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join(",")
}

/// One series per method over its sweep (points in parameter order), labelled.
fn series_of(eval: &Evaluation, f: &dyn Fn(&RunSummary) -> (f64, f64)) -> Vec<Series> {
    let mut methods: Vec<&str> = eval.summaries.iter().map(|s| s.method.as_str()).collect();
    methods.dedup();
    methods
        .iter()
        .map(|m| {
            let mut runs: Vec<&RunSummary> =
                eval.summaries.iter().filter(|s| s.method == *m).collect();
            runs.sort_by(|a, b| {
                let key = |s: &RunSummary| s.params.first().map_or(0.0, |p| p.1);
                key(a).total_cmp(&key(b))
            });
            Series {
                name: m.to_string(),
                points: runs.iter().map(|s| f(s)).collect(),
                labels: runs.iter().map(|s| point_label(s)).collect(),
                markers: true,
                line: true,
            }
        })
        .collect()
}

/// The charts; returns the Pareto front (indices into the summaries).
fn write_charts(eval: &Evaluation, dir: &Path) -> Result<Vec<usize>> {
    let speed = |s: &RunSummary| (s.error.pixels.p999, s.gpu_ms.median);
    let time_vs_error: Vec<(f64, f64)> = eval.summaries.iter().map(speed).collect();
    let front = pareto_front(&time_vs_error);
    let mut highlight: Vec<(f64, f64)> = front.iter().map(|&i| time_vs_error[i]).collect();
    highlight.sort_by(|a, b| a.0.total_cmp(&b.0));
    Chart {
        title: format!(
            "GPU time vs error: {} ({}x{})",
            eval.scenario, eval.width, eval.height
        ),
        x_label: "screen-space error, 99.9th percentile (px)".into(),
        y_label: "GPU time per frame, prepass + terrain (ms, median)".into(),
        series: series_of(eval, &speed),
        highlight,
        y_from_zero: true,
    }
    .write(dir, "frame_time_vs_error")?;
    Chart {
        title: format!("Triangles vs error: {}", eval.scenario),
        x_label: "screen-space error, 99.9th percentile (px)".into(),
        y_label: "triangles per frame (median)".into(),
        series: series_of(eval, &|s| (s.error.pixels.p999, s.triangles_median)),
        y_from_zero: true,
        ..Default::default()
    }
    .write(dir, "triangles_vs_error")?;
    Chart {
        title: format!("Error over time: {}", eval.scenario),
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
                line: true,
                ..Default::default()
            })
            .collect(),
        ..Default::default()
    }
    .write(dir, "error_over_time")?;
    Ok(front)
}

/// Side-by-side images: reference | method | screen-space error | FLIP error map; encoded in
/// parallel on the rayon pool (each a 4 x frame-width PNG).
fn write_images(eval: &Evaluation, dir: &Path) -> Result<Vec<(String, u64, String)>> {
    use rayon::prelude::*;
    eval.images
        .par_iter()
        .map(|img| {
            let name = format!(
                "images/{}_f{:04}.png",
                img.variant.replace([' ', '=', ','], "_"),
                img.frame
            );
            write_png(&dir.join(&name), 4 * img.width, img.height, &panels(img))?;
            Ok((img.variant.clone(), img.frame, name))
        })
        .collect()
}

/// The four panels of one image frame side by side, RGBA8.
fn panels(img: &super::run::ImageFrame) -> Vec<u8> {
    let (w, h) = (img.width, img.height);
    let n = (w * h) as usize;
    let flip = img
        .flip
        .clone()
        .unwrap_or_else(|| super::flip::magma_rgba(&vec![0.0; n], w, h));
    let panels = 4u32;
    let mut out = vec![0u8; n * 4 * panels as usize];
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let src = i * 4;
            let e = img.error_px[i];
            let error = (e < EVAL_NO_ERROR_PX).then_some(e as f64);
            for (panel, px) in [
                (
                    0,
                    [
                        img.reference[src],
                        img.reference[src + 1],
                        img.reference[src + 2],
                    ],
                ),
                (
                    1,
                    [img.method[src], img.method[src + 1], img.method[src + 2]],
                ),
                (2, heat(error, 2.0)),
                (3, [flip[src], flip[src + 1], flip[src + 2]]),
            ] {
                let dst = ((y * panels * w + panel * w + x) * 4) as usize;
                out[dst..dst + 3].copy_from_slice(&px);
                out[dst + 3] = 255;
            }
        }
    }
    out
}

fn report_md(eval: &Evaluation, front: &[usize], images: &[(String, u64, String)]) -> String {
    let mut md = report_header(eval);
    report_summary(&mut md, eval, front);
    let _ = writeln!(
        md,
        "## Charts\n\n![GPU time vs error](frame_time_vs_error.png) ![triangles vs error](triangles_vs_error.png) ![error over time](error_over_time.png)\n\n(SVG versions beside them.)\n"
    );
    let _ = writeln!(
        md,
        "## Images\n\nReference | method | screen-space error (black 0 to yellow >= 2 px, grey: sky) | FLIP error map (magma: black 0 to white 1).\n"
    );
    for (variant, frame, link) in images {
        let _ = writeln!(
            md,
            "- {variant}, frame {frame}: ![{variant} {frame}]({link})"
        );
    }
    md
}

/// The report's title, the run's setup and the command that regenerates it.
fn report_header(eval: &Evaluation) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# Evaluation: {} on {}\n", eval.scenario, eval.dataset);
    let _ = writeln!(
        md,
        "- Device: {}\n- Resolution: {}x{}, {} view(s){}\n- Data set: {} (terrain: {})\n- Frames: {} ({} warm-up excluded from the summaries)\n- Speed: {}\n- Reference: {}\n- FLIP: {}\n- Evaluation wall time: {:.1} s\n",
        eval.device,
        eval.width,
        eval.height,
        eval.views,
        if eval.clipmap {
            ", heights through the clipmap"
        } else {
            ""
        },
        eval.dataset,
        eval.earth,
        eval.frames,
        eval.warmup,
        eval.timing,
        eval.reference,
        if eval.flip_every > 0 {
            format!(
                "every {} measured frame(s) and the image frames",
                eval.flip_every
            )
        } else {
            "the image frames only".into()
        },
        eval.wall_s,
    );
    let _ = writeln!(
        md,
        "Regenerate with:\n\n```sh\n{}\n```\n\nDefinitions of every metric: `docs/metrics.md`; how the evaluation works: `docs/eval.md`.\n",
        eval.command
    );
    md
}

/// The summary table, its warnings, the Pareto front and the cross-check's verdict.
fn report_summary(md: &mut String, eval: &Evaluation, front: &[usize]) {
    md.push_str(&super::table::markdown(
        super::table::SUMMARY_COLUMNS,
        &eval.summaries,
    ));
    for w in super::budget_warnings(&eval.summaries) {
        let _ = writeln!(md, "\n**Warning**: {w}");
    }
    let pareto: Vec<&str> = front
        .iter()
        .map(|&i| eval.summaries[i].variant.as_str())
        .collect();
    let _ = writeln!(
        md,
        "\nPareto front (GPU time vs 99.9th-percentile error): {}.\n",
        pareto.join(", ")
    );
    if let Some(check) = &eval.cross_check {
        let _ = writeln!(
            md,
            "Cross-check (GPU metrics against the CPU path on the same {} frames): {}.\n",
            check.frames,
            if check.problems.is_empty() {
                "equal within the tolerances".to_string()
            } else {
                format!(
                    "{} difference(s), first: {}",
                    check.problems.len(),
                    check.problems[0]
                )
            }
        );
    }
}

/// A CSV cell for an optional number: empty when absent.
fn optional(v: Option<f64>, decimals: usize) -> String {
    v.map(|v| format!("{v:.decimals$}")).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::metrics::{GeometricError, Summary};
    use crate::render::stats::Percentiles;

    /// The fields of one CSV line (RFC 4180: quoted fields, doubled quotes inside them).
    fn parse_line(line: &str) -> Vec<String> {
        let mut fields = vec![String::new()];
        let mut quoted = false;
        let mut chars = line.chars().peekable();
        while let Some(c) = chars.next() {
            match (c, quoted) {
                ('"', true) if chars.peek() == Some(&'"') => {
                    chars.next();
                    fields.last_mut().unwrap().push('"');
                }
                ('"', _) => quoted = !quoted,
                (',', false) => fields.push(String::new()),
                (c, _) => fields.last_mut().unwrap().push(c),
            }
        }
        fields
    }

    const LABEL: &str = "udlod tau_px=1,morph_range=0.5";

    fn row(variant: &str) -> FrameRow {
        FrameRow {
            variant: variant.into(),
            method: "udlod".into(),
            frame: 3,
            gpu_ms: 1.0,
            gpu_prepass_ms: 0.25,
            gpu_terrain_ms: 0.75,
            gpu_eval_ms: 2.0,
            cpu_record_ms: 0.1,
            triangles: 1000,
            tiles: Some(40),
            budget_overflow: 0,
            error: GeometricError::default(),
            holes: 0,
            cracks: 0,
            silhouette_px: 0,
            psnr_db: 40.0,
            ssim: 0.99,
            popping_p99_px: 0.1,
            flip: None,
            oracle_triangles: None,
            coarse: None,
        }
    }

    fn summary(variant: &str) -> RunSummary {
        RunSummary {
            variant: variant.into(),
            method: "udlod".into(),
            params: vec![("tau_px".into(), 1.0), ("morph_range".into(), 0.5)],
            frames: 4,
            gpu_ms: Percentiles::default(),
            gpu_prepass_ms_median: 0.0,
            gpu_terrain_ms_median: 0.0,
            gpu_eval_ms_median: 0.0,
            triangles_median: 0.0,
            tiles_median: Some(40.0),
            budget_overflow_frames: 0,
            error: GeometricError::default(),
            holes_total: 0,
            cracks_total: 0,
            silhouette_px_max: 0,
            psnr_db_mean: 40.0,
            ssim_mean: 0.99,
            flip_mean: None,
            flip_p99_mean: None,
            flip_frames: 0,
            popping_px: Summary::default(),
            swimming_m: Summary::default(),
            swimming_px: Summary::default(),
            oracle_triangles_median: None,
            oracle_ratio_median: None,
            coarse: None,
        }
    }

    /// Every line has the header's columns and the label comes back whole; the old writer's
    /// line (the label unquoted) has one column too many.
    fn check(csv: &str) {
        let mut lines = csv.lines();
        let header = parse_line(lines.next().unwrap());
        let mut n = 0;
        for line in lines {
            let fields = parse_line(line);
            assert_eq!(fields.len(), header.len(), "{line}");
            assert_eq!(fields[0], LABEL);
            // Negative control: what the writer wrote before quoting does not parse.
            let old = line.replace(&format!("\"{LABEL}\""), LABEL);
            assert_ne!(parse_line(&old).len(), header.len(), "{old}");
            n += 1;
        }
        assert!(n > 0);
    }

    #[test]
    fn variant_labels_with_commas_are_quoted_in_csv() {
        check(&frames_csv_of(&[row(LABEL), row(LABEL)]));
        check(&summary_csv_of(&[summary(LABEL)]));
        assert_eq!(csv_field("pgm 120x525"), "pgm 120x525");
        assert_eq!(csv_field("a \"b\",c"), "\"a \"\"b\"\",c\"");
    }
}

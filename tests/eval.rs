//! `vkterrain eval` end to end (validation on): a small run writes every output (results.json
//! with one row per variant and frame, CSVs, SVG+PNG charts, images, report.md) into a
//! directory that appears complete; bad sweeps and an existing directory are one-line errors
//! that leave nothing behind.

mod common;

use common::cli::{ci_config, run as vkterrain};

fn one_line_error(o: &std::process::Output, expected: &str) {
    common::cli::assert_one_line_error(o, &[expected]);
}

#[test]
fn eval_writes_results_charts_images_and_report() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("ev");
    let out_s = out.to_str().unwrap();
    let config = ci_config();
    let o = vkterrain(&[
        "eval",
        "--config",
        &config,
        "--methods",
        "brute,udlod,pgm",
        "--sweep",
        "tau_px=1,4",
        "--sweep",
        "grid_scale=0.25",
        "--frames",
        "8",
        "--warmup",
        "2",
        "--width",
        "96",
        "--height",
        "64",
        "--out",
        out_s,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "results.json",
        "frames.csv",
        "summary.csv",
        "report.md",
        "frame_time_vs_error.svg",
        "frame_time_vs_error.png",
        "triangles_vs_error.svg",
        "triangles_vs_error.png",
        "error_over_time.svg",
        "error_over_time.png",
        "images/udlod_tau_px_1_f0000.png",
        "images/pgm_60x263_f0007.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert!(!tmp.path().join("ev.partial").exists());
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let summaries = results["summaries"].as_array().unwrap();
    let names: Vec<&str> = summaries
        .iter()
        .map(|s| s["variant"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        ["brute", "udlod tau_px=1", "udlod tau_px=4", "pgm 60x263"]
    );
    assert_eq!(results["rows"].as_array().unwrap().len(), 4 * 8);
    let brute = &summaries[0];
    assert!(brute["error"]["pixels"]["p999"].as_f64().unwrap() < 0.01);
    let frames_csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    assert_eq!(frames_csv.lines().count(), 1 + 4 * 8);
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("| udlod tau_px=4 |") && report.contains("Pareto front"));

    // The same directory again without --force: refused, untouched.
    let before = std::fs::read(out.join("results.json")).unwrap();
    let o = vkterrain(&["eval", "--config", &config, "--frames", "2", "--out", out_s]);
    one_line_error(&o, "exists");
    assert_eq!(std::fs::read(out.join("results.json")).unwrap(), before);
}

#[test]
fn bad_sweeps_and_methods_are_one_line_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("ev");
    let out_s = out.to_str().unwrap();
    let config = ci_config();
    for (args, expected) in [
        (vec!["--sweep", "tau_px"], "no '='"),
        (vec!["--sweep", "tau_px=1,x"], "not a number"),
        (vec!["--sweep", "speed=1"], "speed"),
        (vec!["--methods", "brute", "--sweep", "tau_px=1"], "tau_px"),
        (vec!["--sweep", "tau_px=-1"], "tau_px"),
        (vec!["--methods", "magic"], "magic"),
        (vec!["--methods", "pgm", "--sweep", "grid_cols=1"], "grid"),
    ] {
        let mut a = vec!["eval", "--config", &config, "--frames", "2", "--out", out_s];
        a.extend(args);
        one_line_error(&vkterrain(&a), expected);
        assert!(!out.exists() && !tmp.path().join("ev.partial").exists());
    }
}

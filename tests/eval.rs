//! `vkterrain eval` end to end (validation on): a small run writes every output (results.json
//! with one row per variant and frame, CSVs, SVG+PNG charts with text, four-panel images with
//! the FLIP map, report.md with device, resolution, data set, frames and the command) into a
//! directory that appears complete; clipmap and multi-view frames are evaluated and
//! cross-checked against the CPU path; bad sweeps and an existing directory are one-line errors
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
    for what in [
        "- Device: ",
        "- Resolution: 96x64",
        "- Data set: procedural",
        "- Frames: 8 (2 warm-up",
        "vkterrain eval --config",
        "--sweep grid_scale=0.25",
    ] {
        assert!(report.contains(what), "report.md lacks {what:?}:\n{report}");
    }
    // FLIP on the image frames (0 and 7) and every 16th measured frame from the end of the
    // warm-up (2) of every variant; the reference's is 0.
    let rows = results["rows"].as_array().unwrap();
    let flips = |v: &str| {
        rows.iter()
            .filter(|r| r["variant"] == v && !r["flip"].is_null())
            .map(|r| r["flip"]["mean"].as_f64().unwrap())
            .collect::<Vec<_>>()
    };
    assert_eq!(flips("brute"), [0.0, 0.0, 0.0]);
    udlod_rows_count_tiles(rows, 8);
    assert!(summaries[1]["tiles_median"].as_f64().unwrap() > 0.0);
    let pgm = flips("pgm 60x263");
    assert!(pgm.len() == 3 && pgm.iter().all(|&f| f > 0.0), "{pgm:?}");
    // Side by side: reference | method | error | FLIP.
    let img = image::open(out.join("images/pgm_60x263_f0007.png")).unwrap();
    assert_eq!((img.width(), img.height()), (4 * 96, 64));
    let svg = std::fs::read_to_string(out.join("frame_time_vs_error.svg")).unwrap();
    assert!(svg.contains("screen-space error, 99.9th percentile") && svg.contains("tau_px=4"));

    // The same directory again without --force: refused, untouched.
    let before = std::fs::read(out.join("results.json")).unwrap();
    let o = vkterrain(&["eval", "--config", &config, "--frames", "2", "--out", out_s]);
    one_line_error(&o, "exists");
    assert_eq!(std::fs::read(out.join("results.json")).unwrap(), before);
}

/// Tiles (UDLOD's counter, grid 4; `tests/udlod.rs` checks it against the tile list), over
/// `rows` of two UDLOD variants of `frames` frames each: each drawn tile draws 2 to 32
/// triangles, and with quadrants collapsed or dropped some frame fewer than 32 a tile; brute
/// force has no tiles. Negative control, by hand: triangles / 32 (the bench's column until
/// 2026-12-07), rounded down, breaks the bound in frame 0.
fn udlod_rows_count_tiles(rows: &[serde_json::Value], frames: usize) {
    let (mut udlod_frames, mut below_full) = (0, 0);
    for r in rows {
        let (tiles, triangles) = (&r["tiles"], r["triangles"].as_u64().unwrap());
        if r["method"] == "udlod" {
            let t = tiles
                .as_u64()
                .unwrap_or_else(|| panic!("udlod row without tiles: {r}"));
            assert!(t > 0 && 2 * t <= triangles && triangles <= 32 * t, "{r}");
            udlod_frames += 1;
            below_full += (triangles < 32 * t) as usize;
        } else {
            assert!(tiles.is_null(), "{r}");
        }
    }
    assert!(
        udlod_frames == 2 * frames && below_full > 0,
        "{below_full} of {udlod_frames}"
    );
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

/// Everything the renderer can render is evaluable, and the GPU metrics equal the CPU path on
/// it: heights through the clipmap over a tile pyramid (the reference from the pyramid's level
/// 0), two views side by side, and the clipmap case anchored on the earth (measured on the
/// ellipsoid). `--cross-check` fails the run on any difference.
#[test]
fn clipmap_and_two_view_frames_are_evaluated_and_cross_checked() {
    let tmp = tempfile::tempdir().unwrap();
    let pyramid = common::procedural_pyramid("eval-clipmap", 257, 5, 32);
    let clipmap = tmp.path().join("clipmap.toml");
    std::fs::write(
        &clipmap,
        format!(
            "[render]\nwidth = 96\nheight = 64\n\n[dataset]\nkind = \"tiles\"\npath = {:?}\n\n[method]\nname = \"udlod\"\n\n[clipmap]\nenabled = true\natlas_capacity = 48\nnode_count = 4\n",
            pyramid.display().to_string()
        ),
    )
    .unwrap();
    let views = tmp.path().join("views.toml");
    std::fs::write(
        &views,
        format!(
            "[render]\nwidth = 160\nheight = 48\n\n[[render.extra_views]]\nyaw_deg = 180.0\n\n[dataset]\nkind = \"procedural\"\nsize = 257\nspacing = 60.0\n\n[method]\nname = \"brute\"\n\n[scenario]\npath = {:?}\n",
            format!("{}/config/scenarios/default.toml", env!("CARGO_MANIFEST_DIR"))
        ),
    )
    .unwrap();
    // The clipmap case again with the pyramid anchored on the earth: drawn and measured on the
    // ellipsoid (the GPU inverting the lattice per pixel and per swim point, the CPU by
    // Lattice::sample_at).
    let earth = tmp.path().join("earth.toml");
    let text = std::fs::read_to_string(&clipmap).unwrap().replace(
        "[method]",
        "anchor = { lat_deg = 60.0, lon_deg = 20.0 }\n\n[method]",
    );
    std::fs::write(&earth, text).unwrap();
    for (i, (config, methods, expect_views, expect_clipmap, expect_earth)) in [
        (&clipmap, "brute,udlod", 1, true, "flat"),
        (&views, "brute,udlod,pgm", 2, false, "flat"),
        (&earth, "brute,udlod", 1, true, "ellipsoid"),
    ]
    .into_iter()
    .enumerate()
    {
        let out = tmp.path().join(format!("ev{i}"));
        let o = vkterrain(&[
            "eval",
            "--config",
            config.to_str().unwrap(),
            "--methods",
            methods,
            "--frames",
            "9",
            "--warmup",
            "1",
            "--cross-check",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let results: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap())
                .unwrap();
        assert_eq!(results["views"], expect_views);
        assert_eq!(results["clipmap"], expect_clipmap);
        assert_eq!(results["earth"], expect_earth);
        let runs = methods.split(',').count() as u64;
        let check = &results["cross_check"];
        assert_eq!(check["frames"].as_u64(), Some(9 * runs), "{check}");
        assert_eq!(check["problems"].as_array().map(Vec::len), Some(0));
        let summaries = results["summaries"].as_array().unwrap();
        assert_eq!(summaries.len() as u64, runs);
        // Every run measured terrain pixels.
        for s in summaries {
            assert!(
                s["error"]["pixels"]["count"].as_u64().unwrap() > 1000,
                "{s}"
            );
        }
        let report = std::fs::read_to_string(out.join("report.md")).unwrap();
        assert!(report.contains("equal within the tolerances"), "{report}");
    }
    let _ = std::fs::remove_dir_all(pyramid.parent().unwrap());
}

/// A UDLOD variant whose tile budget is too small for its frames: `eval` counts the frames
/// whose budget overflowed (summary.csv `budget_overflow_frames`), warns on stderr and in the
/// report; the same run with the default budget has none (the control).
#[test]
fn an_overflowing_tile_budget_is_reported() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("ev");
    let config = ci_config();
    let o = vkterrain(&[
        "eval",
        "--config",
        &config,
        "--methods",
        "udlod",
        "--sweep",
        "max_tiles=16,16384",
        "--frames",
        "4",
        "--warmup",
        "1",
        "--width",
        "96",
        "--height",
        "64",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = header
        .iter()
        .position(|h| *h == "budget_overflow_frames")
        .expect("budget_overflow_frames column");
    let overflow_of = |variant: &str| -> usize {
        let line = csv
            .lines()
            .find(|l| l.starts_with(variant))
            .unwrap_or_else(|| panic!("{variant} in {csv}"));
        line.split(',').nth(col).unwrap().parse().unwrap()
    };
    assert_eq!(overflow_of("udlod max_tiles=16,"), 3, "{csv}");
    assert_eq!(overflow_of("udlod max_tiles=16384,"), 0, "{csv}");
    assert!(
        stderr.contains("warning: udlod max_tiles=16:") && !stderr.contains("max_tiles=16384:"),
        "{stderr}"
    );
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        report.contains("**Warning**: udlod max_tiles=16:"),
        "{report}"
    );
}

/// The coarse pixels (docs/eval.md, "Coarse pixels"): UDLOD reports the share of the pixels it
/// drew with tiles coarser than level 0 and their 99.9th percentile; brute force draws no
/// tiles and reports none. Without morphing a level-0 tile is the data itself, so the pixels
/// over one measure no error but f32 noise (brute force's scale, < 0.05 px), while the coarse
/// ones at tau 1.5 measure tenths of a pixel: a lookup that read the tiles wrongly (x for y, or
/// another tile size) puts coarse pixels among the level-0 ones (negative control, by hand:
/// `level_at` with x and y swapped fails it). Tau 1.5, not larger: at 192x108 no level-0 tile
/// is drawn beyond it since morph zones start where the children allow (docs/udlod-rounds.md, "The
/// zone's start"; tau 2 and 4 draw only coarse pixels there).
#[test]
fn coarse_pixels_are_those_over_tiles_coarser_than_level_0() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("ev");
    let scenario = common::cli::shipped_config("scenarios/default.toml");
    let ci = std::fs::read_to_string(ci_config()).unwrap();
    let config = tmp.path().join("unmorphed.toml");
    std::fs::write(
        &config,
        ci.replace("name = \"brute\"", "name = \"udlod\"\nmorph = false")
            .replace(
                "path = \"scenarios/default.toml\"",
                &format!("path = {:?}", scenario.display().to_string()),
            ),
    )
    .unwrap();
    let o = vkterrain(&[
        "eval",
        "--config",
        config.to_str().unwrap(),
        "--methods",
        "brute,udlod",
        "--sweep",
        "tau_px=0.5,1.5",
        "--frames",
        "6",
        "--warmup",
        "1",
        "--width",
        "192",
        "--height",
        "108",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    let summary = |variant: &str| {
        json["summaries"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["variant"] == variant)
            .unwrap_or_else(|| panic!("{variant} in {json}"))
            .clone()
    };
    assert!(summary("brute")["coarse"].is_null());
    let coarse = |variant: &str| {
        let s = summary(variant);
        let c = &s["coarse"];
        let f = |k: &str| c[k].as_f64().unwrap_or_else(|| panic!("{k} in {s}"));
        (f("share"), f("p999_px"), f("level0_max_px"), s)
    };
    let (fine_share, _, fine_level0, s) = coarse("udlod tau_px=0.5");
    let (share, p999, level0, s_coarse) = coarse("udlod tau_px=1.5");
    assert!(
        0.0 < fine_share && fine_share < share && share < 1.0,
        "{s}\n{s_coarse}"
    );
    assert!(p999 > 0.25, "{s_coarse}");
    assert!(fine_level0 < 0.05 && level0 < 0.05, "{s}\n{s_coarse}");
    let frames = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    let header: Vec<&str> = frames.lines().next().unwrap().split(',').collect();
    assert!(header.ends_with(&["coarse_px_p999", "coarse_share", "level0_px_max"]));
}

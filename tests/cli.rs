//! The `vkterrain` binary end to end: the main job works, and bad input gets a one-line error
//! naming the problem, exit status 1, no panic, and no output directory left behind.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

use common::cli::{ci_config, run as vkterrain};

/// Runs a command that must fail; returns its one error line.
fn fails(args: &[&str], out: &Path, expected: &[&str]) -> String {
    let line = common::cli::assert_one_line_error(&vkterrain(args), expected);
    assert!(!out.exists(), "{args:?} left {} behind", out.display());
    line
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn render_writes_pngs_and_summary() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let o = vkterrain(&[
        "render",
        "--config",
        &ci_config(),
        "--frames",
        "3",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        stdout.contains("frame time:") && stdout.contains("triangles/frame: 524288"),
        "{stdout}"
    );
    for f in ["frame_00000.png", "frame_00002.png", "summary.json"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let png = image::open(out.join("frame_00002.png")).unwrap();
    assert_eq!((png.width(), png.height()), (640, 360));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["per_frame"].as_array().unwrap().len(), 3);
    // No temporary files remain.
    let names: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 3, "{names:?}");
}

#[test]
fn info_names_the_device() {
    let o = vkterrain(&["info"]);
    assert!(
        o.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("device:") && stdout.contains("timeline semaphores"),
        "{stdout}"
    );
}

#[test]
fn missing_config_file() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let missing = tmp.path().join("nope.toml");
    fails(
        &[
            "render",
            "--config",
            missing.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &out,
        &["nope.toml"],
    );
}

#[test]
fn invalid_config_files() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let cases = [
        (
            "syntax.toml",
            "[render]\nwidth = = 3\n",
            vec!["syntax.toml:2"],
        ),
        (
            "unknown.toml",
            "[render]\nwidht = 640\n",
            vec!["unknown.toml", "widht"],
        ),
        (
            "type.toml",
            "[render]\nwidth = \"wide\"\n",
            vec!["type.toml"],
        ),
        (
            "zero.toml",
            "[render]\nwidth = 0\n",
            vec!["zero.toml", "resolution"],
        ),
        ("method.toml", "[method]\nname = \"magic\"\n", vec!["magic"]),
        (
            // A data set path without its kind must not render procedural terrain instead.
            "no_kind.toml",
            "[dataset]\npath = \"heights.png\"\n",
            vec!["no_kind.toml", "kind"],
        ),
        (
            "kind_key.toml",
            "[dataset]\nkind = \"procedural\"\npath = \"heights.png\"\n",
            vec!["kind_key.toml", "path"],
        ),
        (
            "method_key.toml",
            "[method]\nname = \"brute\"\ntau_px = 2.0\n",
            vec!["method_key.toml", "tau_px"],
        ),
        (
            "old_lod.toml",
            "[lod]\ntau_px = 2.0\n",
            vec!["old_lod.toml", "lod"],
        ),
        (
            "clipmap_kind.toml",
            "[clipmap]\nenabled = true\n",
            vec!["clipmap", "tiles"],
        ),
        (
            // Live XYZ tiles are read node by node: only through the clipmap.
            "xyz_no_clipmap.toml",
            "[dataset]\nkind = \"xyz\"\nsource = \"tiles\"\nbbox = [1.0, 42.0, 2.0, 43.0]\nzoom = 9\n[clipmap]\nenabled = false\n",
            vec!["xyz", "clipmap"],
        ),
        (
            "xyz_bbox.toml",
            "[dataset]\nkind = \"xyz\"\nsource = \"tiles\"\nbbox = [1.0, 89.0, 2.0, 90.0]\nzoom = 9\n",
            vec!["bbox", "85.05"],
        ),
        (
            "xyz_key.toml",
            "[dataset]\nkind = \"xyz\"\nsource = \"tiles\"\nzom = 9\n",
            vec!["xyz_key.toml", "zom"],
        ),
        (
            "clipmap_nodes.toml",
            "[clipmap]\nnode_count = 7\n",
            vec!["node_count 7"],
        ),
        (
            "views_many.toml",
            "[render]\nextra_views = [{}, {}, {}, {}]\n",
            vec!["extra_views", "at most 4 views"],
        ),
        (
            "views_nan.toml",
            "[[render.extra_views]]\noffset_m = [0.0, nan, 0.0]\n",
            vec!["extra_views", "finite"],
        ),
        (
            "views_pitch.toml",
            "[[render.extra_views]]\npitch_deg = -120.0\n",
            vec!["extra_views", "pitch -120"],
        ),
        (
            "views_key.toml",
            "[[render.extra_views]]\nyaw = 3.0\n",
            vec!["views_key.toml", "yaw"],
        ),
    ];
    for (name, text, expected) in cases {
        let path = write(tmp.path(), name, text);
        fails(
            &[
                "render",
                "--config",
                path.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ],
            &out,
            &expected,
        );
    }
}

#[test]
fn absurd_resolutions_and_counts() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let o = out.to_str().unwrap();
    let c = ci_config();
    fails(
        &["render", "--config", &c, "--out", o, "--width", "0"],
        &out,
        &["resolution"],
    );
    fails(
        &["render", "--config", &c, "--out", o, "--height", "1000000"],
        &out,
        &["resolution"],
    );
    fails(
        &["render", "--config", &c, "--out", o, "--frames", "0"],
        &out,
        &["frames"],
    );
    fails(
        &[
            "render",
            "--config",
            &c,
            "--out",
            o,
            "--frames-in-flight",
            "9",
        ],
        &out,
        &["frames_in_flight"],
    );
}

#[test]
fn unknown_device_override() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let o = out.to_str().unwrap();
    fails(
        &[
            "render",
            "--config",
            &ci_config(),
            "--out",
            o,
            "--device",
            "no-such-gpu",
        ],
        &out,
        &["no-such-gpu"],
    );
    fails(
        &[
            "render",
            "--config",
            &ci_config(),
            "--out",
            o,
            "--device",
            "7",
        ],
        &out,
        &["7"],
    );
    let info = vkterrain(&["info", "--device", "no-such-gpu"]);
    assert_eq!(info.status.code(), Some(1));
}

#[test]
fn nan_and_absurd_camera_values_in_scenarios() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let base = "name = \"bad\"\nfps = 30.0\nframes = 2\nvfov_deg = VFOV\nnear = 1.0\nfar = 1000.0\n\
                [[keyframe]]\nt = 0.0\nposition = [0.0, 0.0, 500.0]\nyaw = 0.0\npitch = PITCH\n";
    let cases = [
        (
            "nan_pitch.toml",
            base.replace("VFOV", "60.0").replace("PITCH", "nan"),
            vec!["nan_pitch.toml", "pitch"],
        ),
        (
            "inf_pitch.toml",
            base.replace("VFOV", "60.0").replace("PITCH", "inf"),
            vec!["pitch"],
        ),
        (
            "fov.toml",
            base.replace("VFOV", "0.0").replace("PITCH", "-10.0"),
            vec!["FOV"],
        ),
        (
            "fov_nan.toml",
            base.replace("VFOV", "nan").replace("PITCH", "-10.0"),
            vec!["FOV"],
        ),
    ];
    for (name, text, expected) in cases {
        let path = write(tmp.path(), name, &text);
        fails(
            &[
                "render",
                "--config",
                &ci_config(),
                "--scenario",
                path.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ],
            &out,
            &expected,
        );
    }
}

#[test]
fn no_vulkan_driver_names_the_package() {
    let o = Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .arg("info")
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .env_remove("VKTERRAIN_VALIDATION")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("mesa-vulkan-drivers"), "{stderr}");
}

/// `render --frames 4` that must succeed: its stdout and `summary.json`.
fn render_4_frames(config: &Path, out: &Path) -> (String, serde_json::Value) {
    let o = vkterrain(&[
        "render",
        "--config",
        config.to_str().unwrap(),
        "--frames",
        "4",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    (String::from_utf8_lossy(&o.stdout).into_owned(), summary)
}

#[test]
fn render_through_the_clipmap_reports_streaming() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("ds");
    let o = vkterrain(&[
        "preprocess",
        "--procedural",
        "--size",
        "257",
        "--node-size",
        "32",
        "--out",
        data.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let config = write(
        tmp.path(),
        "clip.toml",
        &format!(
            "[render]\nwidth = 96\nheight = 64\n[dataset]\nkind = \"tiles\"\npath = {:?}\n\
             [clipmap]\nenabled = true\natlas_capacity = 40\nnode_count = 4\n",
            data.display().to_string()
        ),
    );
    let (stdout, summary) = render_4_frames(&config, &tmp.path().join("out"));
    assert!(stdout.contains("clipmap:"), "{stdout}");
    let c = &summary["clipmap"];
    // 40 layers of 36² texels: height (4 B) + normal and albedo (4 B each) with mips 36, 18,
    // 9, 4.
    let mips = 36 * 36 + 18 * 18 + 9 * 9 + 4 * 4;
    assert_eq!(c["atlas_bytes"], 40 * (36 * 36 * 4 + mips * 8));
    assert!(c["resident_nodes"].as_u64().unwrap() >= 1);
    assert!(c["resident_nodes"].as_u64().unwrap() <= 40);

    // Two cameras in one frame through the same atlas: a rear view 200 m higher.
    let two = write(
        tmp.path(),
        "clip2.toml",
        &format!(
            "{}[[render.extra_views]]\noffset_m = [0.0, 0.0, 200.0]\nyaw_deg = 180.0\n",
            std::fs::read_to_string(&config).unwrap()
        ),
    );
    let out2 = tmp.path().join("out2");
    let (stdout2, summary2) = render_4_frames(&two, &out2);
    assert!(stdout2.contains("views:           2 cameras"), "{stdout2}");
    assert_eq!(summary2["views"], 2);
    assert_eq!(summary2["width"], 96);
    // Same atlas budget for two views as for one.
    assert_eq!(summary2["clipmap"]["atlas_bytes"], c["atlas_bytes"]);
    assert!(summary2["clipmap"]["resident_nodes"].as_u64().unwrap() <= 40);
    // The two halves show different cameras.
    let png = image::open(out2.join("frame_00003.png"))
        .unwrap()
        .to_rgba8();
    assert_eq!(png.dimensions(), (96, 64));
    let half = |x0: u32| -> Vec<u8> {
        let mut v = Vec::new();
        for y in 0..64 {
            for x in x0..x0 + 48 {
                v.extend_from_slice(&png.get_pixel(x, y).0);
            }
        }
        v
    };
    assert_ne!(half(0), half(48));

    // eval measures every view of a clipmap frame (tests/eval.rs cross-checks that case).
    let out3 = tmp.path().join("out3");
    let o = vkterrain(&[
        "eval",
        "--config",
        two.to_str().unwrap(),
        "--frames",
        "3",
        "--out",
        out3.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let results: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out3.join("results.json")).unwrap()).unwrap();
    assert_eq!(
        (results["views"].as_u64(), results["clipmap"].as_bool()),
        (Some(2), Some(true))
    );
    assert!(stdout.contains("peak RSS"), "{stdout}");
    assert!(summary["peak_rss_bytes"].as_u64().unwrap() > 0);
    assert!(summary2["peak_rss_bytes"].as_u64().unwrap() > 0);
    // PGM needs the whole height map, which the clipmap path never loads: one line, no output.
    let out4 = tmp.path().join("out4");
    fails(
        &[
            "render",
            "--config",
            config.to_str().unwrap(),
            "--method",
            "pgm",
            "--out",
            out4.to_str().unwrap(),
        ],
        &out4,
        &["pgm", "clipmap"],
    );
}

/// `cargo run` (the README's `make run`, the Makefile's data targets) must run the product:
/// with the tests' helper binary beside it, the manifest names it as `default-run`, else
/// cargo refuses to choose ("could not determine which binary to run"; how `make run` failed
/// until issue 18's ninth round). Negative control: without the key the test fails.
#[test]
fn cargo_run_runs_the_product() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml");
    let manifest: toml::Table = std::fs::read_to_string(&path).unwrap().parse().unwrap();
    let bins: Vec<&str> = manifest["bin"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["name"].as_str().unwrap())
        .collect();
    assert!(bins.contains(&"vkterrain"), "{bins:?}");
    if bins.len() > 1 {
        assert_eq!(
            manifest["package"]
                .get("default-run")
                .and_then(|v| v.as_str()),
            Some("vkterrain"),
            "{} binaries {bins:?} and no default-run",
            bins.len()
        );
    }
}

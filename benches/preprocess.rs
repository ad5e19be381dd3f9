//! Preprocessing throughput and peak memory (a benchmark, not a test):
//! `cargo bench --bench preprocess` (release). Each case runs in a child process so its peak
//! resident set (VmHWM) is its own. Set `VKT_BENCH_CASES=puget,srtm1,procedural` to pick cases
//! and `VKT_BENCH_PROCEDURAL_SIZE` to change the procedural size (default 16384).

use std::path::{Path, PathBuf};
use std::time::Instant;

use vkterrain::dataset::preprocess::{self, Input, NoProgress, Options};
use vkterrain::dataset::procedural::ProceduralParams;

fn vm_hwm_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|v| v.parse().ok()))
        })
        .unwrap_or(0)
}

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
}

fn run_case(case: &str) {
    let out = std::env::temp_dir().join(format!("vkt-bench-{}-{case}", std::process::id()));
    let d = data();
    let size: u32 = std::env::var("VKT_BENCH_PROCEDURAL_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(16384);
    let (opts, source_desc, source_bytes) = match case {
        "puget" => {
            let opts = Options {
                input: Input::Files(vec![d.join("puget_sound/ps_height_1k.png")]),
                albedo: Some(d.join("puget_sound/ps_texture_1k.png")),
                spacing: Some(160.0),
                vertical_scale: Some(0.1),
                ..Default::default()
            };
            // Decoded source: 1025^2 x 2 B heights + 1024^2 x 3 B imagery.
            (
                opts,
                "Puget Sound 1k heights + texture",
                1025 * 1025 * 2 + 1024 * 1024 * 3,
            )
        }
        "srtm1" => (
            Options {
                input: Input::Files(vec![d.join("srtm/N48W125.hgt.zip")]),
                ..Default::default()
            },
            "SRTM1 N48W125 3601^2 (50% void)",
            3601 * 3601 * 2,
        ),
        "procedural" => (
            Options {
                input: Input::Procedural(ProceduralParams {
                    size,
                    seed: 1,
                    ..Default::default()
                }),
                ..Default::default()
            },
            "procedural (f32 output samples)",
            size as u64 * size as u64 * 4,
        ),
        other => panic!("unknown case {other}"),
    };
    let opts = Options {
        out: out.clone(),
        force: true,
        ..opts
    };
    let before = vm_hwm_kib();
    let t = Instant::now();
    let s = preprocess::run(&opts, &mut NoProgress).expect("preprocess");
    let secs = t.elapsed().as_secs_f64();
    let hwm = vm_hwm_kib();
    println!(
        "{case:<11} {:>6}x{:<6} {:>7.2} s {:>8.1} source MB/s (decoded {:.1} MB: {source_desc}) {:>8.1} MiB output {:>4} nodes {:>2} levels peak RSS {:>7.1} MiB (before run {:.1} MiB)",
        s.width,
        s.height,
        secs,
        source_bytes as f64 / 1e6 / secs,
        source_bytes as f64 / 1e6,
        s.bytes as f64 / 1048576.0,
        s.nodes,
        s.levels,
        hwm as f64 / 1024.0,
        before as f64 / 1024.0,
    );
    std::fs::remove_dir_all(&out).ok();
}

fn main() {
    if let Ok(case) = std::env::var("VKT_BENCH_CASE") {
        run_case(&case);
        return;
    }
    if !data().is_dir() {
        eprintln!(
            "note: {} absent; only the procedural case runs",
            data().display()
        );
    }
    let cases =
        std::env::var("VKT_BENCH_CASES").unwrap_or_else(|_| "puget,srtm1,procedural".into());
    let exe = std::env::current_exe().expect("bench executable");
    for case in cases.split(',') {
        if case != "procedural" && !data().is_dir() {
            continue;
        }
        let status = std::process::Command::new(&exe)
            .env("VKT_BENCH_CASE", case)
            .status()
            .expect("child");
        assert!(status.success(), "case {case} failed");
    }
}

//! Preprocessing throughput and peak memory (a benchmark, not a test):
//! `cargo bench --bench preprocess` (release). Every case runs in a child process so its peak
//! resident set (VmHWM) is its own, once per thread count.
//!
//! - `VKT_BENCH_CASES`: comma-separated, default
//!   `puget,pyrenees,franconia,srtm1,utm,procedural` (the real ones need `../shared/data` or
//!   `$VKTERRAIN_SHARED_DATA`; without it only `procedural` runs).
//! - `VKT_BENCH_PROCEDURAL_SIZES`: default `4097,16385` (add 65537 for the large run).
//! - `VKT_BENCH_THREADS`: default `1,all`.
//! - `VKT_BENCH_OUT`: where data sets are written (default the temp dir); `VKT_BENCH_KEEP=1`
//!   keeps the procedural ones of the last thread count as `<out>/p<size>` (for the start-up
//!   benchmark).

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
    std::env::var_os("VKTERRAIN_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data"))
}

fn out_root() -> PathBuf {
    std::env::var_os("VKT_BENCH_OUT")
        .map(PathBuf::from)
        .unwrap_or_else(std::env::temp_dir)
}

/// Options, description and source bytes (the compressed input files, or for procedural the
/// f32 samples it generates) of a case.
fn case(name: &str) -> (Options, String, u64) {
    let d = data();
    let files = |p: &[&str]| -> (Input, u64) {
        let paths: Vec<PathBuf> = p.iter().map(|f| d.join(f)).collect();
        let bytes = paths
            .iter()
            .map(|p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0))
            .sum();
        (Input::Files(paths), bytes)
    };
    let (input, desc, bytes, extra): (Input, &str, u64, fn(&mut Options)) = match name {
        "puget" => {
            let (i, b) = files(&["puget_sound/ps_height_1k.png"]);
            (i, "Puget Sound 1k PNG + texture", b, |o| {
                o.albedo = Some(data().join("puget_sound/ps_texture_1k.png"));
                o.spacing = Some(160.0);
                o.vertical_scale = Some(0.1);
            })
        }
        "pyrenees" => {
            let (i, b) = files(&["srtm/N41E001.hgt.zip", "srtm/N42E001.hgt.zip"]);
            (i, "SRTM3 pair N41E001+N42E001 (zip)", b, |_| {})
        }
        "franconia" => {
            let (i, b) = files(&["srtm/N49E011.hgt.zip", "srtm/N50E011.hgt.zip"]);
            (i, "SRTM3 pair N49E011+N50E011 (zip)", b, |_| {})
        }
        "srtm1" => {
            let (i, b) = files(&["srtm/N48W125.hgt.zip"]);
            (i, "SRTM1 N48W125 (zip, 50% void)", b, |o| {
                o.center_size = 512
            })
        }
        "utm" => {
            let (i, b) = files(&["geotiff/srtm_bigtujunga30m_utm11.tif"]);
            (i, "GeoTIFF UTM 11N int16", b, |_| {})
        }
        p if p.starts_with("procedural") => {
            let size: u32 = p.trim_start_matches("procedural").parse().expect("size");
            (
                Input::Procedural(ProceduralParams {
                    size,
                    seed: 1,
                    ..Default::default()
                }),
                "procedural (f32 samples generated)",
                size as u64 * size as u64 * 4,
                |_| {},
            )
        }
        other => panic!("unknown case {other}"),
    };
    let mut opts = Options {
        input,
        force: true,
        ..Default::default()
    };
    extra(&mut opts);
    (opts, desc.to_string(), bytes)
}

fn run_case(name: &str, threads: usize, keep: bool) {
    let out = if keep {
        out_root().join(format!("p{}", name.trim_start_matches("procedural")))
    } else {
        out_root().join(format!("vkt-bench-{}-{name}-{threads}", std::process::id()))
    };
    let (opts, desc, source_bytes) = case(name);
    let opts = Options {
        out: out.clone(),
        ..opts
    };
    let t = Instant::now();
    let s = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("pool")
        .install(|| preprocess::run(&opts, &NoProgress))
        .expect("preprocess");
    let secs = t.elapsed().as_secs_f64();
    let hwm = vm_hwm_kib();
    println!(
        "| {name:<17} | {:>6}x{:<6} | {threads:>3} | {secs:>8.2} | {:>9.1} | {:>9.2} | {:>9.1} | {:>7.1} | {desc} |",
        s.width,
        s.height,
        source_bytes as f64 / 1e6 / secs,
        (s.width * s.height) as f64 / 1e6 / secs / threads as f64,
        s.bytes as f64 / 1048576.0,
        hwm as f64 / 1024.0,
    );
    if !keep {
        std::fs::remove_dir_all(&out).ok();
    }
}

fn main() {
    if let (Ok(name), Ok(t)) = (
        std::env::var("VKT_BENCH_CASE"),
        std::env::var("VKT_BENCH_CASE_THREADS"),
    ) {
        let keep = std::env::var("VKT_BENCH_CASE_KEEP").is_ok();
        run_case(&name, t.parse().expect("threads"), keep);
        return;
    }
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads: Vec<usize> = std::env::var("VKT_BENCH_THREADS")
        .unwrap_or_else(|_| "1,all".into())
        .split(',')
        .map(|t| {
            if t == "all" {
                all
            } else {
                t.parse().expect("thread count")
            }
        })
        .collect();
    let sizes = std::env::var("VKT_BENCH_PROCEDURAL_SIZES").unwrap_or_else(|_| "4097,16385".into());
    let cases = std::env::var("VKT_BENCH_CASES")
        .unwrap_or_else(|_| "puget,pyrenees,franconia,srtm1,utm,procedural".into());
    let have_data = data().is_dir();
    if !have_data {
        eprintln!(
            "note: {} absent; only the procedural cases run",
            data().display()
        );
    }
    let keep = std::env::var("VKT_BENCH_KEEP").is_ok();
    let exe = std::env::current_exe().expect("bench executable");
    println!(
        "preprocess on {} ({all} hardware threads); source MB/s: compressed input bytes (procedural: f32 samples generated) per second; Msamples/s/thread: output samples per second per thread",
        std::env::consts::ARCH
    );
    println!(
        "| case              | samples       | thr | seconds  | source MB/s | Msamples/s/thr | output MiB | peak RSS MiB | source |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for c in cases.split(',') {
        let names: Vec<String> = if c == "procedural" {
            sizes.split(',').map(|s| format!("procedural{s}")).collect()
        } else if have_data {
            vec![c.to_string()]
        } else {
            Vec::new()
        };
        for name in names {
            for (k, &t) in threads.iter().enumerate() {
                let mut cmd = std::process::Command::new(&exe);
                cmd.env("VKT_BENCH_CASE", &name)
                    .env("VKT_BENCH_CASE_THREADS", t.to_string());
                if keep && name.starts_with("procedural") && k + 1 == threads.len() {
                    cmd.env("VKT_BENCH_CASE_KEEP", "1");
                }
                let status = cmd.status().expect("child");
                assert!(status.success(), "case {name} with {t} threads failed");
            }
        }
    }
}

//! Fuzzing the readers that remain vkterrain's own (a benchmark-style target, not run in CI:
//! `cargo bench --bench fuzz_readers`): the manifest parser and checker, level-file headers
//! and node records, stored tile statistics, and the XYZ tile PNG decoding path. Each case
//! mutates a valid input (bit flips, byte runs, truncation, extension, field rewrites with
//! hostile values) and asserts the reader returns a value or a one-line error: no panic, no
//! allocation beyond its limits (peak RSS is checked at the end), and accepted values keep
//! their invariants.
//!
//! `VKT_FUZZ_CASES` (default 1000000, split over the four targets), `VKT_FUZZ_SEED`.

use std::panic::AssertUnwindSafe;
use std::time::Instant;

use vkterrain::dataset::manifest::Manifest;
use vkterrain::dataset::preprocess::{self, Input, NoProgress, Options};
use vkterrain::dataset::procedural::ProceduralParams;
use vkterrain::dataset::pyramid::{LEVEL_HEADER, level_header, parse_record};
use vkterrain::dataset::stats::TileStats;
use vkterrain::dataset::tiles::Dataset;
use vkterrain::dataset::xyz::{Encoding, decode_tile};

/// xorshift64*: deterministic, no dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// A mutated copy of `base`.
fn mutate(rng: &mut Rng, base: &[u8]) -> Vec<u8> {
    let mut v = base.to_vec();
    for _ in 0..1 + rng.below(4) {
        match rng.below(6) {
            0 if !v.is_empty() => {
                let i = rng.below(v.len());
                v[i] ^= 1 << rng.below(8);
            }
            1 if !v.is_empty() => {
                let i = rng.below(v.len());
                let n = (1 + rng.below(8)).min(v.len() - i);
                for b in &mut v[i..i + n] {
                    *b = rng.next() as u8;
                }
            }
            2 => {
                let n = rng.below(v.len() + 1);
                v.truncate(n);
            }
            3 => {
                let n = rng.below(64);
                v.extend((0..n).map(|_| rng.next() as u8));
            }
            4 if v.len() >= 4 => {
                // An aligned 32-bit word set to a hostile value.
                let i = rng.below(v.len() / 4) * 4;
                let w: u32 = [0, 1, u32::MAX, 0x7fc0_0000, 0xff80_0000, 0x8000_0000][rng.below(6)];
                v[i..i + 4].copy_from_slice(&w.to_le_bytes());
            }
            _ if !v.is_empty() => {
                let i = rng.below(v.len());
                v[i] = [0u8, 0xff, b'-', b'9', b'e', b'"', b'.', b'/'][rng.below(8)];
            }
            _ => {}
        }
    }
    v
}

/// Hostile values for manifest fields.
fn hostile_json(rng: &mut Rng) -> serde_json::Value {
    use serde_json::json;
    match rng.below(12) {
        0 => json!(-1),
        1 => json!(0),
        2 => json!(u64::MAX),
        3 => json!(1e308),
        4 => json!(-1e-300),
        5 => json!("../../etc/passwd"),
        6 => json!("/dev/zero"),
        7 => json!([]),
        8 => json!([1e300, -1e300]),
        9 => json!(null),
        10 => json!(4294967295u64),
        _ => json!({}),
    }
}

fn rewrite(rng: &mut Rng, v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Object(m) if !m.is_empty() => {
            let k = m.keys().nth(rng.below(m.len())).expect("key").clone();
            if rng.below(3) == 0 {
                m.insert(k, hostile_json(rng));
            } else if rng.below(5) == 0 {
                m.remove(&k);
            } else {
                rewrite(rng, m.get_mut(&k).expect("key"));
            }
        }
        serde_json::Value::Array(a) if !a.is_empty() => {
            let i = rng.below(a.len());
            rewrite(rng, &mut a[i]);
        }
        other => *other = hostile_json(rng),
    }
}

fn one_line(e: &vkterrain::Error) {
    let s = e.to_string();
    assert!(!s.contains('\n') && !s.is_empty(), "not one line: {s:?}");
}

fn vm_hwm_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .unwrap_or(0.0)
        / 1024.0
}

/// The targets, in the order cases cycle through them.
const TARGETS: [&str; 4] = [
    "manifest",
    "level header / node record",
    "tile statistics",
    "tile PNG decoding",
];

fn main() {
    let cases: u64 = std::env::var("VKT_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1_000_000);
    let seed: u64 = std::env::var("VKT_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0x5eed);
    let dir = std::env::temp_dir().join(format!("vkt-fuzz-{}", std::process::id()));
    let fx = Fixture::new(&dir.join("ds"));
    let mut rng = Rng(seed | 1);
    let mut accepted = [0u64; 4];
    let mut counts = [0u64; 4];
    let t0 = Instant::now();
    // Quiet panics: a panic is reported with its input below.
    std::panic::set_hook(Box::new(|_| {}));
    for case in 0..cases {
        let target = (case % 4) as usize;
        counts[target] += 1;
        let state = rng.0;
        let (input, result) = match target {
            0 => fx.manifest_case(&mut rng),
            1 => fx.level_case(&mut rng),
            2 => fx.stats_case(&mut rng),
            _ => fx.tile_case(&mut rng),
        };
        match result {
            Ok(ok) => accepted[target] += ok as u64,
            Err(_) => {
                let path = dir.join(format!("crash-{case}-target{target}.bin"));
                std::fs::write(&path, &input).ok();
                eprintln!(
                    "case {case} (target {target}, rng state {state:#x}) panicked; input saved to {}",
                    path.display()
                );
                std::process::exit(1);
            }
        }
        if case % 100_000 == 99_999 {
            eprintln!(
                "{} cases, {:.0} s, peak RSS {:.0} MiB",
                case + 1,
                t0.elapsed().as_secs_f64(),
                vm_hwm_mib()
            );
        }
    }
    let hwm = vm_hwm_mib();
    println!(
        "fuzz_readers: {cases} cases in {:.1} s (seed {seed:#x}), no panic, every error one line; peak RSS {hwm:.0} MiB",
        t0.elapsed().as_secs_f64()
    );
    for (k, name) in TARGETS.iter().enumerate() {
        println!(
            "  {name:<27} {:>8} cases, {:>7} accepted",
            counts[k], accepted[k]
        );
    }
    assert!(
        hwm < 512.0,
        "peak RSS {hwm} MiB: a reader allocated what its input claimed"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// One case: the input it built, and whether the reader accepted it (`Err`: it panicked).
type Case = (Vec<u8>, std::thread::Result<bool>);

/// A small real data set (manifest, level files, statistics) and a tile PNG: the valid inputs
/// every case mutates.
struct Fixture {
    ds: Dataset,
    manifest_text: String,
    manifest_json: serde_json::Value,
    /// Level 1's first node record and its file header.
    record: Vec<u8>,
    header: Vec<u8>,
    /// The grid-8 tile statistics file.
    stats: Vec<u8>,
    tile: Vec<u8>,
}

impl Fixture {
    fn new(out: &std::path::Path) -> Fixture {
        preprocess::run(
            &Options {
                input: Input::Procedural(ProceduralParams {
                    size: 97,
                    ..Default::default()
                }),
                out: out.to_path_buf(),
                center_size: 16,
                stats_grid_sizes: vec![4, 8],
                ..Default::default()
            },
            &NoProgress,
        )
        .expect("fixture");
        let ds = Dataset::open(out).expect("fixture");
        let manifest_text = std::fs::read_to_string(out.join("manifest.json")).expect("manifest");
        let manifest_json = serde_json::from_str(&manifest_text).expect("json");
        let level1 = std::fs::read(out.join("L1.bin")).expect("level");
        let record_size = ds.manifest.levels[1].record_size as usize;
        let record = level1[LEVEL_HEADER as usize..LEVEL_HEADER as usize + record_size].to_vec();
        let header = level_header(&ds.layout, 1, ds.layers);
        let stats = std::fs::read(out.join("stats-g8.bin")).expect("stats");
        Fixture {
            ds,
            manifest_text,
            manifest_json,
            record,
            header,
            stats,
            tile: terrarium_png(),
        }
    }

    /// The manifest, mutated as bytes or rewritten as JSON: accepted, everything a reader
    /// derives from it is consistent.
    fn manifest_case(&self, rng: &mut Rng) -> Case {
        let input = if rng.below(2) == 0 {
            mutate(rng, self.manifest_text.as_bytes())
        } else {
            let mut v = self.manifest_json.clone();
            rewrite(rng, &mut v);
            serde_json::to_vec(&v).expect("json")
        };
        let result = std::panic::catch_unwind(AssertUnwindSafe(|| {
            let text = String::from_utf8_lossy(&input);
            match Manifest::parse(&text, "manifest.json") {
                Ok(m) => {
                    let (layout, _) = m.layout().expect("checked layout");
                    assert_eq!(layout.levels() as usize, m.levels.len());
                    assert!(m.spacing.iter().all(|s| s.is_finite() && *s > 0.0));
                    for l in &m.levels {
                        assert!(!l.file.contains('/') && !l.file.contains(".."));
                    }
                    true
                }
                Err(e) => rejected(&e),
            }
        }));
        (input, result)
    }

    /// A level file's header or a node record.
    fn level_case(&self, rng: &mut Rng) -> Case {
        let base = if rng.below(2) == 0 {
            &self.record
        } else {
            &self.header
        };
        let input = mutate(rng, base);
        let result = std::panic::catch_unwind(AssertUnwindSafe(|| {
            if input.len() == LEVEL_HEADER as usize && base.len() == LEVEL_HEADER as usize {
                // The header check is an exact comparison.
                return input == self.header;
            }
            let (layout, layers) = (&self.ds.layout, self.ds.layers);
            match parse_record(&input, layout, layers) {
                Ok(n) => {
                    let side = layout.side() as usize;
                    assert_eq!(n.heights.len(), side * side);
                    assert_eq!(n.mask.len(), if layers.mask { side * side } else { 0 });
                    true
                }
                Err(e) => rejected(&e),
            }
        }));
        (input, result)
    }

    /// The tile statistics file: accepted, its ranges ordered and its errors finite.
    fn stats_case(&self, rng: &mut Rng) -> Case {
        let input = mutate(rng, &self.stats);
        let (w, h) = (
            self.ds.manifest.width as u32,
            self.ds.manifest.height as u32,
        );
        let result = std::panic::catch_unwind(AssertUnwindSafe(|| {
            match TileStats::from_bytes(&input, "stats-g8.bin", w, h, 8) {
                Ok(s) => {
                    for l in &s.levels {
                        assert!(l.min_max.iter().all(|m| m[0] <= m[1] && m[0].is_finite()));
                        assert!(l.error.iter().all(|e| e.is_finite() && *e >= 0.0));
                    }
                    true
                }
                Err(e) => rejected(&e),
            }
        }));
        (input, result)
    }

    /// An XYZ tile PNG: accepted, a whole tile of finite heights.
    fn tile_case(&self, rng: &mut Rng) -> Case {
        let input = mutate(rng, &self.tile);
        let result = std::panic::catch_unwind(AssertUnwindSafe(|| {
            match decode_tile(&input, Encoding::Terrarium, 256) {
                Ok(v) => {
                    assert_eq!(v.len(), 256 * 256);
                    assert!(v.iter().all(|h| h.is_finite()));
                    true
                }
                Err(e) => rejected(&e),
            }
        }));
        (input, result)
    }
}

/// A rejected input: its error must be one line.
fn rejected(e: &vkterrain::Error) -> bool {
    one_line(e);
    false
}

/// A 256² Terrarium-encoded PNG of a tilted plane.
fn terrarium_png() -> Vec<u8> {
    let mut img = image::RgbImage::new(256, 256);
    for (x, y, p) in img.enumerate_pixels_mut() {
        *p = image::Rgb(Encoding::Terrarium.encode((x * 7 + y * 3) as f64 * 0.37 - 50.0));
    }
    let mut b = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut b), image::ImageFormat::Png)
        .expect("png");
    b
}

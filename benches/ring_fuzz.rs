//! The Rust ring reader against 10^6 hostile segments (`cargo bench --bench ring_fuzz`; not
//! part of every CI run: tests/ring.rs runs 3000 of the same cases). Each case mutates a valid
//! ring (tests/helpers/mutate.rs), writes it to one file on tmpfs and opens, waits, reads and
//! views it; every frame returned must agree with the checked header. A crash or a panic fails
//! the run. `VKTERRAIN_FUZZ_CASES` overrides the count, `VKTERRAIN_FUZZ_SEED` the seed.

#[path = "../tests/helpers/mutate.rs"]
mod mutate;

use std::os::unix::fs::PermissionsExt;
use std::time::{Duration, Instant};

use vkterrain::output::ring::{
    FrameMeta, Geometry, Next, ProducerOptions, RingLocation, RingProducer, RingReader,
};

fn main() {
    let cases: u64 = std::env::var("VKTERRAIN_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1_000_000);
    let seed: u64 = std::env::var("VKTERRAIN_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0x5EED);
    let dir = std::path::PathBuf::from(format!("/dev/shm/vkt-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).unwrap();
    // SAFETY: no arguments.
    let me = unsafe { libc::geteuid() };

    let g = Geometry::new(8, 4, 2, true);
    let template = {
        let loc = RingLocation::new(&dir, "template").unwrap();
        let mut p = RingProducer::create(&loc, g, &ProducerOptions::default()).unwrap();
        let px = vec![7u8; g.pixel_bytes() as usize];
        let meta = FrameMeta {
            width: 8,
            height: 4,
            ..Default::default()
        };
        for _ in 0..3 {
            p.publish(&meta, &px, Some(&[0.5f32; 32])).unwrap();
        }
        std::fs::read(loc.segment_path()).unwrap()
    };
    let loc = RingLocation::new(&dir, "case").unwrap();
    let path = loc.segment_path();
    let mut rng = mutate::Rng(seed | 1);
    let (mut opened, mut frames, mut views) = (0u64, 0u64, 0u64);
    let start = Instant::now();
    for c in 0..cases {
        let bytes = if c == 0 {
            template.clone()
        } else {
            mutate::mutate(&template, &mut rng)
        };
        std::fs::write(&path, &bytes).unwrap();
        let Ok(mut r) = RingReader::open(&loc, Some(me)) else {
            continue;
        };
        opened += 1;
        let geo = r.geometry();
        for _ in 0..3 {
            match r.wait_next(Duration::ZERO) {
                Ok(Next::Frame(m)) => {
                    assert_eq!((m.width, m.height), (geo.width, geo.height), "case {c}");
                    assert_eq!(r.pixels().len() as u64, geo.pixel_bytes(), "case {c}");
                    frames += 1;
                }
                _ => break,
            }
        }
        if let Some(v) = r.view() {
            assert_eq!(v.pixels().len() as u64, geo.pixel_bytes(), "case {c}");
            views += 1;
        }
        if c % 100_000 == 0 && c > 0 {
            eprintln!("{c} cases, {:.0} s", start.elapsed().as_secs_f64());
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(opened > 0 && frames > 0, "no case reached the slot checks");
    println!(
        "ring_fuzz: {cases} cases (seed {seed}), {opened} opened, {frames} frames, {views} views, 0 crashes, {:.1} s",
        start.elapsed().as_secs_f64()
    );
}

//! UDLOD start-up on tile pyramids (a benchmark, not a test): the tile statistics `Levels`
//! needs, (a) read from the data set (`stats-g{GRID}.bin`, `GRID` the tile size whose statistics
//! UDLOD's default reads, stored by `vkterrain preprocess`: what start-up does now), (b) computed from level 0 through the bounded node reader on one
//! thread (what start-up did before), (c) computed from level 0's file in parallel (a grid size
//! that was not stored); and (d) the split field built from them (`SplitField::new`, UDLOD's
//! default settings at 1080p; after it, with two field nodes per tile side, whose levels are
//! computed untimed). `cargo bench --bench startup`.
//!
//! `VKT_STARTUP_DATASETS`: comma-separated data set directories (default
//! `target/data/proc4k`); `VKT_STARTUP_BEFORE=0` skips (b) (minutes on 65537²).

use std::path::PathBuf;
use std::time::Instant;

use vkterrain::dataset::stats::TileStats;
use vkterrain::dataset::{Level0, PyramidReader};
use vkterrain::lod::udlod::field::{FieldKey, SplitField};
use vkterrain::lod::udlod::levels::Levels;
use vkterrain::lod::udlod::settings::UdlodSettings;
use vkterrain::scene::Camera;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The tile size whose statistics UDLOD's default reads: its split field's cells (stored by
/// `vkterrain preprocess` by default).
const GRID: u32 = vkterrain::dataset::preprocess::DEFAULT_STATS_GRID_SIZES[0];

/// The default's split-field nodes per tile side (its tiles are `GRID x DENSITY` quads).
fn density() -> u32 {
    let d = UdlodSettings::default();
    assert_eq!(
        d.grid_size / d.field_density(),
        GRID,
        "the stored grid is the default's cells"
    );
    d.field_density()
}

fn main() {
    let sets = std::env::var("VKT_STARTUP_DATASETS")
        .unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/target/data/proc4k").to_string());
    let before = std::env::var("VKT_STARTUP_BEFORE").map_or(true, |v| v != "0");
    let threads = rayon::current_num_threads();
    println!(
        "UDLOD start-up (grid_size {GRID}): tile statistics for Levels; {threads} threads for (c); warm page cache, medians of 3 (one run for (b))"
    );
    println!(
        "| data set | samples | (a) stored s | (b) level 0, 1 thread s | (c) level 0, parallel s | stats file MiB | (d) split field s, 1 / 2 nodes per side |"
    );
    println!("|---|---|---|---|---|---|---|");
    for dir in sets.split(',').map(PathBuf::from) {
        let reader = PyramidReader::open(&dir).expect("data set");
        let stored = (0..3)
            .map(|_| {
                let t = Instant::now();
                let r = PyramidReader::open(&dir).expect("data set");
                let s = r.field_stats(GRID, density()).expect("stats");
                let levels = Levels::from_field_stats(s, r.spacing());
                assert_eq!(r.node_loads(), 0, "start-up read level 0");
                std::hint::black_box(levels);
                t.elapsed().as_secs_f64()
            })
            .collect::<Vec<_>>();
        let bytes =
            std::fs::metadata(dir.join(format!("stats-g{GRID}.bin"))).map_or(0, |m| m.len());
        let old = if before {
            let t = Instant::now();
            let l =
                Levels::for_settings(&reader.sweep(), &UdlodSettings::default()).expect("levels");
            std::hint::black_box(l);
            format!("{:.2}", t.elapsed().as_secs_f64())
        } else {
            "skipped".into()
        };
        let par = (0..3)
            .map(|_| {
                let t = Instant::now();
                let rows = reader.store().level0_rows().expect("disk").expect("rows");
                let s = TileStats::compute(&rows, GRID, &|_| {}).expect("stats");
                let levels =
                    Levels::with_field_density(s.without_finest(), density(), reader.spacing());
                std::hint::black_box(levels.expect("levels"));
                t.elapsed().as_secs_f64()
            })
            .collect::<Vec<_>>();
        let field = [1, 2].map(|d| format!("{:.3}", median(field_build_s(&reader, d))));
        println!(
            "| {} | {}x{} | {:.3} | {old} | {:.2} | {:.1} | {} / {} |",
            dir.display(),
            reader.width(),
            reader.height(),
            median(stored),
            median(par),
            bytes as f64 / 1048576.0,
            field[0],
            field[1]
        );
    }
}

/// Seconds to build UDLOD's split field (default settings with `density` field nodes per tile
/// side, 1080p), three times; the levels are built untimed from level 0's file.
fn field_build_s(reader: &PyramidReader, density: u32) -> Vec<f64> {
    let settings = UdlodSettings {
        field_density: density,
        ..UdlodSettings::default()
    };
    let rows = reader.store().level0_rows().expect("disk").expect("rows");
    let cells = TileStats::compute(&rows, settings.grid_size / density, &|_| {}).expect("stats");
    let levels = Levels::with_field_density(cells, density, reader.spacing()).expect("levels");
    let key = FieldKey::new(&settings, Camera::default().focal_px(1080));
    (0..3)
        .map(|_| {
            let t = Instant::now();
            std::hint::black_box(SplitField::new(&levels, key));
            t.elapsed().as_secs_f64()
        })
        .collect()
}

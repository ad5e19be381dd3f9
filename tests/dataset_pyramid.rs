//! Round trips of the node pyramid on small generated rasters (no external data).

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use vkterrain::dataset::preprocess::{self, Input, NoProgress, Options};
use vkterrain::dataset::procedural::{self, ProceduralParams};
use vkterrain::dataset::pyramid::{LayerSet, Layout};
use vkterrain::dataset::source::Raster;
use vkterrain::dataset::tiles::{self, Dataset};

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vkt-pyr-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Rough terrain with a few voids, deterministic.
fn raster(w: u32, h: u32, voids: bool) -> Raster {
    let mut s = 0x1234_5678_9abc_def0u64;
    let mut heights = Vec::new();
    for r in 0..h {
        for c in 0..w {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let noise = (s % 1000) as f32 / 100.0;
            heights.push((c as f32 * 1.7 + r as f32 * 0.9).sin() * 50.0 + noise + 100.0);
        }
    }
    if voids {
        for r in 10..20 {
            for c in 30..45 {
                heights[(r * w + c) as usize] = f32::NAN;
            }
        }
    }
    Raster {
        name: "generated".into(),
        width: w,
        height: h,
        spacing: [10.0, 10.0],
        heights,
        georef: None,
        vertical_datum: "local".into(),
        nodata: None,
        provenance: vec!["generated".into()],
        warnings: Vec::new(),
    }
}

fn build(dir: &Path, r: Raster, center: u32, border: u32) -> Dataset {
    let out = dir.join("ds");
    let opts = Options {
        input: Input::Raster(r),
        out: out.clone(),
        center_size: center,
        border_size: border,
        force: true,
        ..Default::default()
    };
    preprocess::run(&opts, &NoProgress).unwrap();
    Dataset::open(&out).unwrap()
}

/// Level texel `(u, v)` (clamped to the padded level) via single-node reads.
fn texel(ds: &Dataset, lod: u32, u: i64, v: i64) -> f32 {
    let l = &ds.layout;
    let (nx, ny) = l.nodes(lod);
    let c = l.center as i64;
    let u = u.clamp(0, nx as i64 * c - 1);
    let v = v.clamp(0, ny as i64 * c - 1);
    let n = ds.read_node(lod, (u / c) as u32, (v / c) as u32).unwrap();
    n.centre(l, (u % c) as u32, (v % c) as u32)
}

#[test]
fn parent_is_exact_downsample_and_borders_match_neighbours() {
    let dir = tmpdir("exact");
    for (w, h, c, b) in [
        (150u32, 87u32, 16u32, 2u32),
        (64, 64, 16, 3),
        (33, 97, 8, 2),
    ] {
        let ds = build(&dir, raster(w, h, true), c, b);
        let l = ds.layout;
        assert_eq!(ds.manifest.levels.len() as u32, l.levels());
        for lod in 0..l.levels() {
            let (nx, ny) = l.nodes(lod);
            let (lw, lh) = l.level_size(lod);
            let nodes: Vec<Vec<_>> = (0..ny)
                .map(|y| (0..nx).map(|x| ds.read_node(lod, x, y).unwrap()).collect())
                .collect();
            let s = l.side() as i64;
            for y in 0..ny {
                for x in 0..nx {
                    let n = &nodes[y as usize][x as usize];
                    for j in 0..s {
                        for i in 0..s {
                            let val = n.heights[(j * s + i) as usize];
                            assert!(val.is_finite());
                            // Every texel (border or centre) equals the clamped level texel,
                            // i.e. the neighbour's centre texel, bit for bit.
                            let (sx, ci) = l.source_of(nx, x, i - b as i64);
                            let (sy, cj) = l.source_of(ny, y, j - b as i64);
                            let src = nodes[sy as usize][sx as usize].centre(&l, ci, cj);
                            assert_eq!(
                                val.to_bits(),
                                src.to_bits(),
                                "lod {lod} node {x},{y} texel {i},{j}"
                            );
                            // Texels past the valid extent replicate the last valid texel.
                            let (gu, gv) = (
                                x as i64 * c as i64 + i - b as i64,
                                y as i64 * c as i64 + j - b as i64,
                            );
                            let (cu, cv) = (gu.clamp(0, lw as i64 - 1), gv.clamp(0, lh as i64 - 1));
                            if (cu, cv) != (gu, gv) {
                                assert_eq!(val.to_bits(), texel(&ds, lod, cu, cv).to_bits());
                            }
                        }
                    }
                    // min/max cover the record.
                    let lo = n.heights.iter().cloned().fold(f32::INFINITY, f32::min);
                    let hi = n.heights.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
                    assert_eq!((n.min, n.max), (lo, hi));
                }
            }
            if lod == 0 {
                continue;
            }
            // Parent == ((a + b) + (c + d)) * 0.25 of its children over the valid extent.
            for v in 0..lh as i64 {
                for u in 0..lw as i64 {
                    let k = |du, dv| texel(&ds, lod - 1, 2 * u + du, 2 * v + dv);
                    let want = ((k(0, 0) + k(1, 0)) + (k(0, 1) + k(1, 1))) * 0.25;
                    assert_eq!(texel(&ds, lod, u, v).to_bits(), want.to_bits());
                }
            }
        }
        // Level 0 centre texels are the source (voids filled, mask set).
        let src = raster(w, h, true);
        let (void_x, void_y) = (35u32, 15u32);
        let n = ds.read_node(0, void_x / c, void_y / c).unwrap();
        let k = ((void_y % c + b) * l.side() + void_x % c + b) as usize;
        assert_eq!(n.mask[k], 1);
        assert_eq!(ds.manifest.voids_filled, 150);
        for (i, hv) in src.heights.iter().enumerate() {
            let (u, v) = (i as i64 % w as i64, i as i64 / w as i64);
            if hv.is_finite() {
                assert_eq!(texel(&ds, 0, u, v), *hv);
            }
        }
    }
}

#[test]
fn node_reads_alone() {
    let dir = tmpdir("alone");
    let ds = build(&dir, raster(100, 70, false), 16, 2);
    let full = ds.read_node(1, 2, 1).unwrap();
    // Remove every other level: reading one node touches one file, one record.
    for info in &ds.manifest.levels {
        if info.lod != 1 {
            std::fs::remove_file(ds.dir.join(&info.file)).unwrap();
        }
    }
    let again = Dataset::open(&ds.dir).unwrap().read_node(1, 2, 1).unwrap();
    assert_eq!(full, again);
    assert!(ds.read_node(0, 0, 0).is_err());
}

#[test]
fn interrupted_run_leaves_no_dataset_and_rerun_starts_clean() {
    let dir = tmpdir("atomic");
    let out = dir.join("ds");
    let partial = dir.join("ds.partial");
    std::fs::create_dir_all(&partial).unwrap();
    std::fs::write(partial.join("L0.bin"), b"half a file").unwrap();
    // What an interrupted run leaves is not a data set.
    let e = Dataset::open(&partial).unwrap_err().to_string();
    assert!(e.contains("not a complete"), "{e}");
    assert!(!out.exists());
    let opts = Options {
        input: Input::Raster(raster(40, 40, false)),
        out: out.clone(),
        center_size: 8,
        ..Default::default()
    };
    preprocess::run(&opts, &NoProgress).unwrap();
    assert!(!partial.exists());
    Dataset::open(&out).unwrap();
    // A second run refuses to overwrite without force, and leaves the data set intact.
    let e = preprocess::run(&opts, &NoProgress).unwrap_err().to_string();
    assert!(e.contains("already exists"), "{e}");
    Dataset::open(&out).unwrap();
    let opts = Options {
        force: true,
        ..opts
    };
    preprocess::run(&opts, &NoProgress).unwrap();
    Dataset::open(&out).unwrap();
    // A truncated level file is detected.
    let f = std::fs::OpenOptions::new()
        .write(true)
        .open(out.join("L0.bin"))
        .unwrap();
    f.set_len(1000).unwrap();
    let e = Dataset::open(&out)
        .unwrap()
        .read_node(0, 0, 0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("L0.bin") && e.contains("truncated"), "{e}");
}

#[test]
fn procedural_is_deterministic_and_matches_the_generator() {
    let dir = tmpdir("proc");
    let p = ProceduralParams {
        size: 300,
        seed: 7,
        ..Default::default()
    };
    let mut bytes = Vec::new();
    for run in 0..2 {
        let out = dir.join(format!("p{run}"));
        let opts = Options {
            input: Input::Procedural(p),
            out: out.clone(),
            center_size: 64,
            ..Default::default()
        };
        let s = preprocess::run(&opts, &NoProgress).unwrap();
        assert_eq!(s.content, "procedural");
        bytes.push(std::fs::read(out.join("L0.bin")).unwrap());
    }
    assert_eq!(bytes[0], bytes[1]);
    let ds = Dataset::open(&dir.join("p0")).unwrap();
    assert_eq!(ds.manifest.content, "procedural");
    for (u, v) in [(0i64, 0i64), (17, 250), (299, 299), (128, 64)] {
        let want = procedural::height(&p, u as f64 * p.spacing, v as f64 * p.spacing) as f32;
        assert_eq!(texel(&ds, 0, u, v), want);
    }
    let map = tiles::load(&dir.join("p0"), Some(1), u64::MAX).unwrap();
    assert_eq!((map.width, map.height), (150, 150));
    assert_eq!(map.spacing, 60.0);
}

#[test]
fn amplified_dem_is_labelled_and_stays_near_the_source() {
    let dir = tmpdir("amp");
    let out = dir.join("ds");
    let src = raster(40, 30, false);
    let opts = Options {
        input: Input::Raster(src.clone()),
        out: out.clone(),
        center_size: 32,
        amplify: Some((4, 3)),
        ..Default::default()
    };
    let s = preprocess::run(&opts, &NoProgress).unwrap();
    assert_eq!((s.width, s.height), (157, 117));
    let ds = Dataset::open(&out).unwrap();
    assert_eq!(ds.manifest.content, "amplified");
    assert!(ds.manifest.name.contains("amplified"));
    assert!(
        ds.manifest
            .provenance
            .iter()
            .any(|p| p.contains("AMPLIFIED"))
    );
    assert_eq!(ds.manifest.spacing, [2.5, 2.5]);
    // At source sample positions: source + detail of at most ~2 x 0.05 x spacing.
    for (c, r) in [(0u32, 0u32), (10, 20), (39, 29)] {
        let got = texel(&ds, 0, c as i64 * 4, r as i64 * 4);
        let want = src.heights[(r * 40 + c) as usize];
        assert!((got - want).abs() <= 1.0, "{got} vs {want}");
    }
}

#[test]
fn tiles_loader_assembles_a_level() {
    let dir = tmpdir("load");
    let src = raster(70, 50, false);
    let ds = build(&dir, src.clone(), 16, 2);
    let map = tiles::load(&ds.dir, None, u64::MAX).unwrap();
    assert_eq!((map.width, map.height, map.spacing), (70, 50, 10.0));
    assert_eq!(map.heights, src.heights);
    let small = tiles::load(&ds.dir, None, 40 * 40).unwrap();
    assert_eq!((small.width, small.height, small.spacing), (35, 25, 20.0));
    let level1 = tiles::load(&ds.dir, Some(1), u64::MAX).unwrap();
    assert_eq!((level1.width, level1.height), (35, 25));
    let e = tiles::load(&ds.dir, Some(9), u64::MAX)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("dataset.lod") && e.contains("has levels 0.."),
        "{e}"
    );
}

proptest! {
    #[test]
    fn addressing(w in 2u64..100_000, h in 2u64..100_000, ck in 2u32..10, b in 2u32..6, i in -6i64..600) {
        let c = 1u32 << ck;
        prop_assume!(b <= c);
        let l = Layout::new(w, h, c, b).unwrap();
        let levels = l.levels();
        prop_assert_eq!(l.nodes(levels - 1), (1, 1));
        if levels > 1 {
            prop_assert!(l.nodes(levels - 2) != (1, 1));
        }
        for lod in 0..levels {
            let (lw, lh) = l.level_size(lod);
            let (nx, ny) = l.nodes(lod);
            prop_assert_eq!(l.level_size(lod + 1), (lw.div_ceil(2), lh.div_ceil(2)));
            prop_assert!(nx as u64 * c as u64 >= lw && (nx as u64 - 1) * (c as u64) < lw);
            prop_assert!(ny as u64 * c as u64 >= lh && (ny as u64 - 1) * (c as u64) < lh);
            // Texel sources: centre texels map to themselves; others to a neighbour's centre
            // at the same global position, or the clamped edge.
            let x = (i.unsigned_abs() as u32) % nx;
            let ii = i.rem_euclid((c + 2 * b) as i64) - b as i64;
            let (sx, si) = l.source_of(nx, x, ii);
            prop_assert!(sx < nx && si < c);
            let g = x as i64 * c as i64 + ii;
            let clamped = g.clamp(0, nx as i64 * c as i64 - 1);
            prop_assert_eq!(sx as i64 * c as i64 + si as i64, clamped);
            if (0..c as i64).contains(&ii) {
                prop_assert_eq!((sx, si), (x, ii as u32));
            }
            // Records tile the file without gaps or overlaps.
            for layers in [LayerSet::default(), LayerSet { mask: true, albedo: true }] {
                let size = l.record_size(layers);
                let last = l.record_offset(lod, nx - 1, ny - 1, layers);
                prop_assert_eq!(last + size, 64 + nx as u64 * ny as u64 * size);
                if nx > 1 {
                    prop_assert_eq!(l.record_offset(lod, 1, 0, layers) - l.record_offset(lod, 0, 0, layers), size);
                }
            }
        }
    }
}

#[test]
fn config_kind_tiles_loads_a_dataset() {
    let dir = tmpdir("config");
    let ds = build(&dir, raster(50, 40, false), 16, 2);
    std::fs::write(
        dir.join("c.toml"),
        "[dataset]\nkind = \"tiles\"\npath = \"ds\"\nlod = 1\n",
    )
    .unwrap();
    let cfg = vkterrain::config::Config::load(Some(&dir.join("c.toml"))).unwrap();
    let map = cfg.dataset.load(|p| cfg.resolve(p)).unwrap();
    assert_eq!((map.width, map.height, map.spacing), (25, 20, 20.0));
    assert_eq!(
        map.sample(3, 4),
        ds.read_node(1, 0, 0).unwrap().centre(&ds.layout, 3, 4)
    );
    std::fs::write(dir.join("bad.toml"), "[dataset]\nkind = \"tiles\"\n").unwrap();
    assert!(vkterrain::config::Config::load(Some(&dir.join("bad.toml"))).is_err());
}

/// Every file of the data set (levels, statistics, manifest) is the same bit for bit whether
/// one thread or several build it: a raster with voids and amplification, and a procedural
/// terrain of several node rows. Negative control: one flipped byte makes the comparison fail.
#[test]
fn output_is_identical_for_one_thread_and_many() {
    let dir = tmpdir("threads");
    let files = |d: &Path| {
        let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap())
            .map(|e| {
                (
                    e.file_name().to_string_lossy().to_string(),
                    std::fs::read(e.path()).unwrap(),
                )
            })
            .collect();
        v.sort();
        v
    };
    let inputs = [
        Options {
            input: Input::Raster(raster(300, 170, true)),
            center_size: 16,
            amplify: Some((3, 7)),
            stats_grid_sizes: vec![4, 16],
            ..Default::default()
        },
        Options {
            input: Input::Procedural(vkterrain::dataset::procedural::ProceduralParams {
                size: 700,
                ..Default::default()
            }),
            center_size: 32,
            border_size: 3,
            ..Default::default()
        },
    ];
    for (k, base) in inputs.into_iter().enumerate() {
        let mut runs = Vec::new();
        for threads in [1, 4] {
            let out = dir.join(format!("ds{k}-{threads}"));
            let opts = Options {
                out: out.clone(),
                ..base.clone()
            };
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| preprocess::run(&opts, &NoProgress))
                .unwrap();
            runs.push(files(&out));
        }
        assert!(runs[0].len() >= 4);
        assert_eq!(runs[0].len(), runs[1].len());
        for (a, b) in runs[0].iter().zip(&runs[1]) {
            assert_eq!(a.0, b.0);
            assert!(a.1 == b.1, "{} differs between 1 and 4 threads", a.0);
        }
        let mut flipped = runs[1].clone();
        flipped[0].1[70] ^= 1;
        assert!(
            flipped != runs[0],
            "the comparison must see one flipped byte"
        );
    }
}

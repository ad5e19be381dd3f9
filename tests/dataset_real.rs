//! Real DEMs from `../shared/data` (skipped with a note when that directory is absent).

use std::io::Read;
use std::path::{Path, PathBuf};

use vkterrain::dataset::preprocess::{self, Input, NoProgress, Options};
use vkterrain::dataset::tiles::{self, Dataset};
use vkterrain::dataset::{srtm, voids};

fn data() -> Option<PathBuf> {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    if d.is_dir() {
        Some(d)
    } else {
        eprintln!("note: {} absent, real-data test skipped", d.display());
        None
    }
}

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vkt-real-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run(inputs: Vec<PathBuf>, out: &Path, f: impl FnOnce(&mut Options)) -> Dataset {
    let mut opts = Options {
        input: Input::Files(inputs),
        out: out.to_path_buf(),
        force: true,
        ..Default::default()
    };
    f(&mut opts);
    preprocess::run(&opts, &mut NoProgress).unwrap();
    Dataset::open(out).unwrap()
}

fn texel(ds: &Dataset, lod: u32, u: u64, v: u64) -> f32 {
    let c = ds.layout.center as u64;
    ds.read_node(lod, (u / c) as u32, (v / c) as u32)
        .unwrap()
        .centre(&ds.layout, (u % c) as u32, (v % c) as u32)
}

fn raw_hgt(path: &Path) -> Vec<i16> {
    let mut zip = zip::ZipArchive::new(std::fs::File::open(path).unwrap()).unwrap();
    let mut bytes = Vec::new();
    zip.by_index(0).unwrap().read_to_end(&mut bytes).unwrap();
    bytes
        .chunks_exact(2)
        .map(|c| i16::from_be_bytes([c[0], c[1]]))
        .collect()
}

#[test]
fn srtm_pair_mosaics_with_a_seamless_shared_edge() {
    let Some(d) = data() else { return };
    for (south, north) in [("N41E001", "N42E001"), ("N49E011", "N50E011")] {
        let s = d.join(format!("srtm/{south}.hgt.zip"));
        let n = d.join(format!("srtm/{north}.hgt.zip"));
        let r = srtm::mosaic(&[n.clone(), s.clone()]).unwrap();
        assert_eq!((r.width, r.height), (1201, 2401));
        let (rs, rn) = (raw_hgt(&s), raw_hgt(&n));
        // Shared row 1200: the south tile's north row (file row 0) and the north tile's south
        // row (file row 1200) agree wherever both are valid; the mosaic keeps that value.
        let mut compared = 0;
        for c in 0..1201usize {
            let (a, b) = (rs[c], rn[1200 * 1201 + c]);
            let m = r.heights[1200 * 1201 + c];
            if a != srtm::VOID && b != srtm::VOID {
                assert_eq!(a, b, "{south}/{north} column {c}");
                assert_eq!(m, a as f32);
                compared += 1;
            }
        }
        assert!(compared > 1000);
        // Rows either side come from each tile unchanged.
        for c in (0..1201usize).step_by(97) {
            let below = rs[1201 + c];
            if below != srtm::VOID {
                assert_eq!(r.heights[1199 * 1201 + c], below as f32);
            }
            let above = rn[1199 * 1201 + c];
            if above != srtm::VOID {
                assert_eq!(r.heights[1201 * 1201 + c], above as f32);
            }
        }
        // Through the pyramid: with 256-texel nodes row 1200 lies inside node row 4; the node
        // rows either side see each other's texels as borders, bit for bit.
        let out = tmpdir(south).join("ds");
        let ds = run(vec![s, n], &out, |_| {});
        for x in 0..ds.layout.nodes(0).0 {
            let lower = ds.read_node(0, x, 3).unwrap();
            let upper = ds.read_node(0, x, 4).unwrap();
            let side = ds.layout.side() as usize;
            let b = ds.layout.border as usize;
            for i in 0..side {
                for k in 0..b {
                    // lower's top border rows == upper's first centre rows.
                    assert_eq!(
                        lower.heights[(b + 256 + k) * side + i].to_bits(),
                        upper.heights[(b + k) * side + i].to_bits()
                    );
                    // upper's bottom border rows == lower's last centre rows.
                    assert_eq!(
                        upper.heights[k * side + i].to_bits(),
                        lower.heights[(256 + k) * side + i].to_bits()
                    );
                }
            }
        }
        std::fs::remove_dir_all(out.parent().unwrap()).ok();
    }
}

#[test]
fn void_filling_leaves_no_nodata_and_no_spikes() {
    let Some(d) = data() else { return };
    let mut r = srtm::mosaic(&[
        d.join("srtm/N41E001.hgt.zip"),
        d.join("srtm/N42E001.hgt.zip"),
    ])
    .unwrap();
    assert_eq!(r.void_count(), 7786);
    let valid: Vec<f32> = r.heights.iter().copied().filter(|h| !h.is_nan()).collect();
    let lo = valid.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = valid.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let (w, h) = (r.width as usize, r.height as usize);
    let mut max_valid_step = 0f32;
    for y in 0..h {
        for x in 0..w - 1 {
            let a = r.heights[y * w + x];
            for j in [y * w + x + 1, ((y + 1) * w + x).min(w * h - 1)] {
                let b = r.heights[j];
                if !a.is_nan() && !b.is_nan() {
                    max_valid_step = max_valid_step.max((a - b).abs());
                }
            }
        }
    }
    let (mask, n) = voids::fill(&r.name, &mut r.heights, r.width, r.height).unwrap();
    assert_eq!(n, 7786);
    assert!(r.heights.iter().all(|v| v.is_finite()));
    let mut max_filled_step = 0f32;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if mask[i] == 0 {
                continue;
            }
            assert!(r.heights[i] >= lo && r.heights[i] <= hi);
            let mut nbs = Vec::new();
            if x + 1 < w {
                nbs.push(i + 1);
            }
            if y + 1 < h {
                nbs.push(i + w);
            }
            for j in nbs {
                max_filled_step = max_filled_step.max((r.heights[i] - r.heights[j]).abs());
            }
        }
    }
    // No spikes or pits: every void region's fill stays within the range of the valid samples
    // on its rim (the maximum principle of the harmonic fill), to 1 m.
    let mut region = vec![u32::MAX; w * h];
    let mut regions = 0;
    for start in 0..w * h {
        if mask[start] == 0 || region[start] != u32::MAX {
            continue;
        }
        let (mut members, mut stack) = (Vec::new(), vec![start]);
        region[start] = regions;
        let mut rim = (f32::INFINITY, f32::NEG_INFINITY);
        while let Some(i) = stack.pop() {
            members.push(i);
            let (x, y) = (i % w, i / w);
            let mut nbs = Vec::new();
            if x > 0 {
                nbs.push(i - 1)
            }
            if x + 1 < w {
                nbs.push(i + 1)
            }
            if y > 0 {
                nbs.push(i - w)
            }
            if y + 1 < h {
                nbs.push(i + w)
            }
            for j in nbs {
                if mask[j] == 0 {
                    rim = (rim.0.min(r.heights[j]), rim.1.max(r.heights[j]));
                } else if region[j] == u32::MAX {
                    region[j] = regions;
                    stack.push(j);
                }
            }
        }
        for &i in &members {
            let v = r.heights[i];
            assert!(
                v >= rim.0 - 1.0 && v <= rim.1 + 1.0,
                "fill {v} at {},{} outside its void's rim range {rim:?} ({} samples)",
                i % w,
                i / w,
                members.len()
            );
        }
        regions += 1;
    }
    assert!(regions > 10);
    assert!(
        max_filled_step <= max_valid_step,
        "{max_filled_step} > {max_valid_step}"
    );
}

#[test]
fn srtm1_tile_heights_match_source_and_half_void_is_filled() {
    let Some(d) = data() else { return };
    let path = d.join("srtm/N48W125.hgt.zip");
    let raw = raw_hgt(&path);
    let out = tmpdir("srtm1").join("ds");
    let ds = run(vec![path], &out, |o| o.center_size = 512);
    let m = &ds.manifest;
    assert_eq!((m.width, m.height), (3601, 3601));
    assert!(m.voids_filled > 3601 * 3601 * 4 / 10, "{}", m.voids_filled);
    // 1 arc-second: ~30.9 m north-south, ~20.6 m east-west at 48.5 N.
    assert!((m.spacing[1] - 30.87).abs() < 0.1, "{:?}", m.spacing);
    assert!((m.spacing[0] - 20.5).abs() < 0.2, "{:?}", m.spacing);
    let g = m.georef.as_ref().unwrap();
    assert_eq!((g.origin, g.crs.as_str()), ([-125.0, 48.0], "EPSG:4326"));
    let mut checked = 0;
    for file_row in (0..3601u64).step_by(113) {
        for col in (0..3601u64).step_by(89) {
            let s = raw[(file_row * 3601 + col) as usize];
            if s != srtm::VOID {
                assert_eq!(texel(&ds, 0, col, 3600 - file_row), s as f32);
                checked += 1;
            }
        }
    }
    assert!(checked > 200);
    std::fs::remove_dir_all(out.parent().unwrap()).ok();
}

#[test]
fn utm_geotiff_heights_match_source() {
    let Some(d) = data() else { return };
    let path = d.join("geotiff/srtm_bigtujunga30m_utm11.tif");
    // Reference samples straight from the uncompressed strips.
    let mut dec = tiff::decoder::Decoder::new(std::fs::File::open(&path).unwrap()).unwrap();
    let tiff::decoder::DecodingResult::I16(reference) = dec.read_image().unwrap() else {
        panic!("int16 expected")
    };
    let out = tmpdir("utm").join("ds");
    let ds = run(vec![path], &out, |_| {});
    let m = &ds.manifest;
    assert_eq!((m.width, m.height, m.spacing), (1197, 643, [30.0, 30.0]));
    assert_eq!(m.height_range, [315.0, 2295.0]);
    assert_eq!(m.voids_filled, 0);
    let g = m.georef.as_ref().unwrap();
    assert_eq!(g.crs, "EPSG:32611");
    // World file: top-left pixel centre 376328.655, 3807902.828; 30 m steps.
    assert!((g.origin[0] - 376_328.655_454_263_5).abs() < 1e-6);
    assert!((g.origin[1] - (3_807_902.827_628_375_5 - 642.0 * 30.0)).abs() < 1e-6);
    for row in (0..643u64).step_by(37) {
        for col in (0..1197u64).step_by(41) {
            let want = reference[(row * 1197 + col) as usize] as f32;
            assert_eq!(texel(&ds, 0, col, 642 - row), want);
        }
    }
    // The brute-force renderer's loader sees the same metres.
    let map = tiles::load(&out, Some(0), u64::MAX).unwrap();
    assert_eq!(map.sample(5, 642), reference[5] as f32);
    std::fs::remove_dir_all(out.parent().unwrap()).ok();
}

#[test]
fn puget_sound_png_with_albedo() {
    let Some(d) = data() else { return };
    let out = tmpdir("ps").join("ds");
    let ds = run(vec![d.join("puget_sound/ps_height_1k.png")], &out, |o| {
        o.spacing = Some(160.0);
        o.vertical_scale = Some(0.1);
        o.albedo = Some(d.join("puget_sound/ps_texture_1k.png"));
    });
    assert_eq!(ds.manifest.layers.albedo.as_deref(), Some("rgba8_srgb"));
    assert!((ds.manifest.height_range[1] - 4379.8).abs() < 0.01);
    let map = tiles::load(&out, None, u64::MAX).unwrap();
    assert_eq!((map.width, map.height, map.spacing), (1025, 1025, 160.0));
    let a = map.albedo.as_ref().unwrap();
    assert_eq!((a.width, a.height), (1025, 1025));
    assert!(a.rgba.chunks(4).any(|p| p[0] != p[1]));
    std::fs::remove_dir_all(out.parent().unwrap()).ok();
}

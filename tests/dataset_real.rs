//! Real DEMs from `../shared/data` (skipped with a note when that directory is absent, a
//! failure in CI), read through GDAL and checked against independent readers of the raw
//! bytes. Every test here reads files through GDAL: built only with the `gdal` feature (the
//! default, and what CI builds).
#![cfg(feature = "gdal")]

mod common;

use std::io::Read;
use std::path::{Path, PathBuf};

use vkterrain::dataset::preprocess::{self, Input, NoProgress, Options, read_inputs};
use vkterrain::dataset::tiles::{self, Dataset};
use vkterrain::dataset::voids;

const VOID: i16 = -32768;

fn data() -> Option<PathBuf> {
    common::shared_data()
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
    preprocess::run(&opts, &NoProgress).unwrap();
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
        let r = read_inputs(&[n.clone(), s.clone()], None, None).unwrap();
        assert_eq!((r.width, r.height), (1201, 2401));
        let (rs, rn) = (raw_hgt(&s), raw_hgt(&n));
        // Shared row 1200: the south tile's north row (file row 0) and the north tile's south
        // row (file row 1200) agree wherever both are valid; the mosaic keeps that value.
        let mut compared = 0;
        for c in 0..1201usize {
            let (a, b) = (rs[c], rn[1200 * 1201 + c]);
            let m = r.heights[1200 * 1201 + c];
            if a != VOID && b != VOID {
                assert_eq!(a, b, "{south}/{north} column {c}");
                assert_eq!(m, a as f32);
                compared += 1;
            }
        }
        assert!(compared > 1000);
        // Rows either side come from each tile unchanged.
        for c in (0..1201usize).step_by(97) {
            let below = rs[1201 + c];
            if below != VOID {
                assert_eq!(r.heights[1199 * 1201 + c], below as f32);
            }
            let above = rn[1199 * 1201 + c];
            if above != VOID {
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
    let mut r = read_inputs(
        &[
            d.join("srtm/N41E001.hgt.zip"),
            d.join("srtm/N42E001.hgt.zip"),
        ],
        None,
        None,
    )
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
    assert_eq!(g.crs.authority.as_deref(), Some("EPSG:4326"));
    assert_eq!(m.vertical_datum, "egm96");
    assert_eq!(m.nodata, Some(-32768.0));
    let [x0, y0] = g.origin();
    assert!(
        (x0 + 125.0).abs() < 1e-9 && (y0 - 48.0).abs() < 1e-9,
        "{x0} {y0}"
    );
    assert!((g.step()[0] - 1.0 / 3600.0).abs() < 1e-15);
    let mut checked = 0;
    for file_row in (0..3601u64).step_by(113) {
        for col in (0..3601u64).step_by(89) {
            let s = raw[(file_row * 3601 + col) as usize];
            if s != VOID {
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
    assert_eq!(g.crs.authority.as_deref(), Some("EPSG:32611"));
    // World file: top-left pixel centre 376328.655, 3807902.828; 30 m steps.
    assert!((g.origin()[0] - 376_328.655_454_263_5).abs() < 1e-6);
    assert!((g.origin()[1] - (3_807_902.827_628_375_5 - 642.0 * 30.0)).abs() < 1e-6);
    assert_eq!(g.step(), [30.0, 30.0]);
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

/// Every shared data file through GDAL gives the heights the raw bytes hold, at every sample
/// (0 m difference; voids exactly where the source has its void value): SRTM tiles against
/// their big-endian int16 bytes, the GeoTIFF against the `tiff` crate's strips, the PNG
/// against the `image` crate's decoder (the readers vkterrain had before GDAL).
#[test]
fn every_shared_file_through_gdal_equals_its_raw_samples() {
    let Some(d) = data() else { return };
    for tile in ["N41E001", "N42E001", "N48W125", "N49E011", "N50E011"] {
        let path = d.join(format!("srtm/{tile}.hgt.zip"));
        let raw = raw_hgt(&path);
        let side = (raw.len() as f64).sqrt() as usize;
        let r = read_inputs(std::slice::from_ref(&path), None, None).unwrap();
        assert_eq!(
            (r.width as usize, r.height as usize),
            (side, side),
            "{tile}"
        );
        let mut voids = 0;
        for row in 0..side {
            for col in 0..side {
                let want = raw[(side - 1 - row) * side + col];
                let got = r.heights[row * side + col];
                if want == VOID {
                    assert!(got.is_nan(), "{tile} ({col}, {row}) should be void");
                    voids += 1;
                } else {
                    assert_eq!(got, want as f32, "{tile} ({col}, {row})");
                }
            }
        }
        eprintln!("{tile}: {} samples equal, {voids} voids", side * side);
    }
    let path = d.join("geotiff/srtm_bigtujunga30m_utm11.tif");
    let mut dec = tiff::decoder::Decoder::new(std::fs::File::open(&path).unwrap()).unwrap();
    let tiff::decoder::DecodingResult::I16(reference) = dec.read_image().unwrap() else {
        panic!("int16 expected")
    };
    let r = read_inputs(std::slice::from_ref(&path), None, None).unwrap();
    let (w, h) = (r.width as usize, r.height as usize);
    assert_eq!(reference.len(), w * h);
    for row in 0..h {
        for col in 0..w {
            assert_eq!(
                r.heights[row * w + col],
                reference[(h - 1 - row) * w + col] as f32
            );
        }
    }
    let path = d.join("puget_sound/ps_height_1k.png");
    let old = vkterrain::dataset::load_png16(&path, 160.0, 0.1, None).unwrap();
    let r = read_inputs(std::slice::from_ref(&path), Some(160.0), Some(0.1)).unwrap();
    assert_eq!((r.width, r.height), (old.width, old.height));
    assert!(
        r.heights
            .iter()
            .zip(&old.heights)
            .all(|(a, b)| a.to_bits() == b.to_bits())
    );
}

/// A GeoTIFF in UTM (a plane, so its bilinear interpolation is exact) and a geographic SRTM
/// crop warped into one mosaic in the UTM CRS: inside the UTM input the mosaic is the plane;
/// elsewhere it is the bilinear SRTM height at the sample's longitude/latitude (PROJ in the
/// test as the oracle of the coordinates). Negative control: the SRTM oracle evaluated half a
/// sample off disagrees.
#[test]
fn utm_geotiff_and_geographic_srtm_warp_into_one_mosaic() {
    use gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};
    let Some(d) = data() else { return };
    let dir = tmpdir("warp");
    let raw = raw_hgt(&d.join("srtm/N48W125.hgt.zip"));
    // Crop: file rows 2900..3300 (about 48.19..48.08 N), cols 1800..2400 (-124.5..-124.33).
    let (c0, r0, cw, rh) = (1800usize, 2900usize, 600usize, 400usize);
    let crop = write_srtm_crop(&raw, (c0, r0, cw, rh), &dir.join("srtm_crop.tif"));
    let mut geo = SpatialRef::from_epsg(4326).unwrap();
    geo.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
    let mut utm = SpatialRef::from_epsg(32610).unwrap();
    utm.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
    let to_utm = CoordTransform::new(&geo, &utm).unwrap();
    let to_geo = CoordTransform::new(&utm, &geo).unwrap();
    let pt = |t: &CoordTransform, x: f64, y: f64| {
        let (mut xs, mut ys, mut zs) = ([x], [y], [0.0]);
        t.transform_coords(&mut xs, &mut ys, &mut zs).unwrap();
        (xs[0], ys[0])
    };
    // The UTM input: 120 x 120 samples of 30 m around the crop's centre, h = plane(E, N).
    let (ec, nc) = pt(&to_utm, -124.4167, 48.1389);
    let (e0, n_top) = (
        (ec / 30.0).round() * 30.0 - 1800.0,
        (nc / 30.0).round() * 30.0 + 1800.0,
    );
    let plane = |e: f64, n: f64| 500.0 + 0.01 * (e - e0) + 0.02 * (n - n_top);
    let utm_tif = dir.join("plane_utm10.tif");
    write_utm_plane(&utm_tif, &utm, (e0, n_top), plane);
    let m = read_inputs(&[utm_tif.clone(), crop.clone()], None, None).unwrap();
    assert!(
        m.provenance.iter().any(|l| l.contains("warped")),
        "{:?}",
        m.provenance
    );
    let g = m.georef.as_ref().unwrap();
    assert_eq!(g.crs.authority.as_deref(), Some("EPSG:32610"));
    // No coarser than the finest input: SRTM1's ~20.7 m east-west, UTM's 30 m north-south.
    let [sx, sy] = g.step();
    assert!(sx < 21.0 && sy <= 30.0 + 1e-9, "{sx} x {sy}");
    let srtm_at = |lon, lat, shift| srtm_bilinear(&raw, (c0, r0, cw, rh), lon, lat, shift);
    let (mut in_plane, mut in_srtm, mut worst_plane, mut worst_srtm, mut worst_shifted) =
        (0, 0, 0f64, 0f64, 0f64);
    let w = m.width as usize;
    for row in (0..m.height as usize).step_by(3) {
        for col in (0..w).step_by(3) {
            let v = m.heights[row * w + col] as f64;
            let [e, n] = g.at(col as f64, row as f64);
            let inside_utm = e > e0 + 30.0
                && e < e0 + 118.0 * 30.0
                && n < n_top - 30.0
                && n > n_top - 118.0 * 30.0;
            let outside_utm = e < e0 - 60.0
                || e > e0 + 121.0 * 30.0
                || n > n_top + 60.0
                || n < n_top - 121.0 * 30.0;
            if inside_utm {
                worst_plane = worst_plane.max((v - plane(e, n)).abs());
                in_plane += 1;
            } else if outside_utm {
                let (lon, lat) = pt(&to_geo, e, n);
                if let (Some(want), Some(shifted)) =
                    (srtm_at(lon, lat, 0.0), srtm_at(lon, lat, 0.5))
                {
                    if v.is_nan() {
                        continue;
                    }
                    worst_srtm = worst_srtm.max((v - want).abs());
                    worst_shifted = worst_shifted.max((v - shifted).abs());
                    in_srtm += 1;
                }
            }
        }
    }
    eprintln!(
        "plane: {in_plane} samples, worst {worst_plane:.2e} m; SRTM: {in_srtm} samples, worst {worst_srtm:.3} m (half a sample off: {worst_shifted:.1} m)"
    );
    assert!(in_plane > 500 && in_srtm > 5000, "{in_plane} {in_srtm}");
    assert!(worst_plane < 1e-3, "{worst_plane}");
    assert!(worst_srtm < 0.05, "{worst_srtm}");
    assert!(
        worst_shifted > 1.0,
        "the negative control should disagree: {worst_shifted}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Writes SRTM1 tile N48W125's samples `raw` in the window `(col, row, width, height)` as a
/// geographic (EPSG:4326) i16 GeoTIFF at `path`, voids as no-data.
fn write_srtm_crop(
    raw: &[i16],
    (c0, r0, cw, rh): (usize, usize, usize, usize),
    path: &Path,
) -> PathBuf {
    use gdal::spatial_ref::SpatialRef;
    let gtiff = gdal::DriverManager::get_driver_by_name("GTiff").unwrap();
    let mut ds = gtiff
        .create_with_band_type::<i16, _>(path, cw, rh, 1)
        .unwrap();
    let s = 1.0 / 3600.0;
    ds.set_geo_transform(&[
        -125.0 + (c0 as f64 - 0.5) * s,
        s,
        0.0,
        49.0 - (r0 as f64 - 0.5) * s,
        0.0,
        -s,
    ])
    .unwrap();
    ds.set_spatial_ref(&SpatialRef::from_epsg(4326).unwrap())
        .unwrap();
    let mut band = ds.rasterband(1).unwrap();
    band.set_no_data_value(Some(VOID as f64)).unwrap();
    let data: Vec<i16> = (0..rh)
        .flat_map(|r| raw[(r0 + r) * 3601 + c0..(r0 + r) * 3601 + c0 + cw].to_vec())
        .collect();
    band.write(
        (0, 0),
        (cw, rh),
        &mut gdal::raster::Buffer::new((cw, rh), data),
    )
    .unwrap();
    path.to_path_buf()
}

/// Writes 120 x 120 samples of 30 m in `utm`, the first at `(e0, n_top)`, of `plane(E, N)`
/// as an f32 GeoTIFF at `path`.
fn write_utm_plane(
    path: &Path,
    utm: &gdal::spatial_ref::SpatialRef,
    (e0, n_top): (f64, f64),
    plane: impl Fn(f64, f64) -> f64 + Copy,
) {
    let gtiff = gdal::DriverManager::get_driver_by_name("GTiff").unwrap();
    let mut ds = gtiff
        .create_with_band_type::<f32, _>(path, 120, 120, 1)
        .unwrap();
    ds.set_geo_transform(&[e0 - 15.0, 30.0, 0.0, n_top + 15.0, 0.0, -30.0])
        .unwrap();
    ds.set_spatial_ref(utm).unwrap();
    let data: Vec<f32> = (0..120)
        .flat_map(|r| {
            (0..120).map(move |c| plane(e0 + c as f64 * 30.0, n_top - r as f64 * 30.0) as f32)
        })
        .collect();
    ds.rasterband(1)
        .unwrap()
        .write(
            (0, 0),
            (120, 120),
            &mut gdal::raster::Buffer::new((120, 120), data),
        )
        .unwrap();
}

/// The bilinear height of SRTM1 tile N48W125's samples `raw` at `(lon, lat)`, `shift`
/// samples east of it (the negative control's offset), where its four samples lie inside
/// the crop window `(col, row, width, height)` (one sample in from its edges) and none is void.
fn srtm_bilinear(
    raw: &[i16],
    (c0, r0, cw, rh): (usize, usize, usize, usize),
    lon: f64,
    lat: f64,
    shift: f64,
) -> Option<f64> {
    let (fc, fr) = ((lon + 125.0) * 3600.0 + shift, (49.0 - lat) * 3600.0);
    let (c, r) = (fc.floor() as usize, fr.floor() as usize);
    if c < c0 + 1 || r < r0 + 1 || c + 2 >= c0 + cw || r + 2 >= r0 + rh {
        return None;
    }
    let v = |c: usize, r: usize| raw[r * 3601 + c];
    let k = [v(c, r), v(c + 1, r), v(c, r + 1), v(c + 1, r + 1)];
    if k.contains(&VOID) {
        return None;
    }
    let (tx, ty) = (fc - c as f64, fr - r as f64);
    let k = k.map(|x| x as f64);
    Some((k[0] * (1.0 - tx) + k[1] * tx) * (1.0 - ty) + (k[2] * (1.0 - tx) + k[3] * tx) * ty)
}

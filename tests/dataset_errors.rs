//! GeoTIFF variants and bad input: each error is one line naming the file and the problem.

use std::path::{Path, PathBuf};

use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, colortype};
use tiff::tags::Tag;
use vkterrain::dataset::preprocess::{self, Input, NoProgress, Options, read_inputs};
use vkterrain::dataset::{geotiff, srtm};

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vkt-err-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Expects an error mentioning the file name and every one of `words`, on one line.
fn expect_err<T: std::fmt::Debug>(r: vkterrain::Result<T>, file: &Path, words: &[&str]) {
    let e = r.unwrap_err().to_string();
    let name = file.file_name().unwrap().to_string_lossy();
    assert!(e.contains(&*name), "{e:?} does not name {name}");
    for w in words {
        assert!(e.contains(w), "{e:?} lacks {w:?}");
    }
    assert!(!e.contains('\n'), "{e:?} is not one line");
}

fn geokeys(model: u16, code: u16) -> Vec<u16> {
    let key = if model == 2 { 2048 } else { 3072 };
    vec![1, 1, 0, 2, 1024, 0, 1, model, key, 0, 1, code]
}

enum Samples<'a> {
    I16(&'a [i16]),
    U16(&'a [u16]),
    F32(&'a [f32]),
    U8(&'a [u8]),
    F64(&'a [f64]),
}

#[allow(clippy::too_many_arguments)]
fn write_tiff(
    path: &Path,
    w: u32,
    h: u32,
    data: Samples,
    compression: Compression,
    scale: [f64; 3],
    tie: [f64; 6],
    keys: &[u16],
    nodata: Option<&str>,
) {
    let file = std::fs::File::create(path).unwrap();
    let mut enc = TiffEncoder::new(file)
        .unwrap()
        .with_compression(compression);
    macro_rules! go {
        ($ct:ty, $d:expr) => {{
            let mut img = enc.new_image::<$ct>(w, h).unwrap();
            img.encoder()
                .write_tag(Tag::ModelPixelScaleTag, &scale[..])
                .unwrap();
            img.encoder()
                .write_tag(Tag::ModelTiepointTag, &tie[..])
                .unwrap();
            img.encoder()
                .write_tag(Tag::GeoKeyDirectoryTag, keys)
                .unwrap();
            if let Some(nd) = nodata {
                img.encoder().write_tag(Tag::GdalNodata, nd).unwrap();
            }
            img.write_data($d).unwrap();
        }};
    }
    match data {
        Samples::I16(d) => go!(colortype::GrayI16, d),
        Samples::U16(d) => go!(colortype::Gray16, d),
        Samples::F32(d) => go!(colortype::Gray32Float, d),
        Samples::U8(d) => go!(colortype::Gray8, d),
        Samples::F64(d) => go!(colortype::Gray64Float, d),
    }
}

const UTM_TIE: [f64; 6] = [0.0, 0.0, 0.0, 500_000.0, 4_000_000.0, 0.0];

#[test]
fn geotiff_sample_formats_and_compressions() {
    let dir = tmpdir("formats");
    let (w, h) = (37u32, 21u32);
    let vals: Vec<i16> = (0..w * h).map(|i| (i as i16 % 500) - 100).collect();
    for (k, comp) in [
        Compression::Uncompressed,
        Compression::Lzw,
        Compression::Deflate(DeflateLevel::Balanced),
    ]
    .into_iter()
    .enumerate()
    {
        let p = dir.join(format!("i16_{k}.tif"));
        write_tiff(
            &p,
            w,
            h,
            Samples::I16(&vals),
            comp,
            [10.0, 10.0, 0.0],
            UTM_TIE,
            &geokeys(1, 32633),
            Some("-100"),
        );
        let r = geotiff::read(&p, None).unwrap();
        assert_eq!((r.width, r.height, r.spacing), (w, h, [10.0, 10.0]));
        // Row 0 is south: the file's last row.
        for c in 0..w as usize {
            let want = vals[(h as usize - 1) * w as usize + c];
            let got = r.heights[c];
            if want == -100 {
                assert!(got.is_nan());
            } else {
                assert_eq!(got, want as f32);
            }
        }
        assert_eq!(r.georef.as_ref().unwrap().crs, "EPSG:32633");
        // PixelIsArea: sample centres are half a pixel inside the tiepoint corner.
        assert_eq!(
            r.georef.as_ref().unwrap().origin,
            [500_005.0, 4_000_000.0 - 5.0 - 200.0]
        );

        let u: Vec<u16> = vals.iter().map(|v| (*v + 200) as u16).collect();
        let p = dir.join(format!("u16_{k}.tif"));
        write_tiff(
            &p,
            w,
            h,
            Samples::U16(&u),
            comp,
            [10.0, 10.0, 0.0],
            UTM_TIE,
            &geokeys(1, 32633),
            None,
        );
        assert_eq!(
            geotiff::read(&p, None).unwrap().heights[3],
            u[(h as usize - 1) * w as usize + 3] as f32
        );

        let f: Vec<f32> = vals.iter().map(|v| *v as f32 + 0.25).collect();
        let p = dir.join(format!("f32_{k}.tif"));
        write_tiff(
            &p,
            w,
            h,
            Samples::F32(&f),
            comp,
            [10.0, 10.0, 0.0],
            UTM_TIE,
            &geokeys(1, 32633),
            None,
        );
        assert_eq!(
            geotiff::read(&p, None).unwrap().heights[4],
            f[(h as usize - 1) * w as usize + 4]
        );
    }
    // Geographic: spacing from latitude, never assumed. 3" at 45..~45.02 N.
    let p = dir.join("geo.tif");
    let tie = [0.0, 0.0, 0.0, 7.0, 45.0 + 20.0 / 1200.0, 0.0];
    let s = 1.0 / 1200.0;
    write_tiff(
        &p,
        w,
        h,
        Samples::I16(&vals),
        Compression::Uncompressed,
        [s, s, 0.0],
        tie,
        &geokeys(2, 4326),
        None,
    );
    let r = geotiff::read(&p, None).unwrap();
    assert!((r.spacing[1] - 92.6).abs() < 0.2, "{:?}", r.spacing);
    assert!((r.spacing[0] - 65.6).abs() < 0.2, "{:?}", r.spacing);
    assert_eq!(r.georef.unwrap().units, "degrees");
}

#[test]
fn bad_tiffs() {
    let dir = tmpdir("badtiff");
    let (w, h) = (16u32, 16u32);
    let keys = geokeys(1, 32633);
    let p = dir.join("u8.tif");
    write_tiff(
        &p,
        w,
        h,
        Samples::U8(&[7u8; 256]),
        Compression::Uncompressed,
        [1.0; 3],
        UTM_TIE,
        &keys,
        None,
    );
    expect_err(
        geotiff::read(&p, None),
        &p,
        &["unsupported TIFF sample format", "8-bit"],
    );
    let p = dir.join("f64.tif");
    write_tiff(
        &p,
        w,
        h,
        Samples::F64(&[7.0; 256]),
        Compression::Uncompressed,
        [1.0; 3],
        UTM_TIE,
        &keys,
        None,
    );
    expect_err(
        geotiff::read(&p, None),
        &p,
        &["unsupported TIFF sample format", "64-bit"],
    );
    let p = dir.join("packbits.tif");
    write_tiff(
        &p,
        w,
        h,
        Samples::I16(&[7; 256]),
        Compression::Packbits,
        [1.0; 3],
        UTM_TIE,
        &keys,
        None,
    );
    expect_err(
        geotiff::read(&p, None),
        &p,
        &["unsupported TIFF compression 32773"],
    );
    let mut f = vec![1.0f32; 256];
    f[37] = f32::NAN;
    let p = dir.join("nan.tif");
    write_tiff(
        &p,
        w,
        h,
        Samples::F32(&f),
        Compression::Uncompressed,
        [1.0; 3],
        UTM_TIE,
        &keys,
        None,
    );
    expect_err(geotiff::read(&p, None), &p, &["NaN", "col 5, row 2"]);
    // NaN declared as nodata is a void, not an error.
    write_tiff(
        &p,
        w,
        h,
        Samples::F32(&f),
        Compression::Uncompressed,
        [1.0; 3],
        UTM_TIE,
        &keys,
        Some("nan"),
    );
    assert_eq!(geotiff::read(&p, None).unwrap().void_count(), 1);
    f[37] = f32::INFINITY;
    let p = dir.join("inf.tif");
    write_tiff(
        &p,
        w,
        h,
        Samples::F32(&f),
        Compression::Uncompressed,
        [1.0; 3],
        UTM_TIE,
        &keys,
        None,
    );
    expect_err(geotiff::read(&p, None), &p, &["inf"]);
    // Truncated: half the file.
    let p = dir.join("ok.tif");
    write_tiff(
        &p,
        64,
        64,
        Samples::I16(&[3; 4096]),
        Compression::Uncompressed,
        [1.0; 3],
        UTM_TIE,
        &keys,
        None,
    );
    let bytes = std::fs::read(&p).unwrap();
    let t = dir.join("truncated.tif");
    std::fs::write(&t, &bytes[..bytes.len() / 2]).unwrap();
    expect_err(geotiff::read(&t, None), &t, &["TIFF"]);
    std::fs::write(&t, &bytes[..100]).unwrap();
    expect_err(geotiff::read(&t, None), &t, &["TIFF"]);
    // Entirely void.
    let p = dir.join("allvoid.tif");
    write_tiff(
        &p,
        w,
        h,
        Samples::I16(&[-9999; 256]),
        Compression::Uncompressed,
        [1.0; 3],
        UTM_TIE,
        &keys,
        Some("-9999"),
    );
    let out = dir.join("out");
    let r = preprocess::run(
        &Options {
            input: Input::Files(vec![p.clone()]),
            out: out.clone(),
            ..Default::default()
        },
        &mut NoProgress,
    );
    expect_err(r, &p, &["entirely void"]);
    assert!(!out.exists());
}

fn write_hgt(path: &Path, side: usize, f: impl Fn(usize, usize) -> i16) {
    let mut b = Vec::with_capacity(side * side * 2);
    for r in 0..side {
        for c in 0..side {
            b.extend_from_slice(&f(r, c).to_be_bytes());
        }
    }
    std::fs::write(path, b).unwrap();
}

#[test]
fn bad_srtm_and_mosaics() {
    let dir = tmpdir("badhgt");
    let t = dir.join("N10E010.hgt");
    std::fs::write(&t, vec![0u8; 1000]).unwrap();
    expect_err(
        srtm::read_tile(&t),
        &t,
        &["1000 bytes", "truncated or wrong size"],
    );
    std::fs::write(&t, vec![0u8; 1201 * 1201 * 2 + 2]).unwrap();
    expect_err(srtm::read_tile(&t), &t, &["not an SRTM tile"]);
    let bad_name = dir.join("tile.hgt");
    std::fs::write(&bad_name, vec![0u8; 1201 * 1201 * 2]).unwrap();
    expect_err(
        srtm::read_tile(&bad_name),
        &bad_name,
        &["south-west corner"],
    );
    // Truncated zip.
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/srtm/N49E011.hgt.zip");
    if data.is_file() {
        let bytes = std::fs::read(&data).unwrap();
        let z = dir.join("N49E011.hgt.zip");
        std::fs::write(&z, &bytes[..bytes.len() / 2]).unwrap();
        expect_err(srtm::read_tile(&z), &z, &["zip"]);
    } else {
        eprintln!("note: shared data absent, truncated-zip case skipped");
    }
    // Mosaics.
    let a = dir.join("N10E010.hgt");
    write_hgt(&a, 1201, |r, c| (r + c) as i16);
    let gap = dir.join("N12E010.hgt");
    write_hgt(&gap, 1201, |_, _| 5);
    expect_err(
        srtm::mosaic(&[a.clone(), gap.clone()]),
        &a,
        &["inconsistent mosaic", "gap", "N11E010"],
    );
    expect_err(
        srtm::mosaic(&[a.clone(), a.clone()]),
        &a,
        &["inconsistent mosaic", "overlaps"],
    );
    let fine = dir.join("N11E010.hgt");
    write_hgt(&fine, 3601, |_, _| 5);
    expect_err(
        srtm::mosaic(&[a.clone(), fine.clone()]),
        &fine,
        &["different resolutions"],
    );
    // A consistent pair works and is 1201 x 2401; a wholly void tile is an error.
    let b = dir.join("N11E010.hgt");
    write_hgt(&b, 1201, |r, c| if r == 1200 { c as i16 } else { 9 });
    let m = srtm::mosaic(&[a.clone(), b.clone()]).unwrap();
    assert_eq!((m.width, m.height), (1201, 2401));
    let v = dir.join("S01W001.hgt");
    write_hgt(&v, 1201, |_, _| srtm::VOID);
    let r = preprocess::run(
        &Options {
            input: Input::Files(vec![v.clone()]),
            out: dir.join("o"),
            ..Default::default()
        },
        &mut NoProgress,
    );
    expect_err(r, &v, &["entirely void"]);
    // Mixed and unknown input types.
    let x = dir.join("dem.xyz");
    std::fs::write(&x, "1 2 3").unwrap();
    expect_err(
        read_inputs(std::slice::from_ref(&x), None, None),
        &x,
        &["unknown input type"],
    );
}

#[test]
fn imagery_must_cover_the_dem() {
    let dir = tmpdir("albedo");
    let dem = dir.join("N10E010.hgt");
    write_hgt(&dem, 1201, |r, c| ((r * 7 + c * 3) % 400) as i16);
    let img = dir.join("wide.png");
    image::RgbImage::from_pixel(300, 100, image::Rgb([10, 20, 30]))
        .save(&img)
        .unwrap();
    let r = preprocess::run(
        &Options {
            input: Input::Files(vec![dem.clone()]),
            out: dir.join("o"),
            albedo: Some(img.clone()),
            center_size: 512,
            ..Default::default()
        },
        &mut NoProgress,
    );
    expect_err(r, &img, &["does not cover the DEM"]);
    // With a world file placing it beside the DEM: also refused.
    let img2 = dir.join("square.png");
    image::RgbImage::from_pixel(100, 100, image::Rgb([10, 20, 30]))
        .save(&img2)
        .unwrap();
    std::fs::write(dir.join("square.pgw"), "0.01\n0\n0\n-0.01\n20.0\n11.0\n").unwrap();
    let r = preprocess::run(
        &Options {
            input: Input::Files(vec![dem.clone()]),
            out: dir.join("o"),
            albedo: Some(img2.clone()),
            center_size: 512,
            ..Default::default()
        },
        &mut NoProgress,
    );
    expect_err(r, &img2, &["does not cover the DEM"]);
    // Covering world file: accepted. The DEM's sample centres span 10..11 E, 10..11 N
    // (x 0.0025-wide pixels centred from 9.99875).
    std::fs::write(
        dir.join("square.pgw"),
        "0.0102\n0\n0\n-0.0102\n9.995\n11.005\n",
    )
    .unwrap();
    preprocess::run(
        &Options {
            input: Input::Files(vec![dem]),
            out: dir.join("o"),
            albedo: Some(img2),
            center_size: 512,
            ..Default::default()
        },
        &mut NoProgress,
    )
    .unwrap();
}

#[test]
fn cli_prints_one_line_and_exits_1() {
    let dir = tmpdir("cli");
    let t = dir.join("N10E010.hgt");
    std::fs::write(&t, vec![0u8; 1000]).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .args([
            "preprocess",
            t.to_str().unwrap(),
            "--out",
            dir.join("o").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().last().unwrap();
    assert!(
        last.starts_with("error: ") && last.contains("N10E010.hgt") && last.contains("truncated"),
        "{err}"
    );
    assert!(!dir.join("o").exists() && !dir.join("o.partial").exists());
}

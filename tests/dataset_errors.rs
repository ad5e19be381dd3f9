//! Inputs through GDAL and bad input: each error is one line naming the file and the problem,
//! nothing is left half-written, and no input costs memory proportional to a size it merely
//! claims (the list of probed failures, each a test).

mod common;

use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, colortype};
use tiff::tags::Tag;
use vkterrain::dataset::output::PartialDir;
use vkterrain::dataset::preprocess::{self, Input, NoProgress, Options, read_inputs};
use vkterrain::dataset::procedural::ProceduralParams;
use vkterrain::dataset::tiles::Dataset;

const VOID: i16 = -32768;

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

/// [`write_tiff`] in UTM zone 33N (EPSG:32633) at [`UTM_TIE`], with square samples of
/// `spacing` metres.
fn write_utm(
    path: &Path,
    (w, h): (u32, u32),
    data: Samples,
    compression: Compression,
    spacing: f64,
    nodata: Option<&str>,
) {
    let keys = geokeys(1, 32633);
    let scale = [spacing, spacing, 0.0];
    write_tiff(path, w, h, data, compression, scale, UTM_TIE, &keys, nodata);
}

fn read1(p: &Path) -> vkterrain::Result<vkterrain::dataset::source::Raster> {
    read_inputs(&[p.to_path_buf()], None, None)
}

/// Every sample type and compression GDAL hands us gives the file's values (row 0 = south),
/// and the georeferencing lands on sample centres.
#[test]
fn geotiff_sample_formats_and_compressions() {
    let _memory = shared();
    let dir = tmpdir("formats");
    let (w, h) = (37u32, 21u32);
    let vals: Vec<i16> = (0..w * h).map(|i| (i as i16 % 500) - 100).collect();
    let south = |v: &[f32], c: usize| v[c];
    let file_last = |c: usize| (h as usize - 1) * w as usize + c;
    for (k, comp) in [
        Compression::Uncompressed,
        Compression::Lzw,
        Compression::Deflate(DeflateLevel::Balanced),
        Compression::Packbits,
    ]
    .into_iter()
    .enumerate()
    {
        let p = dir.join(format!("i16_{k}.tif"));
        write_utm(&p, (w, h), Samples::I16(&vals), comp, 10.0, Some("-100"));
        let r = read1(&p).unwrap();
        assert_eq!((r.width, r.height, r.spacing), (w, h, [10.0, 10.0]));
        for c in 0..w as usize {
            let want = vals[file_last(c)];
            let got = south(&r.heights, c);
            if want == -100 {
                assert!(got.is_nan());
            } else {
                assert_eq!(got, want as f32);
            }
        }
        let g = r.georef.as_ref().unwrap();
        assert_eq!(g.crs.authority.as_deref(), Some("EPSG:32633"));
        // PixelIsArea: sample centres are half a pixel inside the tiepoint corner.
        assert_eq!(g.origin(), [500_005.0, 4_000_000.0 - 5.0 - 200.0]);

        let u: Vec<u16> = vals.iter().map(|v| (*v + 200) as u16).collect();
        let p = dir.join(format!("u16_{k}.tif"));
        write_utm(&p, (w, h), Samples::U16(&u), comp, 10.0, None);
        assert_eq!(read1(&p).unwrap().heights[3], u[file_last(3)] as f32);

        let f: Vec<f32> = vals.iter().map(|v| *v as f32 + 0.25).collect();
        let p = dir.join(format!("f32_{k}.tif"));
        write_utm(&p, (w, h), Samples::F32(&f), comp, 10.0, None);
        assert_eq!(read1(&p).unwrap().heights[4], f[file_last(4)]);
    }
    // 8-bit and 64-bit samples (refused by the hand-written reader) come through GDAL.
    let p = dir.join("u8.tif");
    let b: Vec<u8> = (0..w * h).map(|i| (i % 251) as u8).collect();
    write_utm(
        &p,
        (w, h),
        Samples::U8(&b),
        Compression::Uncompressed,
        10.0,
        None,
    );
    assert_eq!(read1(&p).unwrap().heights[5], b[file_last(5)] as f32);
    let p = dir.join("f64.tif");
    let d: Vec<f64> = (0..w * h).map(|i| i as f64 * 0.5).collect();
    write_utm(
        &p,
        (w, h),
        Samples::F64(&d),
        Compression::Uncompressed,
        10.0,
        None,
    );
    assert_eq!(read1(&p).unwrap().heights[6], d[file_last(6)] as f32);
    // Geographic: the native grid in degrees is kept; the local spacing is derived at the
    // centre latitude, never assumed. 3" at 45..~45.02 N.
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
    let r = read1(&p).unwrap();
    assert!((r.spacing[1] - 92.6).abs() < 0.2, "{:?}", r.spacing);
    assert!((r.spacing[0] - 65.6).abs() < 0.2, "{:?}", r.spacing);
    let g = r.georef.unwrap();
    assert_eq!(g.crs.units, "degree");
    assert_eq!(g.step(), [s, s]);
    assert!((g.origin()[0] - (7.0 + s / 2.0)).abs() < 1e-12);
}

#[test]
fn bad_tiffs() {
    let _memory = shared();
    let dir = tmpdir("badtiff");
    let (w, h) = (16u32, 16u32);
    let keys = geokeys(1, 32633);
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
    expect_err(read1(&p), &p, &["NaN", "col 5, row 2"]);
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
    assert_eq!(read1(&p).unwrap().void_count(), 1);
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
    expect_err(read1(&p), &p, &["inf"]);
    // Truncated: half the file, and only its first 100 bytes.
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
    expect_err(read1(&t), &t, &[]);
    std::fs::write(&t, &bytes[..100]).unwrap();
    expect_err(read1(&t), &t, &["GDAL"]);
    // Entirely void: an error, and no data set.
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
        &NoProgress,
    );
    expect_err(r, &p, &["entirely void"]);
    assert!(!out.exists() && !dir.join("out.partial").exists());
    // Several bands: not a DEM.
    let p = dir.join("rgb.png");
    image::RgbImage::from_pixel(8, 8, image::Rgb([1, 2, 3]))
        .save(&p)
        .unwrap();
    expect_err(read1(&p), &p, &["3 bands"]);
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
    let _memory = shared();
    let dir = tmpdir("badhgt");
    let t = dir.join("N10E010.hgt");
    std::fs::write(&t, vec![0u8; 1000]).unwrap();
    expect_err(read1(&t), &t, &["1000 bytes", "truncated or wrong size"]);
    std::fs::write(&t, vec![0u8; 1201 * 1201 * 2 + 2]).unwrap();
    expect_err(read1(&t), &t, &["not an SRTM tile"]);
    let bad_name = dir.join("tile.hgt");
    std::fs::write(&bad_name, vec![0u8; 1201 * 1201 * 2]).unwrap();
    expect_err(read1(&bad_name), &bad_name, &["south-west corner"]);
    // Truncated zip.
    if let Some(d) = common::shared_data() {
        let bytes = std::fs::read(d.join("srtm/N49E011.hgt.zip")).unwrap();
        let z = dir.join("N49E011.hgt.zip");
        std::fs::write(&z, &bytes[..bytes.len() / 2]).unwrap();
        expect_err(read1(&z), &z, &["zip"]);
    }
    // Mosaics.
    let a = dir.join("N10E010.hgt");
    write_hgt(&a, 1201, |r, c| (r + c) as i16);
    let gap = dir.join("N12E010.hgt");
    write_hgt(&gap, 1201, |_, _| 5);
    expect_err(
        read_inputs(&[a.clone(), gap.clone()], None, None),
        &a,
        &["inconsistent mosaic", "gap", "N11E010"],
    );
    expect_err(
        read_inputs(&[a.clone(), a.clone()], None, None),
        &a,
        &["inconsistent mosaic", "overlaps"],
    );
    // A consistent pair is pasted sample for sample: 1201 x 2401, shared row from the first
    // input valid there.
    let b = dir.join("N11E010.hgt");
    write_hgt(
        &b,
        1201,
        |r, c| if r == 1200 { VOID } else { 9 + c as i16 % 7 },
    );
    let m = read_inputs(&[b.clone(), a.clone()], None, None).unwrap();
    assert_eq!((m.width, m.height), (1201, 2401));
    // Row 1200 (shared): b's copy is void there, so a's (file row 0: 0 + c) is taken.
    assert_eq!(m.heights[1200 * 1201 + 17], 17.0);
    assert_eq!(m.heights[2400 * 1201 + 3], 9.0 + 3.0);
    assert!(m.provenance.iter().any(|l| l.contains("no resampling")));
    // Different resolutions: warped to the finer one (1"), not pasted.
    let fine = dir.join("N11E011.hgt");
    write_hgt(&fine, 3601, |_, _| 5);
    let coarse = dir.join("N11E010.hgt");
    write_hgt(&coarse, 1201, |_, _| 7);
    let m = read_inputs(&[coarse.clone(), fine.clone()], None, None).unwrap();
    assert!(
        m.provenance.iter().any(|l| l.contains("warped")),
        "{:?}",
        m.provenance
    );
    let step = m.georef.as_ref().unwrap().step();
    assert!((step[0] - 1.0 / 3600.0).abs() < 1e-12, "{step:?}");
    // Wholly void tile: an error.
    let v = dir.join("S01W001.hgt");
    write_hgt(&v, 1201, |_, _| VOID);
    let r = preprocess::run(
        &Options {
            input: Input::Files(vec![v.clone()]),
            out: dir.join("o"),
            ..Default::default()
        },
        &NoProgress,
    );
    expect_err(r, &v, &["entirely void"]);
    // Not a raster.
    let x = dir.join("dem.xyz");
    std::fs::write(&x, "1 2 3").unwrap();
    expect_err(read1(&x), &x, &[]);
}

#[test]
fn imagery_must_cover_the_dem() {
    let _memory = shared();
    let dir = tmpdir("albedo");
    let dem = dir.join("N10E010.hgt");
    write_hgt(&dem, 1201, |r, c| ((r * 7 + c * 3) % 400) as i16);
    let img = dir.join("wide.png");
    image::RgbImage::from_pixel(300, 100, image::Rgb([10, 20, 30]))
        .save(&img)
        .unwrap();
    let run = |albedo: &Path| {
        preprocess::run(
            &Options {
                input: Input::Files(vec![dem.clone()]),
                out: dir.join("o"),
                albedo: Some(albedo.to_path_buf()),
                center_size: 512,
                force: true,
                ..Default::default()
            },
            &NoProgress,
        )
    };
    expect_err(run(&img), &img, &["does not cover the DEM"]);
    // With a world file placing it beside the DEM: also refused.
    let img2 = dir.join("square.png");
    image::RgbImage::from_pixel(100, 100, image::Rgb([10, 20, 30]))
        .save(&img2)
        .unwrap();
    std::fs::write(dir.join("square.pgw"), "0.01\n0\n0\n-0.01\n20.0\n11.0\n").unwrap();
    expect_err(run(&img2), &img2, &["does not cover the DEM"]);
    // Covering world file: accepted. The DEM's sample centres span 10..11 E, 10..11 N.
    std::fs::write(
        dir.join("square.pgw"),
        "0.0102\n0\n0\n-0.0102\n9.995\n11.005\n",
    )
    .unwrap();
    run(&img2).unwrap();
}

/// A CLI run: exit code, stderr, peak resident set of the child (KiB).
struct CliRun {
    code: Option<i32>,
    stderr: String,
    max_rss_kib: i64,
}

/// Tests that measure a child's peak RSS run alone (`exclusive`), the others together
/// (`shared`): a forked child's peak RSS counts the test process's resident memory at the fork,
/// which the other tests' data sets would inflate (seen: 245-300 MiB for a refusal that takes 42).
static MEMORY: std::sync::RwLock<()> = std::sync::RwLock::new(());

fn shared() -> std::sync::RwLockReadGuard<'static, ()> {
    MEMORY.read().unwrap_or_else(|e| e.into_inner())
}

fn exclusive() -> std::sync::RwLockWriteGuard<'static, ()> {
    MEMORY.write().unwrap_or_else(|e| e.into_inner())
}

/// Runs `vkterrain ARGS` with optional limits (address space, file size in bytes) and reads
/// its peak RSS from `wait4`.
fn cli(args: &[&str], as_limit: Option<u64>, fsize_limit: Option<u64>) -> CliRun {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_vkterrain"));
    cmd.args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .env("RUST_LOG", "off");
    unsafe {
        cmd.pre_exec(move || {
            let set = |res, v: u64| {
                let l = libc::rlimit {
                    rlim_cur: v,
                    rlim_max: v,
                };
                libc::setrlimit(res, &l);
            };
            if let Some(v) = as_limit {
                set(libc::RLIMIT_AS, v);
            }
            if let Some(v) = fsize_limit {
                // Writes past the limit fail with EFBIG instead of killing the process.
                libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
                set(libc::RLIMIT_FSIZE, v);
            }
            Ok(())
        });
    }
    let mut child = cmd.spawn().unwrap();
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    let mut status = 0;
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let pid = child.id() as libc::pid_t;
    let r = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    assert_eq!(r, pid);
    std::mem::forget(child);
    CliRun {
        code: libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status)),
        stderr,
        max_rss_kib: usage.ru_maxrss,
    }
}

fn last_line(r: &CliRun) -> &str {
    r.stderr.lines().last().unwrap_or("")
}

/// Exit 1 with one `error:` line containing `words`, peak RSS under 200 MiB, nothing at
/// `out` (nor its partial directory).
fn assert_refused_cheaply(r: &CliRun, words: &[&str], out: &Path) {
    assert_eq!(r.code, Some(1), "{}", r.stderr);
    let line = last_line(r);
    assert!(line.starts_with("error: "), "{}", r.stderr);
    for w in words {
        assert!(line.contains(w), "{line:?} lacks {w:?}");
    }
    assert!(r.max_rss_kib < 200 * 1024, "peak RSS {} KiB", r.max_rss_kib);
    assert!(!out.exists(), "{} exists", out.display());
    let partial = out.with_file_name(format!(
        "{}.partial",
        out.file_name().unwrap().to_string_lossy()
    ));
    assert!(!partial.exists(), "{} exists", partial.display());
}

#[test]
fn cli_prints_one_line_and_exits_1() {
    let _memory = exclusive();
    let dir = tmpdir("cli");
    let t = dir.join("N10E010.hgt");
    std::fs::write(&t, vec![0u8; 1000]).unwrap();
    let out = dir.join("o");
    let r = cli(
        &[
            "preprocess",
            t.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        None,
        None,
    );
    assert_refused_cheaply(&r, &["N10E010.hgt", "truncated"], &out);
}

/// The probed sizes: a procedural size of 2^32 - 1 (grew to 12 GB), an `.hgt` that is
/// /dev/zero (8.4 GB), a 2 MB zip holding a 2 GiB entry (2.1 GB), a GeoTIFF whose header
/// claims 200000² samples: each refused before reading, within 200 MiB (and 2 GiB of address
/// space for the first three, so an attempt to allocate would fail loudly).
#[test]
fn absurd_sizes_are_refused_before_reading_with_bounded_memory() {
    let _memory = exclusive();
    let dir = tmpdir("absurd");
    let out = dir.join("o");
    let o = out.to_str().unwrap();
    let gib2 = Some(2u64 << 30);
    let r = cli(
        &[
            "preprocess",
            "--procedural",
            "--size",
            "4294967295",
            "--out",
            o,
        ],
        gib2,
        None,
    );
    assert_refused_cheaply(&r, &["--size", "4294967295", "16777217"], &out);
    // Within the format's limit but larger than any disk: the space check, before writing.
    let r = cli(
        &[
            "preprocess",
            "--procedural",
            "--size",
            "16777217",
            "--out",
            o,
        ],
        gib2,
        None,
    );
    assert_refused_cheaply(&r, &["needs", "PiB on disk", "free"], &out);

    let zero = dir.join("N10E010.hgt");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    let r = cli(
        &["preprocess", zero.to_str().unwrap(), "--out", o],
        gib2,
        None,
    );
    assert_refused_cheaply(&r, &["N10E010.hgt", "not a regular file"], &out);

    // 2 GiB of zeros deflate to about 2 MB.
    let zip = dir.join("N11E010.hgt.zip");
    {
        use std::io::Write;
        let mut z = zip::ZipWriter::new(std::fs::File::create(&zip).unwrap());
        let opts = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated)
            .large_file(true);
        z.start_file("N11E010.hgt", opts).unwrap();
        let chunk = vec![0u8; 1 << 20];
        for _ in 0..2048 {
            z.write_all(&chunk).unwrap();
        }
        z.finish().unwrap();
    }
    assert!(std::fs::metadata(&zip).unwrap().len() < 4 << 20);
    let r = cli(
        &["preprocess", zip.to_str().unwrap(), "--out", o],
        gib2,
        None,
    );
    assert_refused_cheaply(
        &r,
        &["N11E010.hgt.zip", "2147483648 bytes", "not an SRTM tile"],
        &out,
    );
}

/// A header that claims more than memory holds is refused from its numbers, before any row is
/// read (needs GDAL to write the sparse BigTIFF fixture).
#[cfg(feature = "gdal")]
#[test]
fn a_raster_claiming_200000_squared_samples_is_refused_from_its_header() {
    let _memory = exclusive();
    let dir = tmpdir("claims");
    let out = dir.join("o");
    let o = out.to_str().unwrap();
    // A deflated GeoTIFF claiming 200000 x 200000 int16 samples (written as one small strip
    // through a lying header is not possible with the encoder; a sparse BigTIFF through GDAL
    // is): refused by the memory check from the header's numbers, before any row is read.
    let big = dir.join("claims.tif");
    {
        let drv = gdal::DriverManager::get_driver_by_name("GTiff").unwrap();
        let opts = gdal::raster::RasterCreationOptions::from_iter([
            "COMPRESS=DEFLATE",
            "SPARSE_OK=TRUE",
            "BIGTIFF=YES",
            "TILED=YES",
            "BLOCKXSIZE=4096",
            "BLOCKYSIZE=4096",
        ]);
        let mut ds = drv
            .create_with_band_type_with_options::<i16, _>(&big, 200_000, 200_000, 1, &opts)
            .unwrap();
        ds.set_geo_transform(&[500000.0, 1.0, 0.0, 4e6, 0.0, -1.0])
            .unwrap();
        ds.set_spatial_ref(&gdal::spatial_ref::SpatialRef::from_epsg(32633).unwrap())
            .unwrap();
    }
    assert!(std::fs::metadata(&big).unwrap().len() < 1 << 20);
    let r = cli(
        &["preprocess", big.to_str().unwrap(), "--out", o],
        None,
        None,
    );
    assert_refused_cheaply(&r, &["claims.tif", "200000x200000", "memory"], &out);
}

fn procedural(out: &Path, size: u32, force: bool) -> Options {
    Options {
        input: Input::Procedural(ProceduralParams {
            size,
            ..Default::default()
        }),
        out: out.to_path_buf(),
        center_size: 64,
        force,
        ..Default::default()
    }
}

/// `--force` replaces a data set and nothing else: not a non-empty directory of other files
/// (it deleted one, subfolders included), not a regular file (it built everything, failed,
/// and left a complete-looking `.partial`).
#[test]
fn force_replaces_only_datasets() {
    let _memory = shared();
    let dir = tmpdir("force");
    let other = dir.join("photos");
    std::fs::create_dir_all(other.join("2024")).unwrap();
    std::fs::write(other.join("2024/a.jpg"), b"precious").unwrap();
    let e = preprocess::run(&procedural(&other, 65, true), &NoProgress);
    expect_err(e, &other, &["not a vkterrain data set", "refusing"]);
    assert_eq!(
        std::fs::read(other.join("2024/a.jpg")).unwrap(),
        b"precious"
    );
    assert!(!dir.join("photos.partial").exists());

    let file = dir.join("notes.txt");
    std::fs::write(&file, b"keep").unwrap();
    let e = preprocess::run(&procedural(&file, 65, true), &NoProgress);
    expect_err(e, &file, &["not a directory"]);
    assert_eq!(std::fs::read(&file).unwrap(), b"keep");
    assert!(!dir.join("notes.txt.partial").exists());

    // A data set: refused without --force, replaced with it.
    let ds = dir.join("ds");
    preprocess::run(&procedural(&ds, 65, false), &NoProgress).unwrap();
    let e = preprocess::run(&procedural(&ds, 129, false), &NoProgress);
    expect_err(e, &ds, &["already exists", "--force"]);
    preprocess::run(&procedural(&ds, 129, true), &NoProgress).unwrap();
    assert_eq!(Dataset::open(&ds).unwrap().manifest.width, 129);
    // An empty directory is fine without --force.
    let empty = dir.join("empty");
    std::fs::create_dir(&empty).unwrap();
    preprocess::run(&procedural(&empty, 65, false), &NoProgress).unwrap();
}

/// A write that fails mid-run (EFBIG from a file-size limit, as "No space left on device"
/// would) removes `<out>.partial`: nothing keeps the disk full. The positive control: the same
/// run without the limit succeeds.
#[test]
fn a_failed_write_removes_the_partial_directory() {
    let _memory = shared();
    let dir = tmpdir("efbig");
    let out = dir.join("o");
    let args = [
        "preprocess",
        "--procedural",
        "--size",
        "1025",
        "--node-size",
        "64",
        "--out",
        out.to_str().unwrap(),
    ];
    let r = cli(&args, None, Some(1 << 20));
    assert_refused_cheaply(&r, &["File too large"], &out);
    let r = cli(&args, None, None);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(Dataset::open(&out).is_ok());
}

/// Two runs on one `--out`: the second is refused while the first holds the lock (it used to
/// delete the first's work); a stale partial directory (its run killed) is cleaned up.
#[test]
fn concurrent_runs_on_one_out_are_locked() {
    let _memory = shared();
    let dir = tmpdir("lock");
    let out = dir.join("o");
    let held = PartialDir::claim(&out).unwrap();
    std::fs::write(held.path.join("L0.bin"), b"the first run's work").unwrap();
    let e = preprocess::run(&procedural(&out, 65, false), &NoProgress);
    expect_err(
        e,
        Path::new("o.partial"),
        &["another vkterrain preprocess", "lock"],
    );
    assert_eq!(
        std::fs::read(held.path.join("L0.bin")).unwrap(),
        b"the first run's work"
    );
    drop(held);
    assert!(
        !dir.join("o.partial").exists(),
        "a dropped claim removes its directory"
    );
    // A stale partial directory without a held lock (a killed run) is replaced.
    std::fs::create_dir_all(dir.join("o.partial")).unwrap();
    std::fs::write(dir.join("o.partial/L0.bin"), b"stale").unwrap();
    preprocess::run(&procedural(&out, 65, false), &NoProgress).unwrap();
    assert!(Dataset::open(&out).is_ok());
    assert!(!dir.join("o.partial").exists());
    // Two processes: the second run starts while the first is writing.
    let out2 = dir.join("o2");
    let mut first = Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .args([
            "preprocess",
            "--procedural",
            "--size",
            "2049",
            "--node-size",
            "64",
            "--threads",
            "1",
            "--out",
            out2.to_str().unwrap(),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let lock = dir.join("o2.partial/.preprocess.lock");
    let t = std::time::Instant::now();
    while !lock.exists() && t.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    assert!(lock.exists(), "the first run never created its lock");
    let second = cli(
        &[
            "preprocess",
            "--procedural",
            "--size",
            "65",
            "--out",
            out2.to_str().unwrap(),
        ],
        None,
        None,
    );
    assert_eq!(second.code, Some(1), "{}", second.stderr);
    assert!(
        last_line(&second).contains("another vkterrain preprocess is writing"),
        "{}",
        second.stderr
    );
    assert!(first.wait().unwrap().success());
    assert_eq!(Dataset::open(&out2).unwrap().manifest.width, 2049);
}

/// Geometry no earth has: a geographic tie point at 95 deg, a pixel scale of 1e-300, negative
/// spacing in a manifest (it rendered as `2x1025 samples`), manifest entries pointing outside
/// the data set.
#[test]
fn invalid_geometry_and_manifests_are_refused() {
    let _memory = shared();
    let dir = tmpdir("geometry");
    let vals = vec![100i16; 64];
    let p = dir.join("lat95.tif");
    write_tiff(
        &p,
        8,
        8,
        Samples::I16(&vals),
        Compression::Uncompressed,
        [0.001, 0.001, 0.0],
        [0.0, 0.0, 0.0, 7.0, 95.0, 0.0],
        &geokeys(2, 4326),
        None,
    );
    expect_err(read1(&p), &p, &["latitudes", "outside -90..90"]);
    let p = dir.join("tiny.tif");
    write_utm(
        &p,
        (8, 8),
        Samples::I16(&vals),
        Compression::Uncompressed,
        1e-300,
        None,
    );
    expect_err(read1(&p), &p, &["step"]);

    let ds = dir.join("ds");
    preprocess::run(&procedural(&ds, 129, false), &NoProgress).unwrap();
    let mpath = ds.join("manifest.json");
    let good = std::fs::read_to_string(&mpath).unwrap();
    let mutate = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
        f(&mut v);
        std::fs::write(&mpath, serde_json::to_string(&v).unwrap()).unwrap();
        Dataset::open(&ds)
    };
    expect_err(
        mutate(&|v| v["spacing"] = serde_json::json!([-30.0, 30.0])),
        &mpath,
        &["spacing"],
    );
    expect_err(
        mutate(&|v| v["levels"][0]["file"] = "../../etc/passwd".into()),
        &mpath,
        &["../../etc/passwd", "inside the data set"],
    );
    expect_err(
        mutate(&|v| v["tile_stats"][0]["file"] = "/etc/shadow".into()),
        &mpath,
        &["/etc/shadow", "inside the data set"],
    );
    expect_err(mutate(&|v| v["width"] = 2.into()), &mpath, &["extent"]);
    expect_err(
        mutate(&|v| v["version"] = 1.into()),
        &mpath,
        &["version 1", "vkterrain preprocess"],
    );
    // The unmodified manifest opens (the mutations above are what fails).
    assert!(mutate(&|_| {}).is_ok());
}

/// What a user who points a config at the wrong thing reads.
#[test]
fn tiles_datasets_say_how_to_build_one() {
    let _memory = shared();
    let dir = tmpdir("tiles-msg");
    let tif = dir.join("dem.tif");
    write_utm(
        &tif,
        (8, 8),
        Samples::I16(&[1; 64]),
        Compression::Uncompressed,
        1.0,
        None,
    );
    let e = Dataset::open(&tif).unwrap_err().to_string();
    assert!(
        e.contains("dem.tif")
            && e.contains("vkterrain preprocess")
            && !e.contains("interrupted preprocess leaves none"),
        "{e}"
    );
    let e = Dataset::open(&dir).unwrap_err().to_string();
    assert!(
        e.contains("no manifest.json") && e.contains("vkterrain preprocess"),
        "{e}"
    );
    // A config with a path but no kind does not render procedural terrain.
    let cfg = dir.join("c.toml");
    std::fs::write(&cfg, "[dataset]\npath = \"ds\"\n").unwrap();
    let e = vkterrain::config::Config::load(Some(&cfg))
        .and_then(|c| c.validate().map(|()| c))
        .unwrap_err()
        .to_string();
    assert!(e.contains("kind") && e.contains("tiles"), "{e}");
}

/// Data that looks wrong is warned about (one line each) and processed: int16 without nodata
/// but with -32768 samples (taken as voids), Web Mercator metres, heights outside -500..9000 m.
#[test]
fn suspicious_data_draws_one_line_warnings() {
    let _memory = shared();
    let dir = tmpdir("warn");
    let mut vals = vec![120i16; 400];
    vals[7] = VOID;
    vals[8] = VOID;
    let p = dir.join("nodata_missing.tif");
    write_utm(
        &p,
        (20, 20),
        Samples::I16(&vals),
        Compression::Uncompressed,
        30.0,
        None,
    );
    let r = read1(&p).unwrap();
    assert_eq!(r.void_count(), 2);
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("-32768") && w.contains("2 samples")),
        "{:?}",
        r.warnings
    );
    // The same file with a nodata tag: no warning.
    write_utm(
        &p,
        (20, 20),
        Samples::I16(&vals),
        Compression::Uncompressed,
        30.0,
        Some("-32768"),
    );
    assert!(read1(&p).unwrap().warnings.is_empty());

    let p = dir.join("merc.tif");
    let tie = [0.0, 0.0, 0.0, 1_000_000.0, 5_500_000.0, 0.0];
    write_tiff(
        &p,
        20,
        20,
        Samples::I16(&[300; 400]),
        Compression::Uncompressed,
        [100.0, 100.0, 0.0],
        tie,
        &geokeys(1, 3857),
        None,
    );
    let r = read1(&p).unwrap();
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("EPSG:3857") && w.contains("not ground metres")),
        "{:?}",
        r.warnings
    );
    // Ground spacing = 100 m x cos(lat) at the centre (y = 5.5e6 - 1000 m), latitude from the
    // spherical Mercator inverse written out here (the oracle; the code goes through PROJ).
    let lat = ((5.5e6 - 1000.0) / 6_378_137.0f64).sinh().atan();
    assert!(
        (r.spacing[0] - 100.0 * lat.cos()).abs() < 1e-6,
        "{:?}",
        r.spacing
    );
    assert_eq!(r.spacing[0], r.spacing[1]);

    let p = dir.join("feet.tif");
    write_utm(
        &p,
        (20, 20),
        Samples::I16(&[12000; 400]),
        Compression::Uncompressed,
        30.0,
        None,
    );
    let out = dir.join("o");
    let s = preprocess::run(
        &Options {
            input: Input::Files(vec![p.clone()]),
            out: out.clone(),
            center_size: 16,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("400 heights outside -500..9000 m")),
        "{:?}",
        s.warnings
    );
    assert_eq!(Dataset::open(&out).unwrap().manifest.warnings, s.warnings);
}

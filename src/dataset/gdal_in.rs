//! Reading DEMs through GDAL: any single-band raster GDAL opens (GeoTIFF/COG, SRTM HGT and
//! `.hgt.zip`, netCDF, VRT, IMG, JPEG2000, PNG, ...), one or several forming a mosaic, in any
//! CRS PROJ knows.
//!
//! - Nodata from the band's metadata marks voids (`NaN`); scale and offset are applied.
//! - The native grid is kept: inputs sharing a CRS and an aligned grid are pasted sample for
//!   sample (a sample two inputs share, e.g. SRTM's duplicated edges, takes the first input
//!   that has it valid). Otherwise every input is warped (GDAL, bilinear) into the first
//!   input's CRS (or `--crs`) at the finest input's resolution.
//! - Sizes are checked before anything is read: the format's limit per side and the memory
//!   the raster needs against what the machine has; rows are read in chunks, so a truncated
//!   file fails at its first missing row, never after allocating what its header claims.
//! - Warnings (one line, processing continues): int16 without nodata but with -32768 samples
//!   (taken as voids, SRTM's convention), Web Mercator metres, heights outside -500..9000 m.

use std::ffi::{CString, c_char};
use std::path::{Path, PathBuf};
use std::sync::Once;

use gdal::raster::GdalDataType;
use gdal::{Dataset, DatasetOptions, DriverManager, GdalOpenFlags};

use super::crs::{Crs, CrsKind, Georef, Transform};
use super::manifest::datum;
use super::output::{available_memory, human_bytes};
use super::pyramid::MAX_SIDE_SAMPLES;
use super::source::{BYTES_PER_SAMPLE, Raster, local_spacing};
use crate::error::{Error, Result};

/// Rows per read.
const CHUNK_ROWS: usize = 64;
/// SRTM tiles: samples per side and bytes.
const SRTM_SIDES: [u64; 2] = [1201, 3601];

/// How to read the inputs.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Local metres between samples (needed without georeferencing; overrides it otherwise).
    pub spacing: Option<f64>,
    /// Target CRS of a warped mosaic (default: the first input's).
    pub crs: Option<String>,
    /// Bytes of memory the raster may use (default: what the system has available).
    pub memory_budget: Option<u64>,
}

/// Silences GDAL's own stderr printing; errors are turned into ours.
pub fn init() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| unsafe {
        gdal_sys::CPLSetErrorHandler(Some(gdal_sys::CPLQuietErrorHandler));
    });
}

fn gdal_msg(e: gdal::errors::GdalError) -> String {
    e.to_string().replace('\n', " ")
}

/// One opened input and what GDAL says about it.
struct Input {
    path: PathBuf,
    ds: Dataset,
    width: u32,
    height: u32,
    band_type: GdalDataType,
    nodata: Option<f64>,
    scale: f64,
    offset: f64,
    /// GDAL's geotransform (pixel corners, row 0 = north) and CRS, when present.
    transform: Option<[f64; 6]>,
    crs: Option<Crs>,
    driver: String,
}

impl Input {
    fn name(&self) -> String {
        self.path.display().to_string()
    }

    /// The north-up georeferencing of sample centres (row 0 = south), if the geotransform
    /// has no rotation; `flip`: whether the file's rows run north to south.
    fn north_up(&self) -> Option<(Georef, bool)> {
        let (t, crs) = (self.transform?, self.crs.clone()?);
        if t[2] != 0.0 || t[4] != 0.0 || t[1] <= 0.0 || t[5] == 0.0 {
            return None;
        }
        let h = self.height as f64;
        Some(if t[5] < 0.0 {
            (
                Georef::north_up(
                    crs,
                    [t[0] + 0.5 * t[1], t[3] + (h - 0.5) * t[5]],
                    [t[1], -t[5]],
                ),
                true,
            )
        } else {
            (
                Georef::north_up(crs, [t[0] + 0.5 * t[1], t[3] + 0.5 * t[5]], [t[1], t[5]]),
                false,
            )
        })
    }
}

fn is_srtm_name(path: &Path) -> bool {
    let n = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_uppercase())
        .unwrap_or_default();
    let b = n.as_bytes();
    b.len() >= 11
        && matches!(b[0], b'N' | b'S')
        && b[1..3].iter().all(u8::is_ascii_digit)
        && matches!(b[3], b'E' | b'W')
        && b[4..7].iter().all(u8::is_ascii_digit)
        && n[7..].starts_with(".HGT")
}

fn lower_name(path: &Path) -> String {
    path.to_string_lossy().to_ascii_lowercase()
}

/// Size in bytes of a file as GDAL's virtual file system sees it (`/vsizip/...`).
fn vsi_size(path: &str) -> Option<u64> {
    let c = CString::new(path).ok()?;
    // GDAL's VSIStatBufL is the C library's `struct stat64` (opaque in the bindings).
    let mut st: libc::stat64 = unsafe { std::mem::zeroed() };
    // SAFETY: valid C string and a stat64 buffer.
    (unsafe {
        gdal_sys::VSIStatL(
            c.as_ptr() as *const c_char,
            &mut st as *mut libc::stat64 as *mut gdal_sys::VSIStatBufL,
        )
    } == 0)
        .then_some(st.st_size as u64)
}

/// Checks an SRTM `.hgt` / `.hgt.zip` before GDAL reads it: the name gives the south-west
/// corner, the size is one of SRTM's.
fn check_srtm(path: &Path) -> Result<()> {
    let lower = lower_name(path);
    if !(lower.ends_with(".hgt") || lower.ends_with(".hgt.zip")) {
        return Ok(());
    }
    let what = path.display().to_string();
    if !is_srtm_name(path) {
        return Err(Error::invalid(
            what,
            "an SRTM tile's file name must give its south-west corner (e.g. N41E001.hgt): GDAL places the tile by it",
        ));
    }
    let size = if lower.ends_with(".zip") {
        let stem = path
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let entry = &stem[..stem.len() - 4];
        let inner = format!("/vsizip/{}/{entry}", path.display());
        vsi_size(&inner).ok_or_else(|| {
            Error::invalid(
                &what,
                format!("is not a zip archive holding {entry} (corrupt or truncated zip?)"),
            )
        })?
    } else {
        std::fs::metadata(path)
            .map_err(|e| Error::io(path, e))?
            .len()
    };
    if !SRTM_SIDES.iter().any(|s| s * s * 2 == size) {
        return Err(Error::invalid(
            what,
            format!(
                "{size} bytes is not an SRTM tile (1201x1201 or 3601x3601 int16: 2884802 or 25934402 bytes): truncated or wrong size"
            ),
        ));
    }
    Ok(())
}

fn open(path: &Path) -> Result<Input> {
    init();
    let what = path.display().to_string();
    let ds = open_raster(path, &what)?;
    let (w, h) = one_band_size(&ds, &what)?;
    let band = ds
        .rasterband(1)
        .map_err(|e| Error::invalid(&what, gdal_msg(e)))?;
    let band_type = band.band_type();
    if matches!(band_type, GdalDataType::Unknown) {
        return Err(Error::invalid(
            what,
            "sample type is not a real number (complex or unknown)",
        ));
    }
    let nodata = band.no_data_value();
    let (scale, offset) = (band.scale().unwrap_or(1.0), band.offset().unwrap_or(0.0));
    if !(scale.is_finite() && scale != 0.0 && offset.is_finite()) {
        return Err(Error::invalid(
            what,
            format!("scale {scale} / offset {offset} is not usable"),
        ));
    }
    let transform = ds.geo_transform().ok();
    let crs = match ds.spatial_ref() {
        Ok(srs) if srs.to_wkt().is_ok_and(|w| !w.is_empty()) => {
            Some(Crs::from_spatial_ref(&srs, &what)?)
        }
        _ => None,
    };
    let driver = ds.driver().short_name();
    Ok(Input {
        path: path.to_path_buf(),
        width: w,
        height: h,
        band_type,
        nodata,
        scale,
        offset,
        transform,
        crs,
        driver,
        ds,
    })
}

/// Opens `path` with GDAL as a read-only raster (`/vsizip/` for a zip other than an SRTM
/// `.hgt.zip`), after refusing what is not a regular file or a truncated SRTM tile.
fn open_raster(path: &Path, what: &str) -> Result<Dataset> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::invalid(
            what,
            "is not a regular file (a device, pipe or directory cannot be a DEM)",
        ));
    }
    check_srtm(path)?;
    let lower = lower_name(path);
    let gdal_path = if lower.ends_with(".zip") && !lower.ends_with(".hgt.zip") {
        format!("/vsizip/{}", path.display())
    } else {
        path.display().to_string()
    };
    Dataset::open_ex(
        &gdal_path,
        DatasetOptions {
            open_flags: GdalOpenFlags::GDAL_OF_RASTER | GdalOpenFlags::GDAL_OF_READONLY,
            ..Default::default()
        },
    )
    .map_err(|e| {
        Error::invalid(
            what,
            format!("GDAL cannot read it as a raster: {}", gdal_msg(e)),
        )
    })
}

/// The raster's size, where it has the one band of heights a DEM has and a size within
/// `2..=MAX_SIDE_SAMPLES` per side.
fn one_band_size(ds: &Dataset, what: &str) -> Result<(u32, u32)> {
    let bands = ds.raster_count();
    if bands != 1 {
        return Err(Error::invalid(
            what,
            format!(
                "has {bands} bands; a DEM has one band of heights (Terrarium / terrain-RGB tiles: use --xyz)"
            ),
        ));
    }
    let (w, h) = ds.raster_size();
    if w < 2 || h < 2 || w as u64 > MAX_SIDE_SAMPLES || h as u64 > MAX_SIDE_SAMPLES {
        return Err(Error::invalid(
            what,
            format!("{w}x{h} samples is outside 2..={MAX_SIDE_SAMPLES} per side"),
        ));
    }
    Ok((w as u32, h as u32))
}

/// What reading found besides the heights.
#[derive(Default)]
struct ReadNotes {
    int16_min_voids: u64,
}

/// Reads `input` in chunks of rows (north to south), calling `sink(file_row, heights)` with
/// metres (voids `NaN`). Non-finite samples that are not nodata are errors naming them.
fn read_rows(
    input: &Input,
    notes: &mut ReadNotes,
    sink: &mut dyn FnMut(usize, &[f32]),
) -> Result<()> {
    let what = input.name();
    let band = input
        .ds
        .rasterband(1)
        .map_err(|e| Error::invalid(&what, gdal_msg(e)))?;
    let w = input.width as usize;
    let int16 = matches!(input.band_type, GdalDataType::Int16);
    let mut raw = vec![0f64; w * CHUNK_ROWS];
    let mut out = vec![0f32; w];
    let mut row0 = 0usize;
    while row0 < input.height as usize {
        let n = CHUNK_ROWS.min(input.height as usize - row0);
        let buf = &mut raw[..w * n];
        band.read_into_slice::<f64>((0, row0 as isize), (w, n), (w, n), buf, None)
            .map_err(|e| {
                Error::invalid(
                    &what,
                    format!(
                        "rows {row0}..{} unreadable (truncated or corrupt?): {}",
                        row0 + n,
                        gdal_msg(e)
                    ),
                )
            })?;
        for r in 0..n {
            for (c, o) in out.iter_mut().enumerate() {
                let v = buf[r * w + c];
                let void = match input.nodata {
                    Some(nd) if nd.is_nan() => v.is_nan(),
                    Some(nd) => v == nd,
                    None if int16 && v == -32768.0 => {
                        notes.int16_min_voids += 1;
                        true
                    }
                    None => false,
                };
                if void {
                    *o = f32::NAN;
                    continue;
                }
                if !v.is_finite() {
                    return Err(Error::invalid(
                        &what,
                        format!(
                            "sample at col {c}, row {} is {} (not declared as nodata)",
                            row0 + r,
                            if v.is_nan() {
                                "NaN".to_string()
                            } else {
                                v.to_string()
                            }
                        ),
                    ));
                }
                *o = (v * input.scale + input.offset) as f32;
            }
            sink(row0 + r, &out);
        }
        row0 += n;
    }
    Ok(())
}

fn check_memory(what: &str, w: u64, h: u64, budget: Option<u64>) -> Result<()> {
    let need = w * h * BYTES_PER_SAMPLE;
    let have = budget.or_else(available_memory).unwrap_or(u64::MAX);
    if need > have {
        return Err(Error::invalid(
            what,
            format!(
                "{w}x{h} samples need about {} of memory to preprocess, {} is available: split the input or free memory",
                human_bytes(need),
                human_bytes(have)
            ),
        ));
    }
    Ok(())
}

/// An input read whole into a north-up raster in its own grid.
fn read_one(input: &Input, notes: &mut ReadNotes) -> Result<(Vec<f32>, Option<Georef>)> {
    let (w, h) = (input.width as usize, input.height as usize);
    let geo = input.north_up();
    let flip = geo.as_ref().is_none_or(|(_, f)| *f);
    let mut heights: Vec<f32> = Vec::new();
    read_rows(input, notes, &mut |_, row| {
        // Grows with what was read, never with what the header claims.
        heights.extend_from_slice(row);
    })?;
    if flip {
        for r in 0..h / 2 {
            let (a, b) = heights.split_at_mut((h - 1 - r) * w);
            a[r * w..(r + 1) * w].swap_with_slice(&mut b[..w]);
        }
    }
    Ok((heights, geo.map(|(g, _)| g)))
}

fn provenance_line(i: &Input) -> String {
    format!(
        "{} ({}, {}x{} {:?}, nodata {}, scale {} offset {}, CRS {})",
        i.path.display(),
        i.driver,
        i.width,
        i.height,
        i.band_type,
        i.nodata.map_or("none".into(), |v| v.to_string()),
        i.scale,
        i.offset,
        i.crs.as_ref().map_or("none".into(), |c| c.label())
    )
}

/// The vertical datum GDAL's metadata implies: SRTM is EGM96; a compound CRS names its
/// vertical part; otherwise unknown.
fn vertical_datum(input: &Input) -> String {
    if input.driver == "SRTMHGT" {
        return datum::EGM96.into();
    }
    let wkt = input.ds.projection();
    if wkt.contains("EGM96") {
        datum::EGM96.into()
    } else if wkt.contains("EGM2008") {
        datum::EGM2008.into()
    } else {
        datum::UNKNOWN.into()
    }
}

/// Reads the DEM inputs into one raster (voids `NaN`, row 0 = south).
pub fn read(paths: &[PathBuf], opts: &ReadOptions) -> Result<Raster> {
    let first = paths
        .first()
        .ok_or_else(|| Error::invalid("preprocess", "no input files"))?;
    if let Some(s) = opts.spacing
        && !(s.is_finite() && s > 0.0)
    {
        return Err(Error::invalid(
            "--spacing",
            format!("{s} m is not a positive number"),
        ));
    }
    for (i, p) in paths.iter().enumerate() {
        if paths[..i].iter().any(|q| same_file(p, q)) {
            return Err(Error::invalid(
                p.display().to_string(),
                "inconsistent mosaic: given twice (the same file overlaps itself)",
            ));
        }
    }
    let inputs = paths.iter().map(|p| open(p)).collect::<Result<Vec<_>>>()?;
    let mut notes = ReadNotes::default();
    // One input in its own north-up grid (or without georeferencing) is read as it is;
    // several, a rotated grid or another --crs go through the mosaic (paste or warp).
    let one = &inputs[0];
    let as_is = inputs.len() == 1
        && (one.transform.is_none()
            || one.crs.is_none()
            || opts.crs.is_none() && one.north_up().is_some());
    let mut raster = if as_is {
        single(&inputs[0], opts, &mut notes)?
    } else {
        mosaic(&inputs, opts, &mut notes)?
    };
    if notes.int16_min_voids > 0 {
        raster.warnings.push(format!(
            "{}: int16 without a nodata value but with {} samples of -32768: taken as voids (SRTM's convention)",
            first.display(),
            notes.int16_min_voids
        ));
    }
    if let Some(g) = &raster.georef
        && g.crs.is_web_mercator()
        && !raster
            .warnings
            .iter()
            .any(|w| w.contains("not ground metres"))
    {
        let (_, warning) = local_spacing(g, raster.width, raster.height)?;
        raster.warnings.extend(warning);
    }
    Ok(raster)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

/// Georeferencing and spacing of a raster (checked), with `--spacing` applied.
fn place(
    what: &str,
    georef: Option<Georef>,
    width: u32,
    height: u32,
    opts: &ReadOptions,
    provenance: &mut Vec<String>,
    warnings: &mut Vec<String>,
) -> Result<[f64; 2]> {
    let derived = match &georef {
        Some(g) => {
            g.check(what, width as u64, height as u64)?;
            let (s, warning) = local_spacing(g, width, height)?;
            warnings.extend(warning);
            Some(s)
        }
        None => None,
    };
    let spacing = match (opts.spacing, derived) {
        (Some(s), d) => {
            if d.is_some() {
                provenance.push(format!("spacing overridden to {s} m by --spacing"));
            }
            [s, s]
        }
        (None, Some(s)) => s,
        (None, None) => {
            return Err(Error::invalid(
                what,
                "has no georeferencing (geotransform plus coordinate system): units unknown; pass --spacing (metres)",
            ));
        }
    };
    let (lo, hi) = super::manifest::SPACING_RANGE_M;
    if spacing
        .iter()
        .any(|s| !(s.is_finite() && (lo..=hi).contains(s)))
    {
        return Err(Error::invalid(
            what,
            format!("sample spacing {spacing:?} m is implausible (outside {lo}..{hi} m)"),
        ));
    }
    Ok(spacing)
}

fn single(input: &Input, opts: &ReadOptions, notes: &mut ReadNotes) -> Result<Raster> {
    let what = input.name();
    check_memory(
        &what,
        input.width as u64,
        input.height as u64,
        opts.memory_budget,
    )?;
    if input.transform.is_some() && input.crs.is_none() && opts.spacing.is_none() {
        return Err(Error::invalid(
            what,
            "has a geotransform but no coordinate system: units unknown; pass --spacing (metres) or give the file a CRS",
        ));
    }
    let geo = input.north_up();
    let mut provenance = vec![provenance_line(input)];
    let mut warnings = Vec::new();
    let georef = geo.as_ref().map(|(g, _)| g.clone());
    let spacing = place(
        &what,
        georef.clone(),
        input.width,
        input.height,
        opts,
        &mut provenance,
        &mut warnings,
    )?;
    let (heights, _) = read_one(input, notes)?;
    Ok(Raster {
        name: what,
        width: input.width,
        height: input.height,
        spacing,
        heights,
        georef,
        vertical_datum: if input.crs.is_some() {
            vertical_datum(input)
        } else {
            datum::LOCAL.into()
        },
        nodata: input.nodata,
        provenance,
        warnings,
    })
}

/// Several inputs: pasted when their grids align, else warped.
fn mosaic(inputs: &[Input], opts: &ReadOptions, notes: &mut ReadNotes) -> Result<Raster> {
    let name = inputs
        .iter()
        .map(|i| i.name())
        .collect::<Vec<_>>()
        .join(" + ");
    for i in inputs {
        if i.crs.is_none() || i.transform.is_none() {
            return Err(Error::invalid(
                i.name(),
                "has no georeferencing: a mosaic (or --crs) needs every input placed in a CRS",
            ));
        }
    }
    let target = match &opts.crs {
        Some(c) => Crs::parse(c)?,
        None => inputs[0].crs.clone().expect("checked"),
    };
    let grids: Option<Vec<Georef>> = inputs.iter().map(|i| i.north_up().map(|g| g.0)).collect();
    if let Some(grids) = grids
        && let Some(offsets) = aligned(&grids, &target)
    {
        return paste(inputs, &grids, &offsets, opts, notes, name);
    }
    warp(inputs, &target, opts, notes, name)
}

/// Integer sample offsets of every grid from the first, if all share the target CRS, the
/// steps and the sample lattice.
fn aligned(grids: &[Georef], target: &Crs) -> Option<Vec<[i64; 2]>> {
    let g0 = &grids[0];
    let [sx, sy] = g0.step();
    let [ox, oy] = g0.origin();
    let mut out = Vec::new();
    for g in grids {
        if !g.crs.same_as(target) {
            return None;
        }
        let [tx, ty] = g.step();
        if ((tx - sx) / sx).abs() > 1e-9 || ((ty - sy) / sy).abs() > 1e-9 {
            return None;
        }
        let [x, y] = g.origin();
        let (fx, fy) = ((x - ox) / sx, (y - oy) / sy);
        if (fx - fx.round()).abs() > 1e-6 || (fy - fy.round()).abs() > 1e-6 {
            return None;
        }
        out.push([fx.round() as i64, fy.round() as i64]);
    }
    Some(out)
}

/// A name for the uncovered point `(x, y)`: SRTM-style for geographic degrees.
fn describe_point(crs: &Crs, x: f64, y: f64) -> String {
    if crs.kind == CrsKind::Geographic {
        let (lat, lon) = (y.floor() as i64, x.floor() as i64);
        format!(
            "{}{:02}{}{:03} ({x:.4}, {y:.4})",
            if lat < 0 { 'S' } else { 'N' },
            lat.abs(),
            if lon < 0 { 'W' } else { 'E' },
            lon.abs()
        )
    } else {
        format!("({x:.3}, {y:.3}) {}", crs.units)
    }
}

/// Aligned inputs pasted into their union grid; shared samples take the first valid value.
fn paste(
    inputs: &[Input],
    grids: &[Georef],
    offsets: &[[i64; 2]],
    opts: &ReadOptions,
    notes: &mut ReadNotes,
    name: String,
) -> Result<Raster> {
    let ([x0, y0], w, h) = union_extent(inputs, offsets);
    check_mosaic_shape(&name, inputs, offsets, w, h)?;
    check_memory(&name, w, h, opts.memory_budget)?;
    let g0 = &grids[0];
    let georef = Georef::north_up(g0.crs.clone(), g0.at(x0 as f64, y0 as f64), g0.step());
    let mut provenance: Vec<String> = inputs.iter().map(provenance_line).collect();
    provenance.push(format!(
        "mosaic {w}x{h} of {} inputs on one grid (no resampling; shared samples from the first input valid there)",
        inputs.len()
    ));
    let mut warnings = Vec::new();
    let spacing = place(
        &name,
        Some(georef.clone()),
        w as u32,
        h as u32,
        opts,
        &mut provenance,
        &mut warnings,
    )?;
    let (heights, covered) =
        paste_heights(inputs, offsets, [x0, y0], w as usize, h as usize, notes)?;
    check_no_gap(inputs, &georef, &covered, w as usize)?;
    Ok(Raster {
        name,
        width: w as u32,
        height: h as u32,
        spacing,
        heights,
        vertical_datum: vertical_datum(&inputs[0]),
        nodata: inputs[0].nodata,
        georef: Some(georef),
        provenance,
        warnings,
    })
}

/// The union of the inputs' grids: its first sample's offset from the first grid and its
/// width and height in samples.
fn union_extent(inputs: &[Input], offsets: &[[i64; 2]]) -> ([i64; 2], u64, u64) {
    let x0 = offsets.iter().map(|o| o[0]).min().expect("inputs");
    let y0 = offsets.iter().map(|o| o[1]).min().expect("inputs");
    let x1 = (0..inputs.len())
        .map(|i| offsets[i][0] + inputs[i].width as i64)
        .max()
        .expect("inputs");
    let y1 = (0..inputs.len())
        .map(|i| offsets[i][1] + inputs[i].height as i64)
        .max()
        .expect("inputs");
    ([x0, y0], (x1 - x0) as u64, (y1 - y0) as u64)
}

/// A mosaic of `w`x`h` samples within the side limit, and no input pasted twice over the same
/// area.
fn check_mosaic_shape(
    name: &str,
    inputs: &[Input],
    offsets: &[[i64; 2]],
    w: u64,
    h: u64,
) -> Result<()> {
    if w > MAX_SIDE_SAMPLES || h > MAX_SIDE_SAMPLES {
        return Err(Error::invalid(
            name,
            format!("the mosaic is {w}x{h} samples, over {MAX_SIDE_SAMPLES} per side"),
        ));
    }
    for i in 1..inputs.len() {
        for j in 0..i {
            if offsets[i] == offsets[j]
                && (inputs[i].width, inputs[i].height) == (inputs[j].width, inputs[j].height)
            {
                return Err(Error::invalid(
                    inputs[j].name(),
                    format!(
                        "inconsistent mosaic: {} overlaps it entirely (the same area twice)",
                        inputs[i].name()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Every input's rows read into the `wu`x`hu` union grid whose first sample is at `origin`
/// (offsets from the first grid): the heights (NaN where no input has a valid value) and
/// which samples some input covers.
fn paste_heights(
    inputs: &[Input],
    offsets: &[[i64; 2]],
    origin: [i64; 2],
    wu: usize,
    hu: usize,
    notes: &mut ReadNotes,
) -> Result<(Vec<f32>, Vec<bool>)> {
    let [x0, y0] = origin;
    let mut heights = vec![f32::NAN; wu * hu];
    let mut covered = vec![false; wu * hu];
    for (i, input) in inputs.iter().enumerate() {
        let flip = input.north_up().is_none_or(|(_, f)| f);
        let (ox, oy) = ((offsets[i][0] - x0) as usize, (offsets[i][1] - y0) as usize);
        let ih = input.height as usize;
        read_rows(input, notes, &mut |file_row, row| {
            let r = oy + if flip { ih - 1 - file_row } else { file_row };
            let base = r * wu + ox;
            for (c, &v) in row.iter().enumerate() {
                let k = base + c;
                if heights[k].is_nan() {
                    heights[k] = v;
                }
                covered[k] = true;
            }
        })?;
    }
    Ok((heights, covered))
}

/// An error naming the first sample of the `wu`-wide union grid that no input covers.
fn check_no_gap(inputs: &[Input], georef: &Georef, covered: &[bool], wu: usize) -> Result<()> {
    if let Some(k) = covered.iter().position(|c| !c) {
        let [x, y] = georef.at((k % wu) as f64, (k / wu) as f64);
        return Err(Error::invalid(
            inputs[0].name(),
            format!(
                "inconsistent mosaic: a gap, no input covers {} (missing tile?)",
                describe_point(&georef.crs, x, y)
            ),
        ));
    }
    Ok(())
}

/// A MEM dataset (Float32, NaN nodata) holding `input`'s heights in metres.
fn to_mem(input: &Input, notes: &mut ReadNotes) -> Result<Dataset> {
    let what = input.name();
    let err = |e: gdal::errors::GdalError| Error::invalid(&what, gdal_msg(e));
    let driver = DriverManager::get_driver_by_name("MEM").map_err(err)?;
    let (w, h) = (input.width as usize, input.height as usize);
    let mut ds = driver
        .create_with_band_type::<f32, _>("", w, h, 1)
        .map_err(err)?;
    ds.set_geo_transform(&input.transform.expect("checked"))
        .map_err(err)?;
    ds.set_projection(&input.crs.as_ref().expect("checked").wkt)
        .map_err(err)?;
    let mut band = ds.rasterband(1).map_err(err)?;
    band.set_no_data_value(Some(f64::NAN)).map_err(err)?;
    let mut failure = None;
    read_rows(input, notes, &mut |file_row, row| {
        let mut buf = gdal::raster::Buffer::new((w, 1), row.to_vec());
        if let Err(e) = band.write((0, file_row as isize), (w, 1), &mut buf) {
            failure.get_or_insert(e);
        }
    })?;
    if let Some(e) = failure {
        return Err(err(e));
    }
    Ok(ds)
}

/// The grid `warp` resamples into: the finest input's resolution over the union of the
/// inputs' extents, in the target CRS.
struct WarpGrid {
    /// Sample spacing (x, y) in the target CRS's units.
    step: [f64; 2],
    /// Bounds `[min x, min y, max x, max y]` of the inputs' union.
    bounds: [f64; 4],
    width: u64,
    height: u64,
}

impl WarpGrid {
    fn covering(inputs: &[Input], target: &Crs, name: &str) -> Result<Self> {
        let (mut tx, mut ty) = (f64::INFINITY, f64::INFINITY);
        let mut b = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for i in inputs {
            let ([ix, iy], ib) = Self::of_input(i, target)?;
            tx = tx.min(ix);
            ty = ty.min(iy);
            b = [
                b[0].min(ib[0]),
                b[1].min(ib[1]),
                b[2].max(ib[2]),
                b[3].max(ib[3]),
            ];
        }
        if !(tx.is_finite() && ty.is_finite() && tx > 0.0 && ty > 0.0) {
            return Err(Error::invalid(name, "cannot derive a target resolution"));
        }
        let w = ((b[2] - b[0]) / tx).ceil() as u64;
        let h = ((b[3] - b[1]) / ty).ceil() as u64;
        if w < 2 || h < 2 || w > MAX_SIDE_SAMPLES || h > MAX_SIDE_SAMPLES {
            return Err(Error::invalid(
                name,
                format!(
                    "the warped mosaic would be {w}x{h} samples (outside 2..={MAX_SIDE_SAMPLES} per side)"
                ),
            ));
        }
        Ok(WarpGrid {
            step: [tx, ty],
            bounds: b,
            width: w,
            height: h,
        })
    }

    /// One input's resolution (a pixel step at its centre) and bounds in the target CRS.
    fn of_input(i: &Input, target: &Crs) -> Result<([f64; 2], [f64; 4])> {
        let t = i.transform.expect("checked");
        let to = Transform::new(i.crs.as_ref().expect("checked"), target)?;
        let at = |c: f64, r: f64| [t[0] + c * t[1] + r * t[2], t[3] + c * t[4] + r * t[5]];
        let (cw, ch) = (i.width as f64, i.height as f64);
        let centre = to.point(at(cw / 2.0, ch / 2.0))?;
        let east = to.point(at(cw / 2.0 + 1.0, ch / 2.0))?;
        let south = to.point(at(cw / 2.0, ch / 2.0 + 1.0))?;
        let step = |p: [f64; 2]| ((p[0] - centre[0]).abs(), (p[1] - centre[1]).abs());
        let (ex, ey) = step(east);
        let (sx, sy) = step(south);
        let mut b = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        // Densified edges.
        let n = 64;
        for k in 0..=n {
            let f = k as f64 / n as f64;
            for p in [
                at(f * cw, 0.0),
                at(f * cw, ch),
                at(0.0, f * ch),
                at(cw, f * ch),
            ] {
                let q = to.point(p)?;
                b = [
                    b[0].min(q[0]),
                    b[1].min(q[1]),
                    b[2].max(q[0]),
                    b[3].max(q[1]),
                ];
            }
        }
        Ok(([ex.max(sx), ey.max(sy)], b))
    }

    /// `gdalwarp`'s arguments for this grid in `target`.
    fn warp_args(&self, target: &Crs) -> Vec<String> {
        let (b, [tx, ty]) = (self.bounds, self.step);
        let (w, h) = (self.width, self.height);
        [
            "-of",
            "MEM",
            "-r",
            "bilinear",
            "-ot",
            "Float32",
            "-dstnodata",
            "nan",
            "-et",
            "0",
            "-t_srs",
        ]
        .iter()
        .map(|s| s.to_string())
        .chain([target.wkt.clone(), "-te".into()])
        .chain(
            [b[0], b[1], b[0] + w as f64 * tx, b[1] + h as f64 * ty]
                .iter()
                .map(|v| format!("{v:.17e}")),
        )
        .chain(["-tr".into(), format!("{tx:.17e}"), format!("{ty:.17e}")])
        .collect()
    }

    /// The warped heights, row 0 the southern edge: GDAL's row 0 is the northern one, the
    /// raster's origin is the grid's minimum corner.
    fn read_heights(&self, out: &Dataset, name: &str) -> Result<Vec<f32>> {
        let band = out
            .rasterband(1)
            .map_err(|e| Error::invalid(name, gdal_msg(e)))?;
        let (wu, hu) = (self.width as usize, self.height as usize);
        let mut heights = vec![0f32; wu * hu];
        band.read_into_slice::<f32>((0, 0), (wu, hu), (wu, hu), &mut heights, None)
            .map_err(|e| Error::invalid(name, gdal_msg(e)))?;
        for r in 0..hu / 2 {
            let (a, bb) = heights.split_at_mut((hu - 1 - r) * wu);
            a[r * wu..(r + 1) * wu].swap_with_slice(&mut bb[..wu]);
        }
        Ok(heights)
    }
}

/// The inputs' common vertical datum; unknown (with a warning) where they differ.
fn common_vertical_datum(inputs: &[Input], warnings: &mut Vec<String>) -> String {
    let datums: Vec<String> = inputs.iter().map(vertical_datum).collect();
    if datums.iter().all(|d| *d == datums[0]) {
        datums[0].clone()
    } else {
        warnings.push(format!(
            "inputs have different vertical datums {datums:?}: heights are mixed, the data set says unknown"
        ));
        datum::UNKNOWN.into()
    }
}

/// Every input warped (GDAL, bilinear) into `target` at the finest input's resolution over
/// the union of their extents; the first input wins where several have data.
fn warp(
    inputs: &[Input],
    target: &Crs,
    opts: &ReadOptions,
    notes: &mut ReadNotes,
    name: String,
) -> Result<Raster> {
    let grid = WarpGrid::covering(inputs, target, &name)?;
    let (w, h) = (grid.width, grid.height);
    let [tx, ty] = grid.step;
    let input_samples: u64 = inputs
        .iter()
        .map(|i| i.width as u64 * i.height as u64)
        .sum();
    check_memory(&name, w, h + input_samples.div_ceil(w), opts.memory_budget)?;
    let mems = inputs
        .iter()
        .map(|i| to_mem(i, notes))
        .collect::<Result<Vec<_>>>()?;
    let out = gdal_warp(&mems, &grid.warp_args(target), &name)?;
    let heights = grid.read_heights(&out, &name)?;
    let b = grid.bounds;
    let georef = Georef::north_up(target.clone(), [b[0] + 0.5 * tx, b[1] + 0.5 * ty], [tx, ty]);
    let mut provenance: Vec<String> = inputs.iter().map(provenance_line).collect();
    provenance.push(format!(
        "warped into {} at {tx} x {ty} {} (GDAL warp, bilinear; the finest input's resolution; where inputs overlap the first wins)",
        target.label(),
        target.units
    ));
    let mut warnings = Vec::new();
    let spacing = place(
        &name,
        Some(georef.clone()),
        w as u32,
        h as u32,
        opts,
        &mut provenance,
        &mut warnings,
    )?;
    let vertical_datum = common_vertical_datum(inputs, &mut warnings);
    Ok(Raster {
        name,
        width: w as u32,
        height: h as u32,
        spacing,
        heights,
        georef: Some(georef),
        vertical_datum,
        nodata: None,
        provenance,
        warnings,
    })
}

/// `gdalwarp` as a library call: sources in reverse, so the first input is warped last and
/// wins where inputs overlap.
fn gdal_warp(sources: &[Dataset], args: &[String], what: &str) -> Result<Dataset> {
    let cargs: Vec<CString> = args
        .iter()
        .map(|a| CString::new(a.as_str()).expect("no NUL in warp arguments"))
        .collect();
    let mut argv: Vec<*mut c_char> = cargs.iter().map(|c| c.as_ptr() as *mut c_char).collect();
    argv.push(std::ptr::null_mut());
    let mut handles: Vec<gdal_sys::GDALDatasetH> =
        sources.iter().rev().map(|d| d.c_dataset()).collect();
    // SAFETY: argv is NULL-terminated and outlives the call; handles are open datasets.
    unsafe {
        let options = gdal_sys::GDALWarpAppOptionsNew(argv.as_mut_ptr(), std::ptr::null_mut());
        if options.is_null() {
            return Err(Error::invalid(what, "GDAL rejected the warp options"));
        }
        let mut usage_error = 0;
        let out = gdal_sys::GDALWarp(
            c"".as_ptr(),
            std::ptr::null_mut(),
            handles.len() as i32,
            handles.as_mut_ptr(),
            options,
            &mut usage_error,
        );
        gdal_sys::GDALWarpAppOptionsFree(options);
        if out.is_null() {
            let msg = std::ffi::CStr::from_ptr(gdal_sys::CPLGetLastErrorMsg())
                .to_string_lossy()
                .replace('\n', " ");
            return Err(Error::invalid(what, format!("GDAL warp failed: {msg}")));
        }
        Ok(Dataset::from_c_dataset(out))
    }
}

/// Georeferencing of an image (e.g. `.pgw`/`.jgw`/`.wld` world files) as GDAL reads it:
/// GDAL's geotransform (pixel corners, row 0 = north), if the image has one.
pub fn image_transform(path: &Path) -> Option<[f64; 6]> {
    init();
    let ds = Dataset::open(path).ok()?;
    let t = ds.geo_transform().ok()?;
    (t != [0.0, 1.0, 0.0, 0.0, 0.0, 1.0]).then_some(t)
}

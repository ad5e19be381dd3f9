//! GeoTIFF elevation rasters: int16, uint16 or float32 samples, one band; strips or tiles;
//! uncompressed, deflate or LZW (decoding by the `tiff` crate). Georeferencing comes from the
//! GeoTIFF tags (ModelPixelScale 33550, ModelTiepoint 33922, GeoKeyDirectory 34735) or, when
//! those are absent, a `.tfw` world file next to the image; GDAL_NODATA (42113) marks voids.

use std::path::{Path, PathBuf};

use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;

use super::source::{Georef, Raster, geographic_spacing};
use crate::error::{Error, Result};

fn bad(path: &Path, msg: impl Into<String>) -> Error {
    Error::invalid(path.display().to_string(), msg)
}

/// The GeoKeys vkterrain uses.
#[derive(Clone, Copy, Debug, Default)]
struct GeoKeys {
    model_type: Option<u16>,
    raster_type: Option<u16>,
    geographic_type: Option<u16>,
    projected_type: Option<u16>,
    linear_units: Option<u16>,
    angular_units: Option<u16>,
}

fn parse_geokeys(dir: &[u16]) -> GeoKeys {
    let mut k = GeoKeys::default();
    if dir.len() < 4 {
        return k;
    }
    for e in dir[4..].chunks_exact(4).take(dir[3] as usize) {
        // Only keys stored inline (location 0) are short values.
        if e[1] != 0 {
            continue;
        }
        let v = Some(e[3]);
        match e[0] {
            1024 => k.model_type = v,
            1025 => k.raster_type = v,
            2048 => k.geographic_type = v,
            2054 => k.angular_units = v,
            3072 => k.projected_type = v,
            3076 => k.linear_units = v,
            _ => {}
        }
    }
    k
}

/// World file beside `path`: `.tfw`, `.tifw` or `.wld`.
pub fn world_file_for(path: &Path) -> Option<PathBuf> {
    ["tfw", "tifw", "wld", "TFW"]
        .iter()
        .map(|ext| path.with_extension(ext))
        .find(|p| p.is_file())
}

/// Parses a world file: `[A, D, B, E, C, F]`; x = A*col + B*row + C (pixel centre).
pub fn read_world_file(path: &Path) -> Result<[f64; 6]> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let v: Vec<f64> = text
        .split_whitespace()
        .map(str::parse)
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| bad(path, format!("world file line is not a number ({e})")))?;
    if v.len() != 6 {
        return Err(bad(
            path,
            format!("world file has {} values, expected 6", v.len()),
        ));
    }
    Ok([v[0], v[1], v[2], v[3], v[4], v[5]])
}

/// Reads a GeoTIFF DEM. `spacing_override` (metres) replaces the georeferenced spacing.
pub fn read(path: &Path, spacing_override: Option<f64>) -> Result<Raster> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let tiff_err = |e: tiff::TiffError| bad(path, format!("TIFF decoding failed: {e}"));
    let mut dec = Decoder::new(std::io::BufReader::new(file))
        .map_err(tiff_err)?
        .with_limits(Limits::unlimited());
    let (w, h) = dec.dimensions().map_err(tiff_err)?;
    let compression = dec
        .find_tag_unsigned::<u16>(Tag::Compression)
        .map_err(tiff_err)?
        .unwrap_or(1);
    let compression_name = match compression {
        1 => "none",
        5 => "LZW",
        8 | 32946 => "deflate",
        other => {
            return Err(bad(
                path,
                format!("unsupported TIFF compression {other} (supported: none, LZW, deflate)"),
            ));
        }
    };
    let spp = dec
        .find_tag_unsigned::<u16>(Tag::SamplesPerPixel)
        .map_err(tiff_err)?
        .unwrap_or(1);
    let bits = dec
        .find_tag_unsigned_vec::<u16>(Tag::BitsPerSample)
        .map_err(tiff_err)?
        .and_then(|v| v.first().copied())
        .unwrap_or(1);
    let format = dec
        .find_tag_unsigned_vec::<u16>(Tag::SampleFormat)
        .map_err(tiff_err)?
        .and_then(|v| v.first().copied())
        .unwrap_or(1);
    let kind = match (format, bits) {
        (2, 16) => "int16",
        (1, 16) => "uint16",
        (3, 32) => "float32",
        _ => {
            let f = match format {
                1 => "unsigned integer",
                2 => "signed integer",
                3 => "floating point",
                _ => "unknown format",
            };
            return Err(bad(
                path,
                format!(
                    "unsupported TIFF sample format: {bits}-bit {f} (supported: int16, uint16, float32)"
                ),
            ));
        }
    };
    if spp != 1 {
        return Err(bad(
            path,
            format!("{spp} samples per pixel; an elevation GeoTIFF has one band"),
        ));
    }
    let f64s = |dec: &mut Decoder<_>, tag| -> Result<Option<Vec<f64>>> {
        match dec.find_tag(tag).map_err(tiff_err)? {
            Some(v) => Ok(Some(v.into_f64_vec().map_err(tiff_err)?)),
            None => Ok(None),
        }
    };
    let scale = f64s(&mut dec, Tag::ModelPixelScaleTag)?;
    let tie = f64s(&mut dec, Tag::ModelTiepointTag)?;
    let keys = match dec.find_tag(Tag::GeoKeyDirectoryTag).map_err(tiff_err)? {
        Some(v) => Some(parse_geokeys(&v.into_u16_vec().map_err(tiff_err)?)),
        None => None,
    };
    let nodata: Option<f64> = match dec.find_tag(Tag::GdalNodata).map_err(tiff_err)? {
        Some(v) => {
            let s = v.into_string().map_err(tiff_err)?;
            let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
            Some(
                s.parse::<f64>()
                    .map_err(|_| bad(path, format!("GDAL_NODATA value {s:?} is not a number")))?,
            )
        }
        None => None,
    };
    let data = dec.read_image().map_err(tiff_err)?;
    let n = w as usize * h as usize;
    let values: Vec<f64> = match data {
        DecodingResult::I16(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::U16(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::F32(v) => v.into_iter().map(f64::from).collect(),
        _ => return Err(bad(path, "decoder returned an unexpected sample type")),
    };
    if values.len() < n {
        return Err(bad(
            path,
            format!("{} samples decoded for {w}x{h}: truncated", values.len()),
        ));
    }
    // Flip: TIFF row 0 is north.
    let mut heights = vec![0f32; n];
    let mut voids = 0usize;
    for r in 0..h as usize {
        let src = (h as usize - 1 - r) * w as usize;
        for c in 0..w as usize {
            let v = values[src + c];
            let is_void = match nodata {
                Some(nd) if nd.is_nan() => v.is_nan(),
                Some(nd) => v == nd,
                None => false,
            };
            heights[r * w as usize + c] = if is_void {
                voids += 1;
                f32::NAN
            } else if !v.is_finite() {
                return Err(bad(
                    path,
                    format!(
                        "sample (col {c}, row {}) is {v}, and GDAL_NODATA does not declare it void",
                        h as usize - 1 - r
                    ),
                ));
            } else {
                v as f32
            };
        }
    }

    // Georeferencing: GeoTIFF tags first, else the world file.
    let keys = keys.unwrap_or_default();
    let geographic = match keys.model_type {
        Some(2) => Some(true),
        Some(1) => Some(false),
        _ => None,
    };
    // (step_x, step_y, x of column 0 centre, y of row 0 (north) centre), y step positive south.
    let mut affine: Option<(f64, f64, f64, f64, String)> = None;
    if let (Some(s), Some(t)) = (&scale, &tie)
        && s.len() >= 2
        && t.len() >= 6
    {
        // PixelIsArea (default): the tiepoint is the pixel's corner.
        let half = if keys.raster_type == Some(2) {
            0.0
        } else {
            0.5
        };
        let x0 = t[3] + (half - t[0]) * s[0];
        let y0 = t[4] - (half - t[1]) * s[1];
        affine = Some((s[0], s[1], x0, y0, "GeoTIFF tags".into()));
    } else if let Some(wf) = world_file_for(path) {
        let [a, d, b, e, c, f] = read_world_file(&wf)?;
        if d != 0.0 || b != 0.0 {
            return Err(bad(
                &wf,
                "rotated world files are not supported (terms B and D must be 0)",
            ));
        }
        affine = Some((a, -e, c, f, format!("world file {}", wf.display())));
    }
    let mut provenance = vec![format!(
        "GeoTIFF {} ({w}x{h} {kind}, compression {compression_name}, {voids} GDAL_NODATA samples)",
        path.display()
    )];
    let (spacing, georef) = match (affine, geographic) {
        (Some((sx, sy, x0, y0, from)), Some(geo)) => {
            if !(sx > 0.0 && sy > 0.0 && sx.is_finite() && sy.is_finite()) {
                return Err(bad(
                    path,
                    format!(
                        "pixel scale {sx} x {sy} is not positive (flipped rasters are not supported)"
                    ),
                ));
            }
            let origin = [x0, y0 - sy * (h - 1) as f64];
            let (units, spacing, crs) = if geo {
                let code = keys.geographic_type.unwrap_or(4326);
                let centre_lat = origin[1] + sy * (h - 1) as f64 / 2.0;
                if keys.angular_units.is_some_and(|u| u != 9102) {
                    return Err(bad(path, "geographic angular unit is not degrees"));
                }
                (
                    "degrees",
                    geographic_spacing([sx, sy], centre_lat),
                    format!("EPSG:{code}"),
                )
            } else {
                let unit = match keys.linear_units.unwrap_or(9001) {
                    9001 => 1.0,
                    9002 => 0.3048,
                    9003 => 1200.0 / 3937.0,
                    other => {
                        return Err(bad(path, format!("unsupported linear unit code {other}")));
                    }
                };
                let code = keys
                    .projected_type
                    .map(|c| format!("EPSG:{c}"))
                    .unwrap_or_else(|| "unknown projected".into());
                ("metres", [sx * unit, sy * unit], code)
            };
            provenance.push(format!(
                "georeferenced by {from}: {crs}, step {sx} x {sy} {units}, spacing {:.4} x {:.4} m",
                spacing[0], spacing[1]
            ));
            (
                spacing,
                Some(Georef {
                    crs,
                    units: units.into(),
                    origin,
                    step: [sx, sy],
                }),
            )
        }
        _ => match spacing_override {
            Some(s) => ([s, s], None),
            None => {
                return Err(bad(
                    path,
                    "no usable georeferencing (pixel scale/tiepoint or world file, plus GeoKeyDirectory model type); pass --spacing",
                ));
            }
        },
    };
    let spacing = match spacing_override {
        Some(s) => {
            provenance.push(format!("spacing overridden to {s} m by --spacing"));
            [s, s]
        }
        None => spacing,
    };
    Ok(Raster {
        name: path.display().to_string(),
        width: w,
        height: h,
        spacing,
        heights,
        georef,
        provenance,
    })
}

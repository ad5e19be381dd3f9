//! A source elevation raster as read from disk, before void filling and tiling.
//!
//! Same orientation as [`super::Heightmap`]: row 0 is the **south** edge. Voids are `NaN`.
//! The grid is the source's own (its CRS and steps in [`Raster::georef`]); `spacing` is the
//! local-metres approximation the flat renderer uses (see [`local_spacing`]).

use super::crs::{CrsKind, Georef, Transform};
use crate::error::Result;

/// Bytes of working memory per level-0 sample of a raster held for void filling (heights,
/// mask, the fill's coarser levels and the reader's chunk).
pub const BYTES_PER_SAMPLE: u64 = 12;
/// Heights outside this range draw a warning.
pub const PLAUSIBLE_HEIGHTS: (f64, f64) = (-500.0, 9000.0);

#[derive(Clone, Debug)]
pub struct Raster {
    /// Source description (file names), used in messages and the manifest.
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Local metres between samples east-west and north-south ([`local_spacing`]).
    pub spacing: [f64; 2],
    /// Row-major, row 0 = south, `NaN` = void.
    pub heights: Vec<f32>,
    pub georef: Option<Georef>,
    /// Datum of the heights (`manifest::datum`).
    pub vertical_datum: String,
    /// Source value that marked voids, when one was declared.
    pub nodata: Option<f64>,
    /// One line per input and per processing step (for the manifest).
    pub provenance: Vec<String>,
    /// What looked wrong in the data (one line each; processing continued).
    pub warnings: Vec<String>,
}

impl Raster {
    pub fn void_count(&self) -> usize {
        self.heights.iter().filter(|h| h.is_nan()).count()
    }

    /// CRS bounds of the sample centres: `[x_min, y_min, x_max, y_max]`.
    pub fn bounds(&self) -> Option<[f64; 4]> {
        self.georef.as_ref().map(|g| {
            let [x0, y0] = g.origin();
            let [x1, y1] = g.at((self.width - 1) as f64, (self.height - 1) as f64);
            [x0, y0, x1, y1]
        })
    }
}

/// Metres per degree of latitude and of longitude at latitude `lat_deg` (WGS84 ellipsoid,
/// the usual series expansion, accurate to centimetres per degree).
pub fn metres_per_degree(lat_deg: f64) -> (f64, f64) {
    let p = lat_deg.to_radians();
    let lat =
        111_132.92 - 559.82 * (2.0 * p).cos() + 1.175 * (4.0 * p).cos() - 0.0023 * (6.0 * p).cos();
    let lon = 111_412.84 * p.cos() - 93.5 * (3.0 * p).cos() + 0.118 * (5.0 * p).cos();
    (lat, lon)
}

/// Spacing in metres `[x, y]` of a geographic grid with steps in degrees, at the latitude of
/// the grid's centre.
pub fn geographic_spacing(step_deg: [f64; 2], centre_lat: f64) -> [f64; 2] {
    let (m_lat, m_lon) = metres_per_degree(centre_lat);
    [step_deg[0] * m_lon, step_deg[1] * m_lat]
}

/// The local-metres spacing of a `width x height` grid, plus a warning where the CRS's units
/// are not ground metres. This is the flat renderer's approximation (one spacing for the whole
/// grid) until it renders native grids:
/// - geographic: steps in degrees times metres per degree at the grid's centre latitude
///   (rounded to 1e-9 deg so floating-point noise in the geotransform cannot change it);
/// - Web Mercator: steps times the cosine of the centre latitude (PROJ's inverse of the
///   centre), the projection's scale there; a warning says so;
/// - other projected CRSs: steps times the unit's metres.
pub fn local_spacing(g: &Georef, width: u32, height: u32) -> Result<([f64; 2], Option<String>)> {
    let [sx, sy] = g.step();
    let centre = g.at((width - 1) as f64 / 2.0, (height - 1) as f64 / 2.0);
    match g.crs.kind {
        CrsKind::Geographic => {
            let deg = if g.crs.units.eq_ignore_ascii_case("degree") {
                1.0
            } else {
                g.crs.unit_size.to_degrees()
            };
            let lat = (centre[1] * deg * 1e9).round() / 1e9;
            Ok((geographic_spacing([sx * deg, sy * deg], lat), None))
        }
        CrsKind::Projected if g.crs.is_web_mercator() => {
            let to_geo = Transform::new(&g.crs, &super::crs::Crs::wgs84()?)?;
            let [_, lat] = to_geo.point(centre)?;
            let k = lat.to_radians().cos();
            let m = g.crs.unit_size;
            Ok((
                [sx * m * k, sy * m * k],
                Some(format!(
                    "{} metres are not ground metres (scale 1/cos(lat) = {:.3} at the centre, {lat:.3} deg): spacing taken at the centre latitude, off by up to {:.2} % at the north/south edges",
                    g.crs.label(),
                    1.0 / k,
                    edge_error_percent(g, height, lat, &to_geo)?
                )),
            ))
        }
        CrsKind::Projected => Ok(([sx * g.crs.unit_size, sy * g.crs.unit_size], None)),
    }
}

/// How far the centre latitude's Mercator scale is from the edges' (percent).
fn edge_error_percent(g: &Georef, height: u32, lat_c: f64, to_geo: &Transform) -> Result<f64> {
    let mut worst: f64 = 0.0;
    for row in [0.0, (height - 1) as f64] {
        let [_, lat] = to_geo.point(g.at(0.0, row))?;
        let r = lat.to_radians().cos() / lat_c.to_radians().cos();
        worst = worst.max((r - 1.0).abs() * 100.0);
    }
    Ok(worst)
}

/// Warns (one line) about heights outside [`PLAUSIBLE_HEIGHTS`] (after any scaling).
pub fn plausibility_warnings(raster: &mut Raster) {
    let (lo, hi) = PLAUSIBLE_HEIGHTS;
    let (mut n, mut min, mut max) = (0u64, f32::INFINITY, f32::NEG_INFINITY);
    for &v in raster.heights.iter().filter(|v| !v.is_nan()) {
        if (v as f64) < lo || (v as f64) > hi {
            n += 1;
            min = min.min(v);
            max = max.max(v);
        }
    }
    if n > 0 {
        raster.warnings.push(format!(
            "{}: {n} heights outside {lo}..{hi} m (from {min} to {max} m): wrong units, scale or nodata?",
            raster.name
        ));
    }
}

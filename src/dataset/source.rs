//! A source elevation raster as read from disk, before void filling and tiling.
//!
//! Same orientation as [`super::Heightmap`]: row 0 is the **south** edge. Voids are `NaN`.
//! Spacing may differ between x and y (geographic data: an arc-second is shorter east-west
//! than north-south); it is always in metres, derived from the georeferencing.

use serde::{Deserialize, Serialize};

/// Where the samples lie in a coordinate reference system.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Georef {
    /// E.g. `EPSG:4326` or `EPSG:32611`; `unknown` when the file does not say.
    pub crs: String,
    /// `degrees` or `metres`.
    pub units: String,
    /// CRS coordinates of the centre of sample (0, 0) (the south-west sample).
    pub origin: [f64; 2],
    /// CRS step between samples, x east and y north (both positive).
    pub step: [f64; 2],
}

#[derive(Clone, Debug)]
pub struct Raster {
    /// Source description (file names), used in messages and the manifest.
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Metres between samples east-west and north-south.
    pub spacing: [f64; 2],
    /// Row-major, row 0 = south, `NaN` = void.
    pub heights: Vec<f32>,
    pub georef: Option<Georef>,
    /// One line per input and per processing step (for the manifest).
    pub provenance: Vec<String>,
}

impl Raster {
    pub fn void_count(&self) -> usize {
        self.heights.iter().filter(|h| h.is_nan()).count()
    }

    /// CRS bounds of the sample centres: `[x_min, y_min, x_max, y_max]`.
    pub fn bounds(&self) -> Option<[f64; 4]> {
        self.georef.as_ref().map(|g| {
            [
                g.origin[0],
                g.origin[1],
                g.origin[0] + g.step[0] * (self.width - 1) as f64,
                g.origin[1] + g.step[1] * (self.height - 1) as f64,
            ]
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
/// the grid's centre. (Away from the centre the true east-west spacing differs by the cosine
/// ratio; the data is not reprojected: see `docs/dataset-format.md`.)
pub fn geographic_spacing(step_deg: [f64; 2], centre_lat: f64) -> [f64; 2] {
    let (m_lat, m_lon) = metres_per_degree(centre_lat);
    [step_deg[0] * m_lon, step_deg[1] * m_lat]
}

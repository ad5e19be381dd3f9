//! Coordinate reference systems as PROJ understands them, through GDAL's OSR (PROJ 9
//! underneath: one PROJ for the whole program), and the georeferencing of a grid.
//!
//! Axis order is always "traditional GIS" (x = easting or longitude, y = northing or
//! latitude), whatever the authority says.

#[cfg(feature = "gdal")]
use gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Geographic (angles) or projected (lengths) coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CrsKind {
    Geographic,
    Projected,
}

/// A horizontal CRS as stored in a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Crs {
    /// Human-readable name, e.g. `WGS 84` or `WGS 84 / UTM zone 11N`.
    pub name: String,
    /// `AUTHORITY:CODE` when PROJ identifies one (e.g. `EPSG:4326`).
    pub authority: Option<String>,
    pub kind: CrsKind,
    /// Unit of the coordinates: `degree` or a linear unit (`metre`, `US survey foot`, ...).
    pub units: String,
    /// Size of one unit: radians (geographic) or metres (projected).
    pub unit_size: f64,
    /// The full definition, WKT2 (2019): what PROJ/GDAL read back.
    pub wkt: String,
}

/// EPSG codes of the spherical ("Web", "Pseudo") Mercator family, whose metres are not
/// ground metres.
const WEB_MERCATOR: [&str; 3] = ["EPSG:3857", "EPSG:900913", "EPSG:3785"];

/// The error of a build without GDAL/PROJ.
#[cfg(not(feature = "gdal"))]
fn no_proj(what: &str) -> Error {
    Error::invalid(
        what,
        "this vkterrain was built without GDAL/PROJ (--no-default-features): no coordinate transformations",
    )
}

#[cfg(feature = "gdal")]
fn gdal_err(what: &str, e: gdal::errors::GdalError) -> Error {
    Error::invalid(what, e.to_string().replace('\n', " "))
}

impl Crs {
    /// From a GDAL spatial reference (an authority code is looked up when absent).
    #[cfg(feature = "gdal")]
    pub fn from_spatial_ref(srs: &SpatialRef, what: &str) -> Result<Self> {
        let mut srs = srs.clone();
        if srs.auth_name().is_none() {
            // Best effort: many files carry a definition without its code.
            let _ = srs.auto_identify_epsg();
        }
        let authority = match (srs.auth_name(), srs.auth_code()) {
            (Some(n), Ok(c)) => Some(format!("{n}:{c}")),
            _ => None,
        };
        let (kind, units, unit_size) = if srs.is_geographic() {
            (
                CrsKind::Geographic,
                srs.angular_units_name().unwrap_or_else(|| "degree".into()),
                srs.angular_units(),
            )
        } else if srs.is_projected() {
            (
                CrsKind::Projected,
                srs.linear_units_name().unwrap_or_else(|| "metre".into()),
                srs.linear_units(),
            )
        } else {
            return Err(Error::invalid(
                what,
                "the coordinate system is neither geographic nor projected (local, geocentric or vertical only): units unknown",
            ));
        };
        if !(unit_size.is_finite() && unit_size > 0.0) {
            return Err(Error::invalid(
                what,
                format!("the coordinate system's unit {units:?} has no usable size ({unit_size})"),
            ));
        }
        let wkt = srs.to_wkt().map_err(|e| gdal_err(what, e))?;
        Ok(Crs {
            name: srs.name().unwrap_or_else(|| "unnamed".into()),
            authority,
            kind,
            units,
            unit_size,
            wkt,
        })
    }

    /// From what a user types: `EPSG:32633`, a WKT or a PROJ string.
    #[cfg(not(feature = "gdal"))]
    pub fn parse(_definition: &str) -> Result<Self> {
        Err(no_proj("--crs"))
    }

    /// From what a user types: `EPSG:32633`, a WKT or a PROJ string.
    #[cfg(feature = "gdal")]
    pub fn parse(definition: &str) -> Result<Self> {
        let srs = SpatialRef::from_definition(definition).map_err(|e| {
            Error::invalid(
                "--crs",
                format!("{definition:?} is not a coordinate system PROJ knows ({e})"),
            )
        })?;
        Self::from_spatial_ref(&srs, "--crs")
    }

    /// WGS 84 geographic (longitude, latitude in degrees).
    #[cfg(not(feature = "gdal"))]
    pub fn wgs84() -> Result<Self> {
        Err(no_proj("EPSG:4326"))
    }

    /// Web Mercator (EPSG:3857), the CRS of XYZ tiles.
    #[cfg(not(feature = "gdal"))]
    pub fn web_mercator() -> Result<Self> {
        Err(no_proj("EPSG:3857"))
    }

    /// WGS 84 geographic (longitude, latitude in degrees).
    #[cfg(feature = "gdal")]
    pub fn wgs84() -> Result<Self> {
        let srs = SpatialRef::from_epsg(4326).map_err(|e| gdal_err("EPSG:4326", e))?;
        Self::from_spatial_ref(&srs, "EPSG:4326")
    }

    /// Web Mercator (EPSG:3857), the CRS of XYZ tiles.
    #[cfg(feature = "gdal")]
    pub fn web_mercator() -> Result<Self> {
        let srs = SpatialRef::from_epsg(3857).map_err(|e| gdal_err("EPSG:3857", e))?;
        Self::from_spatial_ref(&srs, "EPSG:3857")
    }

    /// The GDAL spatial reference, axis order x/east, y/north.
    #[cfg(feature = "gdal")]
    pub fn spatial_ref(&self) -> Result<SpatialRef> {
        let mut srs = SpatialRef::from_wkt(&self.wkt).map_err(|e| gdal_err(&self.name, e))?;
        srs.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
        Ok(srs)
    }

    /// Is this the spherical Mercator of web maps?
    pub fn is_web_mercator(&self) -> bool {
        self.authority
            .as_deref()
            .is_some_and(|a| WEB_MERCATOR.contains(&a))
            || self.name.contains("Pseudo-Mercator")
            || self.name.contains("Popular Visualisation")
    }

    /// The same CRS (PROJ's equivalence, ignoring axis order and metadata).
    pub fn same_as(&self, other: &Crs) -> bool {
        if self.wkt == other.wkt {
            return true;
        }
        #[cfg(not(feature = "gdal"))]
        return false;
        #[cfg(feature = "gdal")]
        match (self.spatial_ref(), other.spatial_ref()) {
            (Ok(a), Ok(b)) => unsafe { gdal_sys::OSRIsSame(a.to_c_hsrs(), b.to_c_hsrs()) != 0 },
            _ => false,
        }
    }

    /// Label for messages: `EPSG:4326 (WGS 84)` or the name.
    pub fn label(&self) -> String {
        match &self.authority {
            Some(a) => format!("{a} ({})", self.name),
            None => self.name.clone(),
        }
    }
}

/// Transforms points between two CRSs through PROJ.
pub struct Transform {
    #[cfg(feature = "gdal")]
    inner: CoordTransform,
    what: String,
}

impl Transform {
    #[cfg(not(feature = "gdal"))]
    pub fn new(from: &Crs, to: &Crs) -> Result<Self> {
        Err(no_proj(&format!("{} -> {}", from.label(), to.label())))
    }

    #[cfg(feature = "gdal")]
    pub fn new(from: &Crs, to: &Crs) -> Result<Self> {
        let what = format!("{} -> {}", from.label(), to.label());
        let inner = CoordTransform::new(&from.spatial_ref()?, &to.spatial_ref()?)
            .map_err(|e| gdal_err(&what, e))?;
        Ok(Transform { inner, what })
    }

    /// Transforms `(x, y)` pairs in place; a point PROJ cannot transform is an error.
    #[cfg(not(feature = "gdal"))]
    pub fn apply(&self, _pts: &mut [[f64; 2]]) -> Result<()> {
        Err(no_proj(&self.what))
    }

    /// Transforms `(x, y)` pairs in place; a point PROJ cannot transform is an error.
    #[cfg(feature = "gdal")]
    pub fn apply(&self, pts: &mut [[f64; 2]]) -> Result<()> {
        let mut xs: Vec<f64> = pts.iter().map(|p| p[0]).collect();
        let mut ys: Vec<f64> = pts.iter().map(|p| p[1]).collect();
        let mut zs = vec![0.0; pts.len()];
        self.inner
            .transform_coords(&mut xs, &mut ys, &mut zs)
            .map_err(|e| gdal_err(&self.what, e))?;
        for (p, (x, y)) in pts.iter_mut().zip(xs.into_iter().zip(ys)) {
            if !(x.is_finite() && y.is_finite()) {
                return Err(Error::invalid(
                    &self.what,
                    format!("point {p:?} cannot be transformed"),
                ));
            }
            *p = [x, y];
        }
        Ok(())
    }

    pub fn point(&self, p: [f64; 2]) -> Result<[f64; 2]> {
        let mut v = [p];
        self.apply(&mut v)?;
        Ok(v[0])
    }
}

/// Where the samples of a grid lie: its CRS and the affine map from sample indices to CRS
/// coordinates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Georef {
    pub crs: Crs,
    /// CRS coordinates of the **centre** of sample `(col, row)` (row 0 = south):
    /// `x = t[0] + col * t[1] + row * t[2]`, `y = t[3] + col * t[4] + row * t[5]`.
    /// `vkterrain preprocess` writes north-up grids (`t[2] = t[4] = 0`, `t[1], t[5] > 0`).
    pub sample_to_crs: [f64; 6],
}

impl Georef {
    /// A north-up grid: the south-west sample's centre and the steps east and north.
    pub fn north_up(crs: Crs, origin: [f64; 2], step: [f64; 2]) -> Self {
        Georef {
            crs,
            sample_to_crs: [origin[0], step[0], 0.0, origin[1], 0.0, step[1]],
        }
    }

    /// The south-west sample's centre.
    pub fn origin(&self) -> [f64; 2] {
        [self.sample_to_crs[0], self.sample_to_crs[3]]
    }

    /// Steps between samples east and north (CRS units).
    pub fn step(&self) -> [f64; 2] {
        [self.sample_to_crs[1], self.sample_to_crs[5]]
    }

    /// CRS coordinates of sample `(col, row)`'s centre.
    pub fn at(&self, col: f64, row: f64) -> [f64; 2] {
        let t = &self.sample_to_crs;
        [
            t[0] + col * t[1] + row * t[2],
            t[3] + col * t[4] + row * t[5],
        ]
    }

    /// Checks a north-up grid of `width x height` samples: finite, positive steps no smaller
    /// than 1e-12 of the coordinates' magnitude, geographic coordinates on the earth.
    pub fn check(&self, what: &str, width: u64, height: u64) -> Result<()> {
        let t = &self.sample_to_crs;
        let bad = |m: String| Err(Error::invalid(what, m));
        if t.iter().any(|v| !v.is_finite()) {
            return bad(format!("georeferencing {t:?} is not finite"));
        }
        if t[2] != 0.0 || t[4] != 0.0 {
            return bad(format!("georeferencing {t:?} is rotated (not north-up)"));
        }
        let [sx, sy] = self.step();
        let [x0, y0] = self.origin();
        let [x1, y1] = self.at((width - 1) as f64, (height - 1) as f64);
        let size = x0.abs().max(x1.abs()).max(y0.abs()).max(y1.abs()).max(1.0);
        if !(sx > 0.0 && sy > 0.0) || sx < 1e-12 * size || sy < 1e-12 * size {
            return bad(format!(
                "sample step {sx} x {sy} {} is not positive or is too small for coordinates of {size:e}",
                self.crs.units
            ));
        }
        if self.crs.kind == CrsKind::Geographic {
            let deg = self.crs.unit_size.to_degrees();
            let (lat0, lat1) = (y0 * deg, y1 * deg);
            let (lon0, lon1) = (x0 * deg, x1 * deg);
            if lat0 < -90.0 - 1e-9 || lat1 > 90.0 + 1e-9 {
                return bad(format!("latitudes {lat0}..{lat1} deg lie outside -90..90"));
            }
            if lon0 < -540.0 || lon1 > 540.0 || lon1 - lon0 > 360.0 + 1e-9 {
                return bad(format!(
                    "longitudes {lon0}..{lon1} deg are not on the earth"
                ));
            }
        }
        Ok(())
    }
}

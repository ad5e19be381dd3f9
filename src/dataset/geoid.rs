//! Geoid undulations through PROJ: the height of the geoid above the WGS84 ellipsoid, so that
//! heights above mean sea level (orthometric, e.g. SRTM's EGM96 heights) and heights above the
//! ellipsoid (GNSS) can be compared (`docs/coordinates.md` "Datums").
//!
//! The undulation `N` is what PROJ's `EPSG:4979 -> EPSG:4326+5773` (WGS 84 3D -> WGS 84 + EGM96
//! height) gives: `H = h - N`. PROJ reads Debian's `proj-data` grid `egm96_15.gtx`; ballpark
//! transformations (which would silently return `H = h` when the grid is missing) are refused,
//! so a missing grid is a one-line error, never an undulation of 0.

use super::manifest::datum;
use crate::error::{Error, Result};

/// A geoid model PROJ can evaluate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GeoidModel {
    /// EGM96 (EPSG:5773 heights; grid `egm96_15.gtx`, Debian `proj-data`).
    Egm96,
    /// EGM2008 (EPSG:3855 heights; grid `egm08_25.gtx`, not in Debian's `proj-data`).
    Egm2008,
}

impl GeoidModel {
    /// The geoid a manifest's `vertical_datum` refers to: `egm96`, `egm2008`; `unknown`
    /// ("sea level" of an unstated datum) is taken as EGM96; `ellipsoid` and `local` have none.
    pub fn of_datum(vertical_datum: &str) -> Option<GeoidModel> {
        match vertical_datum {
            datum::EGM96 | datum::UNKNOWN => Some(GeoidModel::Egm96),
            datum::EGM2008 => Some(GeoidModel::Egm2008),
            _ => None,
        }
    }

    /// EPSG code of the vertical CRS of heights above this geoid.
    pub fn vertical_epsg(self) -> u32 {
        match self {
            GeoidModel::Egm96 => 5773,
            GeoidModel::Egm2008 => 3855,
        }
    }

    /// PROJ's grid file of this geoid.
    pub fn grid(self) -> &'static str {
        match self {
            GeoidModel::Egm96 => "egm96_15.gtx",
            GeoidModel::Egm2008 => "egm08_25.gtx",
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            GeoidModel::Egm96 => "EGM96",
            GeoidModel::Egm2008 => "EGM2008",
        }
    }
}

/// Evaluates a geoid's undulation through PROJ.
pub struct Geoid {
    pub model: GeoidModel,
    #[cfg(feature = "gdal")]
    to_orthometric: gdal::spatial_ref::CoordTransform,
}

impl Geoid {
    /// Without GDAL/PROJ there is no geoid: a one-line error.
    #[cfg(not(feature = "gdal"))]
    pub fn new(model: GeoidModel) -> Result<Self> {
        Err(Error::invalid(
            model.name(),
            "this vkterrain was built without GDAL/PROJ (--no-default-features): no geoid, so heights above mean sea level cannot be converted; give heights above the ellipsoid or the ground",
        ))
    }

    #[cfg(feature = "gdal")]
    pub fn new(model: GeoidModel) -> Result<Self> {
        use gdal::spatial_ref::{
            AxisMappingStrategy, CoordTransform, CoordTransformOptions, SpatialRef,
        };
        // GDAL's own stderr printing off: a missing grid is our one-line error, not PROJ's WKT.
        super::gdal_in::init();
        let what = format!("geoid {}", model.name());
        let err =
            |e: gdal::errors::GdalError| Error::invalid(&what, e.to_string().replace('\n', " "));
        let mut from = SpatialRef::from_epsg(4979).map_err(err)?;
        let mut to = SpatialRef::from_definition(&format!("EPSG:4326+{}", model.vertical_epsg()))
            .map_err(err)?;
        from.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
        to.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
        let mut options = CoordTransformOptions::new().map_err(err)?;
        options.set_ballpark_allowed(false).map_err(err)?;
        // PROJ's own message quotes both CRSs in full WKT (kilobytes): say what is missing.
        let to_orthometric =
            CoordTransform::new_with_options(&from, &to, &options).map_err(|e| {
                let gdal = e.to_string().replace('\n', " ");
                let gdal: String = gdal.chars().take(100).collect();
                Error::invalid(
                    &what,
                    format!(
                        "PROJ finds no transformation to {} heights (EPSG:{}): is its grid {} installed (Debian's proj-data ships EGM96's only)? PROJ: {gdal}...",
                        model.name(),
                        model.vertical_epsg(),
                        model.grid()
                    ),
                )
            })?;
        let geoid = Geoid {
            model,
            to_orthometric,
        };
        // PROJ builds the operation lazily: a missing grid shows on the first point.
        geoid.undulation(0.0, 0.0).map_err(|e| {
            Error::invalid(
                &what,
                format!("PROJ cannot evaluate it (is its grid installed? Debian: proj-data): {e}"),
            )
        })?;
        Ok(geoid)
    }

    /// The geoid's height above the WGS84 ellipsoid at a latitude/longitude (degrees), metres.
    #[cfg(not(feature = "gdal"))]
    pub fn undulation(&self, _lat_deg: f64, _lon_deg: f64) -> Result<f64> {
        Err(Error::invalid(self.model.name(), "no PROJ"))
    }

    /// The geoid's height above the WGS84 ellipsoid at a latitude/longitude (degrees), metres.
    #[cfg(feature = "gdal")]
    pub fn undulation(&self, lat_deg: f64, lon_deg: f64) -> Result<f64> {
        let n = self.undulations(&[[lat_deg, lon_deg]])?;
        Ok(n[0])
    }

    /// [`Geoid::undulation`] at many `[lat, lon]` points (degrees) in one PROJ call (the
    /// geolocation lattice's nodes: one transformation of the whole batch, not one per node).
    #[cfg(not(feature = "gdal"))]
    pub fn undulations(&self, _points: &[[f64; 2]]) -> Result<Vec<f64>> {
        Err(Error::invalid(self.model.name(), "no PROJ"))
    }

    /// [`Geoid::undulation`] at many `[lat, lon]` points (degrees) in one PROJ call (the
    /// geolocation lattice's nodes: one transformation of the whole batch, not one per node).
    #[cfg(feature = "gdal")]
    pub fn undulations(&self, points: &[[f64; 2]]) -> Result<Vec<f64>> {
        let where_ = |k: usize| match points.get(k) {
            Some([lat, lon]) if points.len() == 1 => format!("at {lat}, {lon}"),
            Some([lat, lon]) => format!("at {lat}, {lon} (one of {} points)", points.len()),
            None => format!("at {} points", points.len()),
        };
        let what = |k: usize| format!("geoid {} {}", self.model.name(), where_(k));
        let mut x: Vec<f64> = points.iter().map(|p| p[1]).collect();
        let mut y: Vec<f64> = points.iter().map(|p| p[0]).collect();
        let mut z = vec![0.0; points.len()];
        self.to_orthometric
            .transform_coords(&mut x, &mut y, &mut z)
            .map_err(|e| Error::invalid(what(usize::MAX), e.to_string().replace('\n', " ")))?;
        // H = h - N with h = 0.
        if let Some(k) = z.iter().position(|v| !v.is_finite() || v.abs() > 200.0) {
            return Err(Error::invalid(
                what(k),
                format!("PROJ gave an undulation of {} m", -z[k]),
            ));
        }
        Ok(z.into_iter().map(|v| -v).collect())
    }
}

#[cfg(all(test, feature = "gdal"))]
mod tests {
    use super::*;

    #[test]
    fn egm96_matches_published_values() {
        let g = Geoid::new(GeoidModel::Egm96).unwrap();
        // EGM96 at 0 N 0 E: +17.16 m (NGA's EGM96 tables; the classic check value).
        let n = g.undulation(0.0, 0.0).unwrap();
        assert!((n - 17.16).abs() < 0.02, "{n}");
        // Negative control: the undulation varies (a constant would pass a single check).
        // The Indian Ocean low is below -100 m near 5 N 78 E.
        let low = g.undulation(5.0, 78.0).unwrap();
        assert!(low < -95.0, "{low}");
        // Swiss Alps (46.5 N 8 E): PROJ's own cs2cs gives H = -50.68 m for h = 0.
        let alps = g.undulation(46.5, 8.0).unwrap();
        assert!((alps - 50.68).abs() < 0.01, "{alps}");
        // The batch gives the single points' values, in order.
        let batch = g
            .undulations(&[[0.0, 0.0], [5.0, 78.0], [46.5, 8.0]])
            .unwrap();
        assert_eq!(batch, vec![n, low, alps]);
        let e = g.undulations(&[[0.0, 0.0], [f64::NAN, 1.0]]).unwrap_err();
        assert!(!e.to_string().contains('\n'), "{e}");
    }
}

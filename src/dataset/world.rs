//! The world frame of a data set: where vkterrain's metric world (x east, y north, z up) lies
//! on the earth (`docs/coordinates.md` "World frame").
//!
//! - A georeferenced data set: the east-north-up frame at the geodetic position of sample
//!   (0, 0) at height 0 on the WGS84 ellipsoid, found by PROJ from `georef`.
//! - A data set without georeferencing (procedural, PNG, a pyramid built from them): the frame
//!   at `[dataset] anchor` when given.
//! - Otherwise none: a flat world, exactly as before the earth was modelled.

use std::path::{Path, PathBuf};

#[cfg(not(feature = "gdal"))]
use super::crs::CrsKind;
use super::crs::Georef;
use super::geoid::{Geoid, GeoidModel};
use super::level0::{Level0, Terrain};
use super::settings::{Anchor, DatasetConfig};
use super::tiles::Dataset;
use crate::error::{Error, Result};
use crate::geo::{EnuFrame, Geodetic, Lattice, WGS84};
use glam::DVec3;

/// WGS84 latitude and longitude (degrees) of sample `(col, row)`'s centre.
pub fn sample_lat_lon(georef: &Georef, col: f64, row: f64) -> Result<(f64, f64)> {
    SampleLocator::new(georef)?.lat_lon(col, row)
}

/// Latitude/longitude of the samples of one georeferenced grid (the PROJ transformation is
/// set up once, then reused for every sample).
pub struct SampleLocator<'a> {
    georef: &'a Georef,
    #[cfg(feature = "gdal")]
    to_wgs84: super::crs::Transform,
}

impl<'a> SampleLocator<'a> {
    /// Through PROJ (`georef`'s CRS -> EPSG:4326).
    #[cfg(feature = "gdal")]
    pub fn new(georef: &'a Georef) -> Result<Self> {
        use super::crs::{Crs, Transform};
        let to_wgs84 = Transform::new(&georef.crs, &Crs::wgs84()?)?;
        Ok(SampleLocator { georef, to_wgs84 })
    }

    /// Without PROJ only a grid already in WGS 84 geographic coordinates (EPSG:4326) can be
    /// placed: its coordinates are the geodetic ones, no transformation involved.
    #[cfg(not(feature = "gdal"))]
    pub fn new(georef: &'a Georef) -> Result<Self> {
        let crs = &georef.crs;
        if crs.kind == CrsKind::Geographic && crs.authority.as_deref() == Some("EPSG:4326") {
            return Ok(SampleLocator { georef });
        }
        Err(Error::invalid(
            crs.label(),
            "this vkterrain was built without GDAL/PROJ (--no-default-features): only EPSG:4326 data sets can be placed on the earth",
        ))
    }

    /// WGS84 latitude and longitude (degrees) of sample `(col, row)`'s centre.
    #[cfg(feature = "gdal")]
    pub fn lat_lon(&self, col: f64, row: f64) -> Result<(f64, f64)> {
        let [lon, lat] = self.to_wgs84.point(self.georef.at(col, row))?;
        Ok((lat, lon))
    }

    /// WGS84 latitude and longitude (degrees) of sample `(col, row)`'s centre.
    #[cfg(not(feature = "gdal"))]
    pub fn lat_lon(&self, col: f64, row: f64) -> Result<(f64, f64)> {
        let [x, y] = self.georef.at(col, row);
        let deg = self.georef.crs.unit_size.to_degrees();
        Ok((y * deg, x * deg))
    }
}

/// The world frame of a georeferenced grid: ENU at sample (0, 0), height 0 on the ellipsoid.
pub fn frame_of_georef(georef: &Georef) -> Result<EnuFrame> {
    let (lat, lon) = sample_lat_lon(georef, 0.0, 0.0)?;
    if !(lat.is_finite() && lon.is_finite()) || lat.abs() >= 90.0 {
        return Err(Error::invalid(
            georef.crs.label(),
            format!(
                "sample (0, 0) maps to latitude {lat} / longitude {lon}: no east-north-up frame there"
            ),
        ));
    }
    Ok(EnuFrame::new(&WGS84, Geodetic::new(lat, lon, 0.0)))
}

/// The world frame of a data set with georeferencing `georef` (none for procedural and bare
/// PNG data) and the configured `anchor`: `None` is a flat world. Both given is an error (the
/// data set already says where it lies).
pub fn world_frame(georef: Option<&Georef>, anchor: Option<Anchor>) -> Result<Option<EnuFrame>> {
    match (georef, anchor) {
        (Some(g), None) => frame_of_georef(g).map(Some),
        (None, Some(a)) => {
            a.check()?;
            Ok(Some(EnuFrame::new(
                &WGS84,
                Geodetic::new(a.lat_deg, a.lon_deg, 0.0),
            )))
        }
        (None, None) => Ok(None),
        (Some(g), Some(_)) => Err(Error::invalid(
            "dataset.anchor",
            format!(
                "the data set is georeferenced ({}): it places itself on the earth; remove the anchor",
                g.crs.label()
            ),
        )),
    }
}

/// Where a data set lies on the earth: its world frame, the georeferencing of its level-0
/// grid (none for anchored local data) and the datum of its heights.
#[derive(Clone, Debug)]
pub struct Placement {
    pub frame: EnuFrame,
    /// The native grid and its level-0 size in samples.
    pub georef: Option<(Georef, [u64; 2])>,
    /// `manifest::datum` of the heights.
    pub vertical_datum: String,
}

impl DatasetConfig {
    /// The data set's world frame (see the module doc): reads a `tiles` manifest, opens an
    /// `xyz` source's grid; relative paths are resolved with `resolve`.
    pub fn world_frame(&self, resolve: impl Fn(&Path) -> PathBuf) -> Result<Option<EnuFrame>> {
        Ok(self.placement(resolve)?.map(|p| p.frame))
    }

    /// Where the data set lies on the earth; `None`: a flat world.
    pub fn placement(&self, resolve: impl Fn(&Path) -> PathBuf) -> Result<Option<Placement>> {
        use super::manifest::datum;
        let (georef, vertical_datum) = match self {
            DatasetConfig::Procedural(_) | DatasetConfig::Png16(_) => (None, datum::LOCAL.into()),
            DatasetConfig::Tiles(t) => {
                let m = Dataset::open(&resolve(&t.path))?.manifest;
                let size = [m.width, m.height];
                (m.georef.map(|g| (g, size)), m.vertical_datum)
            }
            DatasetConfig::Xyz(_) => {
                let store = self.open_store(resolve)?;
                let l = store.layout();
                (
                    store.georef()?.map(|g| (g, [l.width, l.height])),
                    store.vertical_datum(),
                )
            }
        };
        let frame = world_frame(georef.as_ref().map(|(g, _)| g), self.anchor())?;
        Ok(frame.map(|frame| Placement {
            frame,
            georef,
            vertical_datum,
        }))
    }
}

impl Placement {
    /// The geoid the data set's heights are measured from (`vertical_datum` `egm96`,
    /// `unknown`: EGM96; `egm2008`); none for ellipsoidal and local heights.
    pub fn geoid_model(&self) -> Option<GeoidModel> {
        GeoidModel::of_datum(&self.vertical_datum)
    }

    /// Whether [`Placement::lattice`] draws the heights on their datum's own zero surface (the
    /// geoid for MSL heights), so that world positions are exact geodetic positions with
    /// ellipsoidal heights: always, except EGM96/EGM2008 heights in a build without PROJ,
    /// which has no geoid (the heights are then drawn above the ellipsoid, and poses convert
    /// with the undulation taken at the camera: docs/coordinates.md "Datums").
    pub fn lattice_on_datum(&self) -> bool {
        self.geoid_model().is_none() || cfg!(feature = "gdal")
    }

    /// The geolocation lattice of `data` (docs/coordinates.md, "Geodetic geometry"): a
    /// georeferenced grid's samples where PROJ puts them (sample `(c, r)` of `data` is the
    /// native sample `(c, r) * data.source_step()`), an anchored local grid's samples dropped
    /// onto the ellipsoid from the tangent plane (`Lattice::anchored_plane`); each node on the
    /// zero surface of the heights' datum ([`Placement::lift`]).
    pub fn lattice(&self, data: &Terrain) -> Result<Lattice> {
        let (w, h) = (data.width(), data.height());
        let Some((georef, _)) = &self.georef else {
            return self.lift(Lattice::anchored_plane(w, h, data.spacing(), self.frame)?);
        };
        let locator = SampleLocator::new(georef)?;
        let [sx, sy] = data.source_step();
        // The largest metric sample spacing, from the grid's own extent: east-west along the
        // first and the last row (the equator-most one is the wider), north-south.
        let metres = |c: f64, r: f64| -> Result<DVec3> {
            let (lat, lon) = locator.lat_lon(c * sx, r * sy)?;
            Ok(WGS84.to_ecef(Geodetic::new(lat, lon, 0.0)))
        };
        let (last_c, last_r) = ((w - 1).max(1) as f64, (h - 1).max(1) as f64);
        let along_row = |r: f64| -> Result<f64> {
            Ok((metres(last_c, r)? - metres(0.0, r)?).length() / last_c)
        };
        let ew = along_row(0.0)?.max(along_row(last_r)?);
        let ns = (metres(0.0, last_r)? - metres(0.0, 0.0)?).length() / last_r;
        let step = Lattice::step_for(w, h, ew.max(ns));
        self.lift(Lattice::new(w, h, step, self.frame, |c, r| {
            locator.lat_lon(c * sx, r * sy)
        })?)
    }

    /// `lattice` (on the ellipsoid) moved onto the zero surface of the heights' datum: for
    /// heights above a geoid every node is lifted by the undulation PROJ gives there (one
    /// batch; a missing grid is PROJ's one-line error, never `N = 0`). Ellipsoidal and local
    /// heights: unchanged. Without PROJ: unchanged, with a warning (see
    /// [`Placement::lattice_on_datum`]).
    pub fn lift(&self, lattice: Lattice) -> Result<Lattice> {
        let Some(model) = self.geoid_model() else {
            return Ok(lattice);
        };
        if !self.lattice_on_datum() {
            tracing::warn!(
                geoid = model.name(),
                "no PROJ in this build: heights above the geoid are drawn above the ellipsoid (off by the undulation's change from the camera)"
            );
            return Ok(lattice);
        }
        let started = std::time::Instant::now();
        let geoid = Geoid::new(model)?;
        let lifted = lattice.on_datum(|points| geoid.undulations(points))?;
        let n = lifted.datum_heights();
        tracing::debug!(
            geoid = model.name(),
            nodes = n.len(),
            min_m = n.iter().copied().fold(f64::INFINITY, f64::min),
            max_m = n.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            ms = started.elapsed().as_secs_f64() * 1e3,
            "geolocation lattice on the geoid"
        );
        Ok(lifted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::WGS84;

    #[test]
    fn anchor_places_a_local_data_set_and_none_is_flat() {
        let a = Anchor {
            lat_deg: 46.5,
            lon_deg: 8.0,
        };
        let f = world_frame(None, Some(a)).unwrap().unwrap();
        assert_eq!(f.origin, Geodetic::new(46.5, 8.0, 0.0));
        assert!((f.origin_ecef - WGS84.to_ecef(f.origin)).length() < 1e-9);
        assert!(world_frame(None, None).unwrap().is_none());
        let bad = Anchor {
            lat_deg: 90.0,
            lon_deg: 0.0,
        };
        let e = world_frame(None, Some(bad)).unwrap_err().to_string();
        assert!(e.contains("dataset.anchor") && !e.contains('\n'), "{e}");
    }

    #[cfg(feature = "gdal")]
    #[test]
    fn geographic_grid_is_anchored_at_its_first_sample() {
        let crs = super::super::crs::Crs::wgs84().unwrap();
        let g = Georef::north_up(
            crs,
            [8.0 + 1.0 / 2400.0, 46.0],
            [1.0 / 1200.0, 1.0 / 1200.0],
        );
        let f = world_frame(Some(&g), None).unwrap().unwrap();
        assert!((f.origin.lat_deg - 46.0).abs() < 1e-9, "{:?}", f.origin);
        assert!((f.origin.lon_deg - (8.0 + 1.0 / 2400.0)).abs() < 1e-9);
        assert_eq!(f.origin.height, 0.0);
        let e = world_frame(
            Some(&g),
            Some(Anchor {
                lat_deg: 1.0,
                lon_deg: 2.0,
            }),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("georeferenced"), "{e}");
    }

    #[cfg(feature = "gdal")]
    #[test]
    fn projected_grid_goes_through_proj() {
        // UTM 32N: easting 500 000 lies on the central meridian 9 E; northing 5 150 000 is
        // 46.503 569 57 N (`echo 500000 5150000 | cs2cs -d 8 EPSG:32632 EPSG:4326`).
        let crs = super::super::crs::Crs::parse("EPSG:32632").unwrap();
        let g = Georef::north_up(crs, [500_000.0, 5_150_000.0], [30.0, 30.0]);
        let f = world_frame(Some(&g), None).unwrap().unwrap();
        assert!((f.origin.lon_deg - 9.0).abs() < 1e-9, "{:?}", f.origin);
        assert!(
            (f.origin.lat_deg - 46.503_569_57).abs() < 1e-8,
            "{:?}",
            f.origin
        );
    }
}

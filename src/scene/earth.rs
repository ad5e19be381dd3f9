//! Cameras placed on the earth: [`GeoPose`] (WGS84 latitude/longitude, a height above the
//! ellipsoid, mean sea level or the ground, heading/pitch/roll in the local NED frame) <->
//! [`Camera`] in the data set's world frame (`docs/coordinates.md` "Datums").
//!
//! **The world's heights.** Drawn on the ellipsoid ([`Earth::on_lattice`]), the geolocation
//! lattice places the terrain's heights on their datum's own zero surface (EGM96 heights on
//! the geoid, `N(lat, lon)` at every node), so world positions are exact geodetic positions:
//! a pose's height is brought to the ellipsoid at the pose (an MSL height gains `N96` there,
//! a ground height the terrain's undulation). In the flat world ([`Earth::new`]), and for
//! geoid heights in a build without PROJ, the world's heights are the terrain's: a pose's
//! height is converted into the terrain's datum at the camera, so terrain far from it is off
//! by the undulation's change from there (EGM96: < 5 m at 50 km in most places).
use std::cell::OnceCell;

use glam::DVec3;

use super::Camera;
use crate::dataset::Level0;
use crate::dataset::crs::{Crs, Georef, Transform};
use crate::dataset::geoid::{Geoid, GeoidModel};
use crate::dataset::world::Placement;
use crate::error::{Error, Result};
use crate::geo::{EnuFrame, GeoPose, Geodetic, HeightRef, WGS84};

/// A data set's place on the earth, with what converting poses needs (PROJ objects made on
/// first use: a build without GDAL converts ellipsoidal and ground poses on local data).
pub struct Earth {
    pub placement: Placement,
    /// The geoid of the terrain's heights (none: ellipsoidal or local heights).
    terrain_geoid: Option<GeoidModel>,
    /// World heights are above the ellipsoid (the terrain drawn on its datum's surface by the
    /// lattice); false: in the terrain's datum (the flat world; geoid heights without PROJ).
    ellipsoidal_world: bool,
    egm96: OnceCell<std::result::Result<Geoid, String>>,
    terrain: OnceCell<std::result::Result<Geoid, String>>,
    /// WGS 84 -> the grid's CRS (georeferenced data).
    to_grid: OnceCell<std::result::Result<Transform, String>>,
}

impl Earth {
    /// The earth of the flat world: world heights are the terrain's (module doc).
    pub fn new(placement: Placement) -> Self {
        Self::with_heights(placement, false)
    }

    /// The earth of a terrain drawn on the ellipsoid through `placement`'s lattice
    /// (`Placement::lattice`): world heights are above the ellipsoid wherever the lattice
    /// carries the terrain's datum (`Placement::lattice_on_datum`).
    pub fn on_lattice(placement: Placement) -> Self {
        let ellipsoidal = placement.lattice_on_datum();
        Self::with_heights(placement, ellipsoidal)
    }

    fn with_heights(placement: Placement, ellipsoidal_world: bool) -> Self {
        Earth {
            terrain_geoid: GeoidModel::of_datum(&placement.vertical_datum),
            ellipsoidal_world,
            placement,
            egm96: OnceCell::new(),
            terrain: OnceCell::new(),
            to_grid: OnceCell::new(),
        }
    }

    pub fn frame(&self) -> &EnuFrame {
        &self.placement.frame
    }

    fn geoid(
        cell: &OnceCell<std::result::Result<Geoid, String>>,
        model: GeoidModel,
    ) -> Result<&Geoid> {
        cell.get_or_init(|| Geoid::new(model).map_err(|e| e.to_string()))
            .as_ref()
            .map_err(|e| Error::invalid("height_ref", e.clone()))
    }

    /// EGM96 undulation (mean sea level above the ellipsoid) at a place.
    pub fn msl_undulation(&self, lat_deg: f64, lon_deg: f64) -> Result<f64> {
        Self::geoid(&self.egm96, GeoidModel::Egm96)?.undulation(lat_deg, lon_deg)
    }

    /// Height of the terrain's datum above the ellipsoid at a place (0: ellipsoidal or local).
    pub fn terrain_undulation(&self, lat_deg: f64, lon_deg: f64) -> Result<f64> {
        match self.terrain_geoid {
            None => Ok(0.0),
            Some(GeoidModel::Egm96) => self.msl_undulation(lat_deg, lon_deg),
            Some(m) => Self::geoid(&self.terrain, m)?.undulation(lat_deg, lon_deg),
        }
    }

    /// Where a latitude/longitude lies in the level-0 grid of `data`, as world metres of the
    /// grid's own addressing (`Level0::bilinear`): through PROJ for a georeferenced grid, the
    /// world frame's east/north for anchored local data.
    pub fn grid_position<D: Level0 + ?Sized>(
        &self,
        data: &D,
        lat_deg: f64,
        lon_deg: f64,
    ) -> Result<(f64, f64)> {
        let Some((georef, _)) = &self.placement.georef else {
            let p = self
                .frame()
                .to_local(WGS84.to_ecef(Geodetic::new(lat_deg, lon_deg, 0.0)));
            return Ok((p.x, p.y));
        };
        let [x, y] = self.to_grid(georef)?.point([lon_deg, lat_deg])?;
        let t = &georef.sample_to_crs;
        let (col, row) = ((x - t[0]) / t[1], (y - t[3]) / t[5]);
        let (step, spacing) = (data.source_step(), data.spacing());
        Ok((col / step[0] * spacing, row / step[1] * spacing))
    }

    /// The latitude/longitude (degrees) of grid position `(x, y)` (world metres of the grid's
    /// own addressing, as [`Earth::grid_position`] returns): the inverse of that, and the
    /// mapping the geolocation lattice draws the grid with (`Placement::lattice`).
    pub fn grid_lat_lon<D: Level0 + ?Sized>(&self, data: &D, x: f64, y: f64) -> Result<(f64, f64)> {
        let Some((georef, _)) = &self.placement.georef else {
            let g = WGS84.to_geodetic(self.frame().to_ecef(DVec3::new(x, y, 0.0)));
            return Ok((g.lat_deg, g.lon_deg));
        };
        let (step, spacing) = (data.source_step(), data.spacing());
        crate::dataset::world::SampleLocator::new(georef)?
            .lat_lon(x / spacing * step[0], y / spacing * step[1])
    }

    /// The WGS84 pose of a camera given on the grid (`position` in the grid's world metres,
    /// `z` in the terrain's datum; yaw/pitch/roll against the grid's axes): over the same
    /// sample, its heading turned by the grid north's own true heading there (meridian
    /// convergence of a projected grid, zero for a geographic one). Its `height_m` is `z`, in
    /// the terrain's datum, which is how the lattice draws the terrain's heights: place it with
    /// [`Earth::camera_at`]`(pose, `[`Earth::terrain_to_world`]`(..), ..)`. Scenarios use it so
    /// that keyframes given on the grid keep their place over the terrain on the ellipsoid.
    pub fn grid_pose<D: Level0 + ?Sized>(
        &self,
        data: &D,
        position: DVec3,
        yaw_deg: f64,
        pitch_deg: f64,
        roll_deg: f64,
    ) -> Result<GeoPose> {
        let (lat, lon) = self.grid_lat_lon(data, position.x, position.y)?;
        // Grid north's true heading: towards the grid point one sample north.
        let (lat_n, lon_n) = self.grid_lat_lon(data, position.x, position.y + data.spacing())?;
        let here = EnuFrame::new(&WGS84, Geodetic::new(lat, lon, 0.0));
        let d = here.to_local(WGS84.to_ecef(Geodetic::new(lat_n, lon_n, 0.0)));
        let convergence = d.x.atan2(d.y).to_degrees();
        Ok(GeoPose {
            lat_deg: lat,
            lon_deg: lon,
            height_m: position.z,
            height_ref: HeightRef::Ellipsoid,
            heading_deg: (yaw_deg + convergence).rem_euclid(360.0),
            pitch_deg,
            roll_deg,
        })
    }

    fn to_grid(&self, georef: &Georef) -> Result<&Transform> {
        self.to_grid
            .get_or_init(|| {
                Crs::wgs84()
                    .and_then(|wgs| Transform::new(&wgs, &georef.crs))
                    .map_err(|e| e.to_string())
            })
            .as_ref()
            .map_err(|e| Error::invalid("height_ref = \"ground\"", e.clone()))
    }

    /// The pose's height in the world's datum (above the ellipsoid, or in the terrain's datum
    /// in the flat world: module doc); `data` answers ground heights.
    pub fn world_height<D: Level0 + ?Sized>(&self, pose: &GeoPose, data: &D) -> Result<f64> {
        let (lat, lon) = (pose.lat_deg, pose.lon_deg);
        if self.ellipsoidal_world {
            return match pose.height_ref {
                HeightRef::Ellipsoid => Ok(pose.height_m),
                HeightRef::Msl => Ok(pose.height_m + self.msl_undulation(lat, lon)?),
                HeightRef::Ground => self.terrain_to_world(lat, lon, self.ground(pose, data)?),
            };
        }
        match pose.height_ref {
            HeightRef::Ellipsoid => Ok(pose.height_m - self.terrain_undulation(lat, lon)?),
            HeightRef::Msl if self.terrain_geoid == Some(GeoidModel::Egm96) => Ok(pose.height_m),
            HeightRef::Msl => Ok(pose.height_m + self.msl_undulation(lat, lon)?
                - self.terrain_undulation(lat, lon)?),
            HeightRef::Ground => self.ground(pose, data),
        }
    }

    /// The world's height (above the ellipsoid, or the terrain's datum in the flat world) of a
    /// point `height` metres above the terrain's datum at a place (grid keyframes).
    pub fn terrain_to_world(&self, lat_deg: f64, lon_deg: f64, height: f64) -> Result<f64> {
        if self.ellipsoidal_world && self.terrain_geoid.is_some() {
            Ok(height + self.terrain_undulation(lat_deg, lon_deg)?)
        } else {
            Ok(height)
        }
    }

    /// A ground pose's height in the terrain's datum: the terrain there plus `height_m`.
    fn ground<D: Level0 + ?Sized>(&self, pose: &GeoPose, data: &D) -> Result<f64> {
        let (lat, lon) = (pose.lat_deg, pose.lon_deg);
        let (x, y) = self.grid_position(data, lat, lon)?;
        let (ex, ey) = data.extent();
        if !(-1e-6 * ex..=ex * (1.0 + 1e-6)).contains(&x)
            || !(-1e-6 * ey..=ey * (1.0 + 1e-6)).contains(&y)
        {
            return Err(Error::invalid(
                "height_ref = \"ground\"",
                format!("{lat} deg, {lon} deg lies outside the data set: no ground there"),
            ));
        }
        Ok(data.bilinear(x, y)? + pose.height_m)
    }

    /// The camera of a pose (`template` gives the field of view and clip planes).
    pub fn camera<D: Level0 + ?Sized>(
        &self,
        pose: &GeoPose,
        data: &D,
        template: &Camera,
    ) -> Result<Camera> {
        pose.validate("pose")?;
        let h = self.world_height(pose, data)?;
        self.camera_at(pose, h, template)
    }

    /// The camera of `pose` at `world_height` metres in the world's datum
    /// ([`Earth::world_height`]; its own `height_m`/`height_ref` unused).
    pub fn camera_at(
        &self,
        pose: &GeoPose,
        world_height: f64,
        template: &Camera,
    ) -> Result<Camera> {
        pose.validate("pose")?;
        let w = pose.to_world(self.frame(), world_height);
        let camera = Camera {
            position: w.position,
            yaw_deg: w.yaw_deg,
            pitch_deg: w.pitch_deg,
            roll_deg: w.roll_deg,
            ..*template
        };
        camera.validate()?;
        Ok(camera)
    }

    /// The WGS84 pose of a camera, its height above the ellipsoid.
    pub fn pose(&self, camera: &Camera) -> Result<GeoPose> {
        let mut p = GeoPose::from_world(self.frame(), &camera.into());
        if !self.ellipsoidal_world {
            p.height_m += self.terrain_undulation(p.lat_deg, p.lon_deg)?;
        }
        Ok(p)
    }

    /// Whether world heights are above the ellipsoid (module doc): the datum of the heights
    /// [`GeoPose::from_world`] reads back from world positions.
    pub fn ellipsoidal_world(&self) -> bool {
        self.ellipsoidal_world
    }

    /// The world position of a geodetic point whose height is in the world's datum.
    pub fn world_position(&self, at: Geodetic) -> DVec3 {
        self.frame().to_local(WGS84.to_ecef(at))
    }
}

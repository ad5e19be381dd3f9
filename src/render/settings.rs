//! The renderer's settings as a config file states them (`[render]`), and the
//! [`RenderOptions`] they make.

use serde::Deserialize;

use super::{MAX_VIEWS, RenderOptions, check_frames_in_flight};
use crate::error::{Error, Result};
use crate::frame::Lighting;
use crate::scene::ViewOffset;

/// Largest render target side accepted before the device is known (its limit is checked too).
pub const MAX_RESOLUTION: u32 = 16384;

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub frames_in_flight: u32,
    /// Also read back the depth buffer (tests and evaluation).
    pub readback_depth: bool,
    /// Linear-space RGB of the sky (clear colour).
    pub sky: [f32; 3],
    /// Direction *towards* the sun: azimuth clockwise from north and elevation, degrees.
    pub sun_azimuth_deg: f32,
    pub sun_elevation_deg: f32,
    /// Aerial perspective: the view depth over which terrain fades `1 - 1/e` of the way to the
    /// sky colour, metres; 0 turns it off.
    pub haze_distance_m: f32,
    /// Further cameras drawn into the same frame, side by side right of the main one (each
    /// view gets `width / views` columns); they share the clipmap's atlas.
    pub extra_views: Vec<ViewOffset>,
    /// The terrain's geometry when the data set lies on the earth (georeferenced or
    /// anchored): `ellipsoid` (default) or `flat`.
    pub earth: EarthGeometry,
}

/// Where the vertices of a data set that lies on the earth go (docs/coordinates.md,
/// "Geodetic geometry"); data sets without a world frame are always flat.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum EarthGeometry {
    /// Every sample where it lies on the WGS84 ellipsoid (the geolocation lattice): the
    /// earth's curvature is in the picture.
    #[default]
    Ellipsoid,
    /// The grid laid out on the world frame's tangent plane (`x = col * spacing`): what
    /// every method drew before issue 14; a point `d` from the frame's origin sits
    /// `d^2 / 2R` too high relative to the earth.
    Flat,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 1280,
            height: 720,
            frames_in_flight: 2,
            readback_depth: false,
            sky: [0.45, 0.62, 0.85],
            sun_azimuth_deg: 135.0,
            sun_elevation_deg: 35.0,
            haze_distance_m: 0.0,
            extra_views: Vec::new(),
            earth: EarthGeometry::default(),
        }
    }
}

impl RenderSettings {
    /// Cameras per frame.
    pub fn views(&self) -> usize {
        1 + self.extra_views.len()
    }

    /// The renderer's options.
    pub fn options(&self) -> RenderOptions {
        let (az, el) = (
            self.sun_azimuth_deg.to_radians(),
            self.sun_elevation_deg.to_radians(),
        );
        RenderOptions {
            width: self.width,
            height: self.height,
            frames_in_flight: self.frames_in_flight as usize,
            readback_depth: self.readback_depth,
            light: Lighting {
                sun_dir: [az.sin() * el.cos(), az.cos() * el.cos(), el.sin()],
                sky: self.sky,
                haze_distance_m: self.haze_distance_m,
            },
            views: self.views(),
            earth: self.earth,
        }
    }

    /// Checks what serde cannot (ranges, finiteness); the device's limits are checked when
    /// the renderer is created.
    pub fn validate(&self) -> Result<()> {
        if self.width == 0
            || self.height == 0
            || self.width > MAX_RESOLUTION
            || self.height > MAX_RESOLUTION
        {
            return Err(Error::invalid(
                "resolution",
                format!(
                    "{}x{} is outside 1..={MAX_RESOLUTION} per side",
                    self.width, self.height
                ),
            ));
        }
        check_frames_in_flight(self.frames_in_flight as usize)?;
        if self.extra_views.len() > MAX_VIEWS - 1 {
            return Err(Error::invalid(
                "render.extra_views",
                format!(
                    "{} extra views; at most {MAX_VIEWS} views per frame",
                    self.extra_views.len()
                ),
            ));
        }
        if self.views() as u64 > self.width as u64 {
            return Err(Error::invalid(
                "render.extra_views",
                format!(
                    "{} views do not fit in {} columns",
                    self.views(),
                    self.width
                ),
            ));
        }
        for v in &self.extra_views {
            v.validate()?;
        }
        if self
            .sky
            .iter()
            .chain([&self.sun_azimuth_deg, &self.sun_elevation_deg])
            .any(|v| !v.is_finite())
        {
            return Err(Error::invalid(
                "render",
                "sky colour and sun angles must be finite",
            ));
        }
        if !(self.haze_distance_m.is_finite() && self.haze_distance_m >= 0.0) {
            return Err(Error::invalid(
                "render.haze_distance_m",
                format!("{} must be finite and >= 0", self.haze_distance_m),
            ));
        }
        Ok(())
    }
}

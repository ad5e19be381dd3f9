//! The camera: right-handed, **z up**, x east, y north, metres.
//!
//! `yaw` is the heading in degrees clockwise from north (0 looks along +y, 90 along +x);
//! `pitch` is degrees above the horizon (-90 looks straight down); `roll` banks like an
//! aircraft: positive lowers the right side (the image content turns counter-clockwise). Projection is **reversed-Z** (depth 1 at `near`, 0 at
//! `far`) into a 32-bit float depth buffer, which keeps depth precision roughly constant in
//! relative terms out to 100+ km. Rendering is camera-relative: the view matrix has no
//! translation, vertices are made relative to the camera in the shader (see `docs/`).

use glam::{DVec3, Mat4, Vec3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geo::pose::euler_basis;

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// World position in metres (f64: precise far from the origin).
    pub position: DVec3,
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    /// Vertical field of view in degrees.
    pub vfov_deg: f64,
    pub near: f64,
    pub far: f64,
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            position: DVec3::new(0.0, 0.0, 1000.0),
            yaw_deg: 0.0,
            pitch_deg: -20.0,
            roll_deg: 0.0,
            vfov_deg: 60.0,
            near: 1.0,
            far: 200_000.0,
        }
    }
}

impl Camera {
    /// Rejects NaN/infinite values and absurd parameters with a one-line reason.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("camera", m));
        let p = self.position;
        if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
            return bad(format!("position {p} is not finite"));
        }
        for (name, v) in [
            ("yaw", self.yaw_deg),
            ("pitch", self.pitch_deg),
            ("roll", self.roll_deg),
        ] {
            if !v.is_finite() {
                return bad(format!("{name} {v} is not finite"));
            }
        }
        if !(-90.0..=90.0).contains(&self.pitch_deg) {
            return bad(format!("pitch {} deg is outside [-90, 90]", self.pitch_deg));
        }
        if !(self.vfov_deg.is_finite() && self.vfov_deg > 0.1 && self.vfov_deg < 179.0) {
            return bad(format!(
                "vertical FOV {} deg is outside (0.1, 179)",
                self.vfov_deg
            ));
        }
        if !(self.near.is_finite() && self.near > 0.0) {
            return bad(format!("near plane {} m must be positive", self.near));
        }
        if !(self.far.is_finite() && self.far > self.near) {
            return bad(format!(
                "far plane {} m must be finite and beyond near {} m",
                self.far, self.near
            ));
        }
        Ok(())
    }

    /// Camera basis in world space: (right, up, forward) (`geo::pose::euler_basis`).
    pub fn basis(&self) -> (DVec3, DVec3, DVec3) {
        euler_basis(self.yaw_deg, self.pitch_deg, self.roll_deg)
    }

    /// World -> view rotation (no translation: positions are camera-relative).
    pub fn view_rotation(&self) -> Mat4 {
        let (_, up, forward) = self.basis();
        Mat4::look_to_rh(Vec3::ZERO, forward.as_vec3(), up.as_vec3())
    }

    /// Reversed-Z perspective projection in WebGPU clip space (depth 1 at near, 0 at far).
    pub fn projection(&self, aspect: f64) -> Mat4 {
        // glam's [0,1]-depth projection with near and far swapped is exactly reversed-Z.
        Mat4::perspective_rh(
            self.vfov_deg.to_radians() as f32,
            aspect as f32,
            self.far as f32,
            self.near as f32,
        )
    }

    /// View distance along the forward axis for a reversed-Z depth value.
    pub fn linear_depth(&self, depth: f32) -> f64 {
        let (n, f) = (self.near, self.far);
        n * f / (depth as f64 * (f - n) + n)
    }

    /// Focal length in pixels for an image `height` pixels tall.
    pub fn focal_px(&self, height: u32) -> f64 {
        height as f64 / 2.0 / (self.vfov_deg.to_radians() / 2.0).tan()
    }

    /// World-space direction of the ray through pixel centre `(px, py)` (py down from the top).
    pub fn pixel_ray(&self, px: f64, py: f64, width: u32, height: u32) -> DVec3 {
        let (right, up, forward) = self.basis();
        let f = self.focal_px(height);
        let sx = px - width as f64 / 2.0;
        let sy = height as f64 / 2.0 - py;
        (forward * f + right * sx + up * sy).normalize()
    }
}

/// A further camera drawn into the same frame as the scripted one (config
/// `[[render.extra_views]]`): placed relative to it, so it follows the scenario.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ViewOffset {
    /// Added to the main camera's position: east, north, up in metres (on the earth: in the
    /// local frame at the main camera, [`ViewOffset::apply_on`]).
    pub offset_m: [f64; 3],
    /// Added to the main camera's heading, degrees (180: a rear view).
    pub yaw_deg: f64,
    /// The view's own pitch in degrees (on the earth: in the local frame); the main camera's
    /// when absent.
    pub pitch_deg: Option<f64>,
}

impl Default for ViewOffset {
    fn default() -> Self {
        ViewOffset {
            offset_m: [0.0; 3],
            yaw_deg: 0.0,
            pitch_deg: None,
        }
    }
}

impl From<&Camera> for crate::geo::WorldPose {
    /// The camera's position and world yaw/pitch/roll (for `GeoPose::from_world`).
    fn from(c: &Camera) -> Self {
        crate::geo::WorldPose {
            position: c.position,
            yaw_deg: c.yaw_deg,
            pitch_deg: c.pitch_deg,
            roll_deg: c.roll_deg,
        }
    }
}

impl ViewOffset {
    /// The camera this offset makes of `main`.
    pub fn apply(&self, main: &Camera) -> Camera {
        let [x, y, z] = self.offset_m;
        Camera {
            position: main.position + DVec3::new(x, y, z),
            yaw_deg: main.yaw_deg + self.yaw_deg,
            pitch_deg: self.pitch_deg.unwrap_or(main.pitch_deg),
            ..*main
        }
    }

    /// The camera this offset makes of `main` on the earth (`world`: the world frame, when the
    /// terrain is drawn on the ellipsoid; None: [`ViewOffset::apply`]): the offset in metres
    /// east/north/up and the heading/pitch in the local north-east-down frame at the main
    /// camera, as a camera rig mounted on a vehicle is described. Far from the world frame's
    /// origin its axes tilt against the local ones (0.45 deg at 50 km), which `apply` ignores.
    pub fn apply_on(&self, main: &Camera, world: Option<&crate::geo::EnuFrame>) -> Camera {
        use crate::geo::{EnuFrame, GeoPose, Geodetic, WGS84};
        let Some(world) = world else {
            return self.apply(main);
        };
        let main_pose = GeoPose::from_world(world, &main.into());
        let here = EnuFrame::new(
            &WGS84,
            Geodetic::new(main_pose.lat_deg, main_pose.lon_deg, main_pose.height_m),
        );
        let offset = world.rotate_to_local(here.rotate_to_ecef(DVec3::from(self.offset_m)));
        let at = WGS84.to_geodetic(world.to_ecef(main.position + offset));
        let view = GeoPose {
            lat_deg: at.lat_deg,
            lon_deg: at.lon_deg,
            height_m: at.height,
            heading_deg: main_pose.heading_deg + self.yaw_deg,
            pitch_deg: self.pitch_deg.unwrap_or(main_pose.pitch_deg),
            ..main_pose
        }
        .to_world(world, at.height);
        Camera {
            position: view.position,
            yaw_deg: view.yaw_deg,
            pitch_deg: view.pitch_deg,
            roll_deg: view.roll_deg,
            ..*main
        }
    }

    /// Rejects non-finite values and pitches outside [-90, 90] with a one-line reason.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("render.extra_views", m));
        if self.offset_m.iter().any(|v| !v.is_finite()) || !self.yaw_deg.is_finite() {
            return bad(format!(
                "offset {:?} m and yaw {} deg must be finite",
                self.offset_m, self.yaw_deg
            ));
        }
        if let Some(p) = self.pitch_deg
            && !(p.is_finite() && (-90.0..=90.0).contains(&p))
        {
            return bad(format!("pitch {p} deg is outside [-90, 90]"));
        }
        Ok(())
    }
}

//! Poses on the earth: WGS84 latitude/longitude, a height with its reference, and an attitude
//! in the local north-east-down frame, with the exact conversion to and from a world frame.
//!
//! **Attitude convention** (aerospace, `docs/coordinates.md` "Poses on the earth"): yaw, pitch,
//! roll applied in that order (Z-Y-X, intrinsic) to the local NED frame at the pose itself:
//! `heading` clockwise from true north (0 north, 90 east), `pitch` nose up positive, `roll`
//! right wing down positive. The camera looks along the body's x axis (the nose); its image
//! right is the right wing, its image up the body's -z. vkterrain's `Camera` uses the same
//! three angles against the world's axes (x east, y north, z up): converting between the two
//! is a change of frame, done exactly through ECEF (meridian convergence and the tilt of the
//! local vertical away from the world origin are included).

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

use super::ellipsoid::{Geodetic, WGS84};
use super::frame::EnuFrame;
use crate::error::{Error, Result};

/// What a pose's height is measured from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeightRef {
    /// Above the WGS84 ellipsoid (what GNSS receivers report).
    #[default]
    Ellipsoid,
    /// Above mean sea level: the EGM96 geoid (through PROJ's `egm96_15.gtx`).
    Msl,
    /// Above the terrain under the pose (the data set's height there, CPU query).
    Ground,
}

impl HeightRef {
    pub fn name(self) -> &'static str {
        match self {
            HeightRef::Ellipsoid => "ellipsoid",
            HeightRef::Msl => "msl",
            HeightRef::Ground => "ground",
        }
    }
}

/// A camera pose on the earth (see the module doc for the attitude convention).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeoPose {
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// Metres above `height_ref`.
    pub height_m: f64,
    pub height_ref: HeightRef,
    pub heading_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
}

/// Right, up and forward unit vectors of yaw/pitch/roll (degrees) in an east-north-up frame:
/// yaw clockwise from north (+y) about up, pitch above the horizontal plane, roll about the
/// forward axis lowering the right side. The one definition behind `scene::Camera::basis`.
pub fn euler_basis(yaw_deg: f64, pitch_deg: f64, roll_deg: f64) -> (DVec3, DVec3, DVec3) {
    let (yaw, pitch, roll) = (
        yaw_deg.to_radians(),
        pitch_deg.to_radians(),
        roll_deg.to_radians(),
    );
    let forward = DVec3::new(
        yaw.sin() * pitch.cos(),
        yaw.cos() * pitch.cos(),
        pitch.sin(),
    );
    // At pitch +-90 the heading still defines "right", so straight-down views keep a stable
    // orientation instead of a degenerate cross product.
    let right0 = DVec3::new(yaw.cos(), -yaw.sin(), 0.0);
    let up0 = right0.cross(forward);
    // A positive angle about `forward` turns `right` towards -z (right-hand rule).
    let rot = DMat3::from_axis_angle(forward, roll);
    (rot * right0, rot * up0, forward)
}

/// The yaw/pitch/roll (degrees) of an orthonormal camera basis given by its `right` and
/// `forward` vectors in an east-north-up frame: the inverse of [`euler_basis`]. Yaw in
/// [0, 360), roll in (-180, 180]; looking straight up or down, the yaw is the one that makes
/// the roll 0.
pub fn euler_from_basis(right: DVec3, forward: DVec3) -> (f64, f64, f64) {
    let pitch = forward.z.clamp(-1.0, 1.0).asin();
    let horizontal = forward.x.hypot(forward.y);
    if horizontal < 1e-12 {
        // Gimbal lock: `right` is horizontal, = (cos yaw, -sin yaw, 0) with roll 0.
        let yaw = (-right.y).atan2(right.x);
        return (wrap360(yaw.to_degrees()), pitch.to_degrees(), 0.0);
    }
    let yaw = forward.x.atan2(forward.y);
    let right0 = DVec3::new(yaw.cos(), -yaw.sin(), 0.0);
    let up0 = right0.cross(forward);
    // right = cos(roll) right0 - sin(roll) up0.
    let roll = (-right.dot(up0)).atan2(right.dot(right0));
    (
        wrap360(yaw.to_degrees()),
        pitch.to_degrees(),
        roll.to_degrees(),
    )
}

fn wrap360(deg: f64) -> f64 {
    let w = deg.rem_euclid(360.0);
    if w >= 360.0 { 0.0 } else { w }
}

/// A camera position and attitude in a world frame, as `scene::Camera` holds them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldPose {
    pub position: DVec3,
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
}

impl GeoPose {
    /// Rejects non-finite values and impossible angles with a one-line reason naming `what`.
    pub fn validate(&self, what: &str) -> Result<()> {
        let bad = |m: String| Err(Error::invalid(what, m));
        let vals = [
            ("lat_deg", self.lat_deg),
            ("lon_deg", self.lon_deg),
            ("height_m", self.height_m),
            ("heading_deg", self.heading_deg),
            ("pitch_deg", self.pitch_deg),
            ("roll_deg", self.roll_deg),
        ];
        if let Some((name, v)) = vals.iter().find(|(_, v)| !v.is_finite()) {
            return bad(format!("{name} {v} is not finite"));
        }
        if self.lat_deg.abs() >= 90.0 {
            return bad(format!(
                "latitude {} deg: need -90 < lat < 90 (no heading is defined at a pole)",
                self.lat_deg
            ));
        }
        if self.lon_deg.abs() > 360.0 {
            return bad(format!(
                "longitude {} deg is outside [-360, 360]",
                self.lon_deg
            ));
        }
        if !(-90.0..=90.0).contains(&self.pitch_deg) {
            return bad(format!("pitch {} deg is outside [-90, 90]", self.pitch_deg));
        }
        if self.height_m.abs() > 1.0e7 {
            return bad(format!("height {} m is beyond 10 000 km", self.height_m));
        }
        Ok(())
    }

    /// The world pose of this pose whose height, already resolved to metres above the
    /// ellipsoid of the world frame's datum, is `height`: the position through ECEF, the
    /// attitude re-expressed from the local frame at the pose into `world`'s axes.
    pub fn to_world(&self, world: &EnuFrame, height: f64) -> WorldPose {
        let at = Geodetic::new(self.lat_deg, self.lon_deg, height);
        let position = world.to_local(WGS84.to_ecef(at));
        let local = EnuFrame::new(&WGS84, at);
        let (right, _, forward) = euler_basis(self.heading_deg, self.pitch_deg, self.roll_deg);
        let to_world = |v: DVec3| world.rotate_to_local(local.rotate_to_ecef(v));
        let (yaw_deg, pitch_deg, roll_deg) = euler_from_basis(to_world(right), to_world(forward));
        WorldPose {
            position,
            yaw_deg,
            pitch_deg,
            roll_deg,
        }
    }

    /// The pose of a world pose: latitude, longitude, height above the ellipsoid (to be
    /// re-referenced by the caller: `height_ref` is [`HeightRef::Ellipsoid`]) and the attitude
    /// in the local frame at the camera.
    pub fn from_world(world: &EnuFrame, pose: &WorldPose) -> GeoPose {
        let at = WGS84.to_geodetic(world.to_ecef(pose.position));
        let local = EnuFrame::new(&WGS84, at);
        let (right, _, forward) = euler_basis(pose.yaw_deg, pose.pitch_deg, pose.roll_deg);
        let to_local = |v: DVec3| local.rotate_to_local(world.rotate_to_ecef(v));
        let (heading_deg, pitch_deg, roll_deg) =
            euler_from_basis(to_local(right), to_local(forward));
        GeoPose {
            lat_deg: at.lat_deg,
            lon_deg: at.lon_deg,
            height_m: at.height,
            height_ref: HeightRef::Ellipsoid,
            heading_deg,
            pitch_deg,
            roll_deg,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(lat: f64, lon: f64, h: f64, hd: f64, p: f64, r: f64) -> GeoPose {
        GeoPose {
            lat_deg: lat,
            lon_deg: lon,
            height_m: h,
            height_ref: HeightRef::Ellipsoid,
            heading_deg: hd,
            pitch_deg: p,
            roll_deg: r,
        }
    }

    #[test]
    fn euler_round_trip() {
        for yaw in [0.0, 10.0, 90.0, 179.0, 181.0, 359.5] {
            for pitch in [-89.0, -30.0, 0.0, 45.0, 89.9] {
                for roll in [-170.0, -20.0, 0.0, 5.0, 179.0] {
                    let (r, _, f) = euler_basis(yaw, pitch, roll);
                    let (y2, p2, r2) = euler_from_basis(r, f);
                    let (r3, u3, f3) = euler_basis(y2, p2, r2);
                    let (_, u, _) = euler_basis(yaw, pitch, roll);
                    assert!((r3 - r).length() < 1e-12 && (u3 - u).length() < 1e-12);
                    assert!((f3 - f).length() < 1e-12);
                    assert!((y2 - yaw).abs() < 1e-9 && (p2 - pitch).abs() < 1e-9);
                    assert!((r2 - roll).abs() < 1e-9, "{yaw} {pitch} {roll} -> {r2}");
                }
            }
        }
        // Straight down: the basis survives, with roll folded into yaw.
        let (r, u, f) = euler_basis(30.0, -90.0, 20.0);
        let (y2, p2, r2) = euler_from_basis(r, f);
        let (r3, u3, f3) = euler_basis(y2, p2, r2);
        assert!((r3 - r).length() < 1e-9 && (u3 - u).length() < 1e-9 && (f3 - f).length() < 1e-9);
    }

    #[test]
    fn at_the_origin_local_and_world_attitudes_agree() {
        let world = EnuFrame::new(&WGS84, Geodetic::new(46.5, 8.0, 0.0));
        let w = pose(46.5, 8.0, 1200.0, 33.0, -12.0, 4.0).to_world(&world, 1200.0);
        assert!((w.position - DVec3::new(0.0, 0.0, 1200.0)).length() < 1e-6);
        assert!((w.yaw_deg - 33.0).abs() < 1e-9, "{w:?}");
        assert!((w.pitch_deg + 12.0).abs() < 1e-9 && (w.roll_deg - 4.0).abs() < 1e-9);
    }

    #[test]
    fn world_round_trip_far_from_the_origin() {
        let world = EnuFrame::new(&WGS84, Geodetic::new(45.0, 7.0, 0.0));
        for (lat, lon) in [
            (45.0, 7.0),
            (45.45, 7.0),
            (45.0, 7.7),
            (44.2, 6.1),
            (46.3, 8.9),
        ] {
            for (hd, p, r) in [(0.0, 0.0, 0.0), (123.0, -35.0, 12.0), (271.0, 60.0, -80.0)] {
                let g = pose(lat, lon, 3456.0, hd, p, r);
                let w = g.to_world(&world, g.height_m);
                let back = GeoPose::from_world(&world, &w);
                assert!((back.lat_deg - lat).abs() < 1e-10 && (back.lon_deg - lon).abs() < 1e-10);
                assert!((back.height_m - 3456.0).abs() < 1e-6, "{back:?}");
                assert!((back.heading_deg - hd).abs() < 1e-8, "{g:?} -> {back:?}");
                assert!((back.pitch_deg - p).abs() < 1e-8 && (back.roll_deg - r).abs() < 1e-8);
            }
        }
    }

    #[test]
    fn level_camera_50_km_away_looks_at_its_own_horizon() {
        let world = EnuFrame::new(&WGS84, Geodetic::new(45.0, 7.0, 0.0));
        // 50 km north along the meridian, looking north and level.
        let dlat = (50_000.0 / WGS84.meridian_radius(45.0)).to_degrees();
        let at = Geodetic::new(45.0 + dlat, 7.0, 1000.0);
        let w = pose(at.lat_deg, at.lon_deg, 1000.0, 0.0, 0.0, 0.0).to_world(&world, 1000.0);
        let (_, _, forward) = euler_basis(w.yaw_deg, w.pitch_deg, w.roll_deg);
        // Its own ellipsoid normal in the world frame, computed independently here.
        let (sl, cl) = at.lat_deg.to_radians().sin_cos();
        let (so, co) = at.lon_deg.to_radians().sin_cos();
        let normal = world.rotate_to_local(DVec3::new(cl * co, cl * so, sl));
        assert!(forward.dot(normal).abs() < 1e-12, "{forward} . {normal}");
        // Negative control: level against the world's z would be 0.45 deg off (50 km / R).
        let tilt = forward.z.asin().to_degrees();
        assert!((tilt + 0.4495).abs() < 0.002, "{tilt}");
        // And the position lies 50 km north and about 196 m below the tangent plane + 1000 m.
        assert!((w.position.y - 50_000.0).abs() < 30.0 && (w.position.z - 804.0).abs() < 3.0);
    }

    #[test]
    fn meridian_convergence_turns_the_heading() {
        // 100 km east of the origin at 60 N, a camera heading true north has a world yaw of
        // about -(dlon * sin lat): meridians converge.
        let world = EnuFrame::new(&WGS84, Geodetic::new(60.0, 10.0, 0.0));
        let dlon = (100_000.0 / (WGS84.prime_vertical_radius(60.0) * 60f64.to_radians().cos()))
            .to_degrees();
        let w = pose(60.0, 10.0 + dlon, 500.0, 0.0, 0.0, 0.0).to_world(&world, 500.0);
        let want = -dlon * 60f64.to_radians().sin();
        let yaw = if w.yaw_deg > 180.0 {
            w.yaw_deg - 360.0
        } else {
            w.yaw_deg
        };
        assert!((yaw - want).abs() < 0.01, "{yaw} vs {want}");
        assert!(want.abs() > 1.0);
    }

    #[test]
    fn validation_names_the_problem() {
        let e = pose(90.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            .validate("camera")
            .unwrap_err();
        assert!(e.to_string().contains("latitude"), "{e}");
        let e = pose(0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0)
            .validate("camera")
            .unwrap_err();
        assert!(e.to_string().contains("height_m"), "{e}");
        assert!(
            pose(-33.9, 151.2, 50.0, 350.0, -89.0, 30.0)
                .validate("c")
                .is_ok()
        );
    }
}

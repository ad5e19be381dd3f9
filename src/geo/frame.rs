//! Local east-north-up (ENU) tangent frames on the ellipsoid.

use glam::{DMat3, DVec3};

use super::ellipsoid::{Ellipsoid, Geodetic};

/// A right-handed east-north-up frame whose origin is a geodetic point: x east, y north, z along
/// the ellipsoid normal. vkterrain's world frame (docs/coordinates.md) is such a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnuFrame {
    pub origin: Geodetic,
    pub origin_ecef: DVec3,
    /// Rows: east, north, up unit vectors in ECEF (so `ecef_to_enu * v` rotates ECEF -> ENU).
    pub ecef_to_enu: DMat3,
}

impl EnuFrame {
    pub fn new(ellipsoid: &Ellipsoid, origin: Geodetic) -> Self {
        let (sl, cl) = origin.lat_deg.to_radians().sin_cos();
        let (so, co) = origin.lon_deg.to_radians().sin_cos();
        let east = DVec3::new(-so, co, 0.0);
        let north = DVec3::new(-sl * co, -sl * so, cl);
        let up = DVec3::new(cl * co, cl * so, sl);
        EnuFrame {
            origin,
            origin_ecef: ellipsoid.to_ecef(origin),
            // glam matrices are column-major: the transpose of (east | north | up).
            ecef_to_enu: DMat3::from_cols(east, north, up).transpose(),
        }
    }

    /// ENU coordinates (metres) of an ECEF position.
    pub fn to_local(&self, ecef: DVec3) -> DVec3 {
        self.ecef_to_enu * (ecef - self.origin_ecef)
    }

    /// ECEF position of ENU coordinates.
    pub fn to_ecef(&self, local: DVec3) -> DVec3 {
        self.origin_ecef + self.ecef_to_enu.transpose() * local
    }

    /// Rotates a direction given in ECEF into this frame.
    pub fn rotate_to_local(&self, dir_ecef: DVec3) -> DVec3 {
        self.ecef_to_enu * dir_ecef
    }

    /// Rotates a direction given in this frame into ECEF.
    pub fn rotate_to_ecef(&self, dir_local: DVec3) -> DVec3 {
        self.ecef_to_enu.transpose() * dir_local
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::WGS84;

    #[test]
    fn origin_is_zero_and_up_is_the_normal() {
        let f = EnuFrame::new(&WGS84, Geodetic::new(46.5, 8.0, 300.0));
        assert!(f.to_local(f.origin_ecef).length() < 1e-9);
        // 100 m straight up along the normal is (0, 0, 100).
        let above = WGS84.to_ecef(Geodetic::new(46.5, 8.0, 400.0));
        assert!((f.to_local(above) - DVec3::new(0.0, 0.0, 100.0)).length() < 1e-6);
        // A point a little north has y > 0 and x ~ 0; a little east has x > 0.
        let n = f.to_local(WGS84.to_ecef(Geodetic::new(46.51, 8.0, 300.0)));
        assert!(n.y > 1000.0 && n.x.abs() < 1e-6, "{n}");
        let e = f.to_local(WGS84.to_ecef(Geodetic::new(46.5, 8.01, 300.0)));
        assert!(e.x > 700.0 && e.y.abs() < 1.0, "{e}");
    }

    #[test]
    fn round_trip_and_rotation_is_orthonormal() {
        let f = EnuFrame::new(&WGS84, Geodetic::new(-33.9, 151.2, 0.0));
        let p = DVec3::new(1234.5, -9876.5, 42.0);
        assert!((f.to_local(f.to_ecef(p)) - p).length() < 1e-8);
        let m = f.ecef_to_enu * f.ecef_to_enu.transpose();
        assert!(
            (m - DMat3::IDENTITY)
                .to_cols_array()
                .iter()
                .all(|v| v.abs() < 1e-15)
        );
        assert!((f.ecef_to_enu.determinant() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn sea_level_drops_below_the_tangent_plane() {
        // 50 km north at sea level lies ~196 m below the tangent plane (the figure).
        let f = EnuFrame::new(&WGS84, Geodetic::new(45.0, 0.0, 0.0));
        let m = WGS84.meridian_radius(45.0);
        let dlat = (50_000.0 / m).to_degrees();
        let p = f.to_local(WGS84.to_ecef(Geodetic::new(45.0 + dlat, 0.0, 0.0)));
        assert!((p.z + 196.0).abs() < 2.0, "{p}");
    }
}

//! PGM on the earth (docs/pgm.md, "On the earth"): the auxiliary camera stands in the local
//! frame at the sample under the camera, and its grid rays meet a **reference sphere** (the
//! mean radius of curvature there, raised to the reference height) instead of a plane. Each
//! ray's point on the sphere is mapped to the sample under it through the geolocation lattice
//! on the GPU (`lattice_invert`, shared with the evaluator), so the vertex is placed by
//! `project(cell, frac, h)` like every other method's; only where the grid's vertices land
//! (the screen's coverage) depends on the sphere.

use glam::{DMat3, DVec2, DVec3};

use crate::geo::pose::euler_from_basis;
use crate::geo::{Lattice, WGS84};
use crate::scene::Camera;

/// Where the auxiliary camera stands on the earth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AuxEarth {
    /// Columns: the local frame's axes in world coordinates: x east and y north (the world's
    /// north projected onto the tangent plane), z the up vector at the camera's sample.
    pub axes: DMat3,
    /// The sample position under the camera (columns, rows) and the camera's height above
    /// the lattice surface (the ellipsoid) there (m): [`Lattice::sample_at`].
    pub sample: DVec2,
    pub height_m: f64,
    /// Mean (Gaussian) radius of curvature of the ellipsoid at the camera, `sqrt(M N)` (m).
    pub radius_m: f64,
    /// Rows of the least-squares inverse of the lattice's Jacobian at the camera's sample:
    /// columns and rows per world metre (the shader's first guess for the lattice inverse and
    /// its texel lengths for the mip level).
    pub to_sample: [DVec3; 2],
    /// The reference height (m): the sphere's radius is `radius_m + reference_m`.
    pub reference_m: f64,
}

impl AuxEarth {
    /// The local frame at the sample under world point `position`.
    pub fn at(lattice: &Lattice, position: DVec3) -> AuxEarth {
        let (sample, height_m) = lattice.sample_at(position);
        let base = lattice.position(sample, 0.0);
        let up = (lattice.position(sample, 1.0) - base).normalize();
        let north = (DVec3::Y - up * up.y).normalize();
        let east = north.cross(up);
        let jx = lattice.position(sample + DVec2::X, 0.0) - base;
        let jy = lattice.position(sample + DVec2::Y, 0.0) - base;
        let (a, b, c) = (jx.dot(jx), jx.dot(jy), jy.dot(jy));
        let det = a * c - b * b;
        let to_sample = [(jx * c - jy * b) / det, (jy * a - jx * b) / det];
        let lat = WGS84
            .to_geodetic(lattice.frame.to_ecef(position))
            .lat_deg
            .clamp(-89.999, 89.999);
        let radius_m = (WGS84.meridian_radius(lat) * WGS84.prime_vertical_radius(lat)).sqrt();
        AuxEarth {
            axes: DMat3::from_cols(east, north, up),
            sample,
            height_m,
            radius_m,
            to_sample,
            reference_m: 0.0,
        }
    }

    /// `camera` (world axes) seen in the local frame: its attitude against the local axes, at
    /// `(0, 0, height_m)`.
    pub fn local_camera(&self, camera: &Camera) -> Camera {
        let (r, _, f) = camera.basis();
        let to_local = self.axes.transpose();
        let (yaw_deg, pitch_deg, roll_deg) = euler_from_basis(to_local * r, to_local * f);
        Camera {
            position: DVec3::new(0.0, 0.0, self.height_m),
            yaw_deg,
            pitch_deg,
            roll_deg,
            ..*camera
        }
    }

    /// Radius of the reference sphere (m).
    pub fn sphere_radius(&self) -> f64 {
        self.radius_m + self.reference_m
    }
}

/// The reference sphere seen from `height` metres above it (the auxiliary camera's height).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Radius (m).
    pub radius: f64,
    /// The camera's height above it (m).
    pub height: f64,
}

impl Sphere {
    /// Depression angle of the sphere's horizon below the local horizontal (rad): `cos e =
    /// radius / (radius + height)`; also the central angle to the tangent point.
    pub fn horizon_depression(&self) -> f64 {
        let (rho, a) = (self.radius, self.height);
        (a * (2.0 * rho + a)).sqrt().atan2(rho)
    }

    /// Surface distance (m, along the sphere) of the horizon.
    pub fn horizon_distance(&self) -> f64 {
        self.radius * self.horizon_depression()
    }

    /// The horizon's terms as the shaders read them (`SphereView` in
    /// `shaders/include/pgm_sphere.wgsl`): its depression's sine, its surface distance (m) and
    /// the depression angle (rad).
    pub fn gpu_terms(&self) -> [f32; 3] {
        let e_h = self.horizon_depression();
        [e_h.sin() as f32, self.horizon_distance() as f32, e_h as f32]
    }

    /// Surface distance (m, along the sphere) of the point a ray with depression sine `s`
    /// (`-dir.up` of the unit direction) stands for, at most `max_distance`: where it meets
    /// the sphere; a ray above the sphere's horizon (it misses) takes a distance between the
    /// horizon's (at the horizon) and `max_distance` (at the horizontal and above it),
    /// logarithmic in its depression angle, so rows towards the horizontal keep covering the
    /// terrain beyond the sphere's horizon that rises into view. `sphere_distance` in
    /// `shaders/include/pgm_sphere.wgsl` is the same formula in f32 (tests/pgm.rs
    /// `the_gpu_sphere_distance_equals_the_cpu_one` proves them equal).
    pub fn distance(&self, s: f64, max_distance: f64) -> f64 {
        let (rho, a) = (self.radius, self.height);
        let e_h = self.horizon_depression();
        let sin_h = e_h.sin();
        if s > sin_h {
            let ra = rho + a;
            let disc = ra * ra * (s - sin_h) * (s + sin_h);
            let along = a * (2.0 * rho + a) / (ra * s + disc.sqrt());
            let hl = (1.0 - s * s).max(0.0).sqrt();
            return (rho * (along * hl).atan2(ra - along * s)).min(max_distance);
        }
        let d_h = rho * e_h;
        if d_h < max_distance && s > 0.0 {
            return max_distance * ((d_h / max_distance).ln() * s.asin() / e_h).exp();
        }
        max_distance
    }
}

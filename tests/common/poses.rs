//! The crack/popping tests' camera poses: high straight down, grazing, ground level, outside
//! looking in, and ordinary flight, spread over the data set.

use glam::DVec3;
use vkterrain::dataset::Heightmap;
use vkterrain::scene::Camera;

/// `n` poses over `data`; UDLOD's and GeoMipMapping's tests stand the low cameras on the
/// surface under them.
pub fn poses(data: &Heightmap, n: usize) -> Vec<Camera> {
    poses_over(data, n, |x, y| data.height_at(x, y))
}

/// `n` poses over `data`, the grazing and ground-level cameras `ground(x, y)` plus 2 m / 0.5 m
/// (tessellation's test lifts them above the highest nearby sample: its surface between
/// samples can rise above the bilinear one).
pub fn poses_over(data: &Heightmap, n: usize, ground_of: impl Fn(f64, f64) -> f64) -> Vec<Camera> {
    let (ex, ey) = data.extent();
    let (_, hi) = data.height_range();
    (0..n)
        .map(|i| {
            let f = i as f64 / n as f64;
            let u = (f * 7.31).fract();
            let v = (f * 3.17 + 0.13).fract();
            let (x, y) = match i % 5 {
                3 => (-0.3 * ex, -0.2 * ey + v * ey), // outside, looking in
                _ => (u * ex, v * ey),
            };
            let ground = data.height_at(x, y);
            let low = ground_of(x, y);
            let (z, pitch) = match i % 5 {
                0 => (hi as f64 + 8.0 * ex.max(ey), -90.0), // straight down from high up
                1 => (low + 2.0, -1.0 + 2.0 * v),           // grazing, near the ground
                2 => (low + 0.5, -10.0),                    // at ground level
                3 => (hi as f64 + 200.0, -15.0),            // outside
                _ => (ground + 50.0 + 2000.0 * u, -5.0 - 60.0 * v), // ordinary flight
            };
            let yaw = if i % 5 == 3 {
                60.0 + 60.0 * u
            } else {
                360.0 * ((f * 11.7).fract())
            };
            Camera {
                position: DVec3::new(x, y, z),
                yaw_deg: yaw,
                pitch_deg: pitch,
                near: 0.25,
                ..Camera::default()
            }
        })
        .collect()
}

//! Geometric error of a rendered frame against the exact surface of the data.
//!
//! For every pixel where the method drew terrain, the depth buffer gives the world point `P`
//! the method's surface has on that pixel's ray. Its **height error** is
//! `dh = P.z - h(P.x, P.y)` with `h` the exact surface ([`Heightmap::mesh_height_at`], the
//! full-resolution mesh that brute force draws). Its **screen-space error** is that vertical
//! error projected at the point's distance: `|dh| * focal_px / |P - eye|`, the on-screen length
//! in pixels of a vertical segment `dh` long facing the viewer. This is the quantity UDLOD's
//! pixel target `tau` bounds (`e * focal / d <= tau`), so the two can be compared directly.
//! Measuring against the data (not against another rendered image) keeps the reference
//! independent of any LOD parameter and of rasterization differences along silhouettes.

use glam::DVec3;

use crate::dataset::Heightmap;
use crate::scene::Camera;

/// The error at one pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelError {
    pub x: u32,
    pub y: u32,
    /// Signed vertical error in metres (positive: the method's surface is above the data).
    pub metres: f64,
    /// Screen-space error in pixels (non-negative).
    pub pixels: f64,
}

/// Mean, percentiles and maximum of a set of non-negative values.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Summary {
    pub count: usize,
    pub mean: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
}

impl Summary {
    /// Summary of `values` (NaN-free); all zero when empty. Percentiles are nearest-rank.
    pub fn of(values: &mut [f64]) -> Summary {
        if values.is_empty() {
            return Summary::default();
        }
        values.sort_by(|a, b| a.total_cmp(b));
        let rank = |q: f64| crate::render::stats::nearest_rank(values, q);
        Summary {
            count: values.len(),
            mean: values.iter().sum::<f64>() / values.len() as f64,
            p99: rank(0.99),
            p999: rank(0.999),
            max: values[values.len() - 1],
        }
    }
}

/// World position of the surface seen at pixel `(x, y)` with reversed-Z `depth` (> 0).
pub fn world_point(camera: &Camera, x: u32, y: u32, width: u32, height: u32, depth: f32) -> DVec3 {
    let ray = camera.pixel_ray(x as f64 + 0.5, y as f64 + 0.5, width, height);
    let (_, _, forward) = camera.basis();
    let along_forward = camera.linear_depth(depth);
    camera.position + ray * (along_forward / ray.dot(forward))
}

/// Error of every terrain pixel (depth > 0) whose surface point lies over the data.
pub fn pixel_errors(
    camera: &Camera,
    width: u32,
    height: u32,
    depth: &[f32],
    data: &Heightmap,
) -> Vec<PixelError> {
    let focal = camera.focal_px(height);
    let (x_max, y_max) = data.extent();
    let mut out = Vec::new();
    for y in 0..height {
        for x in 0..width {
            let d = depth[(y * width + x) as usize];
            if d <= 0.0 {
                continue;
            }
            let p = world_point(camera, x, y, width, height, d);
            if !(0.0..=x_max).contains(&p.x) || !(0.0..=y_max).contains(&p.y) {
                continue;
            }
            let metres = p.z - data.mesh_height_at(p.x, p.y);
            let distance = (p - camera.position).length();
            out.push(PixelError {
                x,
                y,
                metres,
                pixels: metres.abs() * focal / distance,
            });
        }
    }
    out
}

/// Summaries of the height error (|metres|) and the screen-space error (pixels).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct GeometricError {
    pub metres: Summary,
    pub pixels: Summary,
}

impl GeometricError {
    pub fn of(errors: &[PixelError]) -> GeometricError {
        let mut metres: Vec<f64> = errors.iter().map(|e| e.metres.abs()).collect();
        let mut pixels: Vec<f64> = errors.iter().map(|e| e.pixels).collect();
        GeometricError {
            metres: Summary::of(&mut metres),
            pixels: Summary::of(&mut pixels),
        }
    }
}

/// Pixels where the reference shows terrain and the method shows sky (holes, cracks).
pub fn holes(reference_depth: &[f32], method_depth: &[f32]) -> usize {
    reference_depth
        .iter()
        .zip(method_depth)
        .filter(|&(&r, &m)| r > 0.0 && m <= 0.0)
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_uses_nearest_rank() {
        let mut v: Vec<f64> = (1..=1000).map(f64::from).collect();
        let s = Summary::of(&mut v);
        assert_eq!(
            (s.count, s.p99, s.p999, s.max),
            (1000, 990.0, 999.0, 1000.0)
        );
        assert!((s.mean - 500.5).abs() < 1e-9);
        assert_eq!(Summary::of(&mut []), Summary::default());
    }

    #[test]
    fn world_point_inverts_the_projection() {
        let camera = Camera {
            position: DVec3::new(100.0, 200.0, 300.0),
            yaw_deg: 30.0,
            pitch_deg: -25.0,
            ..Camera::default()
        };
        let (w, h) = (640, 360);
        let target = DVec3::new(400.0, 900.0, 50.0);
        let proj = camera.projection(w as f64 / h as f64).as_dmat4();
        let view = camera.view_rotation().as_dmat4();
        let clip = proj * view * (target - camera.position).extend(1.0);
        let ndc = clip.truncate() / clip.w;
        // WebGPU clip space: y up, pixel rows down.
        let px = (ndc.x + 1.0) / 2.0 * w as f64 - 0.5;
        let py = (1.0 - ndc.y) / 2.0 * h as f64 - 0.5;
        let (x, y) = (px.round() as u32, py.round() as u32);
        let p = world_point(&camera, x, y, w, h, ndc.z as f32);
        // The pixel centre is within half a pixel of the target's projection.
        let slack = (target - camera.position).length() / camera.focal_px(h);
        assert!(
            (p - target).length() < 1.5 * slack,
            "{p:?} vs {target:?} (slack {slack})"
        );
    }
}

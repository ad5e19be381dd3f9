//! Brute force against exact geometry: a tilted plane and a cone, rendered with depth readback.
//! For each probed pixel the expected view depth comes from intersecting the pixel's centre ray
//! with the analytic surface; the rendered reversed-Z depth must match within 1e-3 relative.
//! Pixels whose footprint straddles a silhouette or the data's edge are skipped (rasterization
//! rules there differ between lavapipe and GPUs); sky coverage is compared as a fraction.

mod common;

use glam::DVec3;
use vkterrain::dataset::procedural::analytic;
use vkterrain::readback::OwnedFrame;
use vkterrain::render::FrameRequest;
use vkterrain::scene::Camera;

const REL_TOL: f64 = 1e-3;

/// First hit of the ray `origin + t * dir` with the top of the surface `z = h(x, y)` over the
/// rectangle `[0, ex] x [0, ey]`, by marching and bisection; None when it misses. Only crossings
/// from above to below count: a ray entering the data's volume through its side sees no top
/// surface there (the mesh has no skirts and back faces are culled).
fn intersect(
    origin: DVec3,
    dir: DVec3,
    ex: f64,
    ey: f64,
    h: &dyn Fn(f64, f64) -> f64,
) -> Option<f64> {
    let inside = |p: DVec3| p.x >= 0.0 && p.y >= 0.0 && p.x <= ex && p.y <= ey;
    let above = |t: f64| {
        let p = origin + dir * t;
        p.z - h(p.x, p.y)
    };
    let (step, t_max) = (0.5, 50_000.0);
    let mut t0 = 0.0;
    let mut a0 = above(t0);
    while t0 < t_max {
        let t1 = t0 + step;
        let a1 = above(t1);
        if a0 > 0.0 && a1 <= 0.0 {
            let (mut lo, mut hi) = (t0, t1);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if above(mid) > 0.0 { lo = mid } else { hi = mid }
            }
            let t = 0.5 * (lo + hi);
            if inside(origin + dir * t) {
                return Some(t);
            }
        }
        (t0, a0) = (t1, a1);
    }
    None
}

struct Check {
    compared: usize,
    worst_rel: f64,
    sky_expected: usize,
    sky_rendered: usize,
    probes: usize,
}

/// Compares a frame against the analytic surface on a grid of probe pixels.
/// `smooth(x, y)` says where the sampled mesh follows the analytic surface closely (away from
/// creases that a grid of samples cannot represent); other hits are not compared.
fn check(
    frame: &OwnedFrame,
    camera: &Camera,
    (ex, ey): (f64, f64),
    h: &dyn Fn(f64, f64) -> f64,
    smooth: &dyn Fn(f64, f64) -> bool,
) -> Check {
    let (w, hgt) = (frame.width, frame.height);
    let (_, _, forward) = camera.basis();
    let mut c = Check {
        compared: 0,
        worst_rel: 0.0,
        sky_expected: 0,
        sky_rendered: 0,
        probes: 0,
    };
    for py in (2..hgt - 2).step_by(6) {
        for px in (2..w - 2).step_by(6) {
            c.probes += 1;
            let (fx, fy) = (px as f64 + 0.5, py as f64 + 0.5);
            let hit = |x: f64, y: f64| {
                let d = camera.pixel_ray(x, y, w, hgt);
                intersect(camera.position, d, ex, ey, h).map(|t| t * d.dot(forward))
            };
            let centre = hit(fx, fy);
            let depth = frame.depth_at(px, py).expect("depth readback");
            if centre.is_none() {
                c.sky_expected += 1;
            }
            if depth == 0.0 {
                c.sky_rendered += 1;
            }
            // Skip footprints that straddle a silhouette, an edge or a crease of the surface.
            let corners = [(-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)]
                .map(|(dx, dy)| hit(fx + dx, fy + dy));
            let Some(expected) = centre else { continue };
            let p = camera.position
                + camera.pixel_ray(fx, fy, w, hgt)
                    * (expected / camera.pixel_ray(fx, fy, w, hgt).dot(forward));
            if !smooth(p.x, p.y) {
                continue;
            }
            if corners
                .iter()
                .any(|c| c.is_none_or(|d| (d - expected).abs() > 0.05 * expected))
            {
                continue;
            }
            assert!(
                depth > 0.0,
                "pixel ({px},{py}) expected terrain at {expected:.2} m, got sky"
            );
            let rendered = camera.linear_depth(depth);
            let rel = (rendered - expected).abs() / expected;
            assert!(
                rel < REL_TOL,
                "pixel ({px},{py}): depth {rendered:.3} m vs analytic {expected:.3} m (rel {rel:.2e})"
            );
            c.worst_rel = c.worst_rel.max(rel);
            c.compared += 1;
        }
    }
    c
}

fn render_one(data: &vkterrain::dataset::Heightmap, camera: Camera, legacy: bool) -> OwnedFrame {
    let gpu = common::gpu(legacy);
    let mut frames = common::render(
        &gpu,
        data,
        common::options(320, 200, 2),
        &[FrameRequest::from(camera)],
    );
    assert_eq!(frames.len(), 1);
    frames.remove(0)
}

#[test]
fn tilted_plane_depth_matches_ray_intersection() {
    let (size, spacing, z0, gx, gy) = (129u32, 10.0, 100.0, 0.20, -0.12);
    let data = analytic::plane(size, spacing, z0, gx, gy).unwrap();
    let (ex, ey) = data.extent();
    let h = move |x: f64, y: f64| z0 + gx * x + gy * y;
    let camera = Camera {
        position: DVec3::new(-150.0, -200.0, 500.0),
        yaw_deg: 35.0,
        pitch_deg: -22.0,
        ..Camera::default()
    };
    let frame = render_one(&data, camera, false);
    let c = check(&frame, &camera, (ex, ey), &h, &|_, _| true);
    println!(
        "plane: {} of {} probes compared, worst rel error {:.2e}",
        c.compared, c.probes, c.worst_rel
    );
    // The view shows both terrain and sky, so both branches of the check ran.
    assert!(
        c.compared > c.probes / 4,
        "too few terrain pixels compared: {}",
        c.compared
    );
    assert!(
        c.sky_expected > c.probes / 10,
        "camera should see sky: {}",
        c.sky_expected
    );
    let diff = c.sky_expected.abs_diff(c.sky_rendered) as f64 / c.probes as f64;
    assert!(
        diff < 0.02,
        "sky coverage differs: expected {} rendered {} of {}",
        c.sky_expected,
        c.sky_rendered,
        c.probes
    );
}

#[test]
fn cone_depth_and_silhouette_match() {
    let (size, spacing, peak, radius) = (257u32, 4.0, 300.0, 400.0);
    let data = analytic::cone(size, spacing, peak, radius).unwrap();
    let (ex, ey) = data.extent();
    let centre = ex / 2.0;
    let h = move |x: f64, y: f64| {
        let d = ((x - centre).powi(2) + (y - centre).powi(2)).sqrt();
        (peak * (1.0 - d / radius)).max(0.0)
    };
    // Low and to the south-west, looking at the peak: the cone's silhouette cuts the sky.
    let camera = Camera {
        position: DVec3::new(centre - 700.0, centre - 700.0, 120.0),
        yaw_deg: 45.0,
        pitch_deg: 2.0,
        ..Camera::default()
    };
    // A grid cannot follow the apex and the rim crease exactly: skip hits within two samples.
    let smooth = move |x: f64, y: f64| {
        let d = ((x - centre).powi(2) + (y - centre).powi(2)).sqrt();
        d > 2.0 * spacing && (d - radius).abs() > 2.0 * spacing
    };
    let frame = render_one(&data, camera, false);
    let c = check(&frame, &camera, (ex, ey), &h, &smooth);
    println!(
        "cone: {} of {} probes compared, worst rel error {:.2e}",
        c.compared, c.probes, c.worst_rel
    );
    assert!(
        c.compared > c.probes / 8,
        "too few terrain pixels compared: {}",
        c.compared
    );
    assert!(
        c.sky_expected > c.probes / 5,
        "camera should see sky: {}",
        c.sky_expected
    );
    let diff = c.sky_expected.abs_diff(c.sky_rendered) as f64 / c.probes as f64;
    assert!(
        diff < 0.02,
        "sky coverage differs: expected {} rendered {} of {}",
        c.sky_expected,
        c.sky_rendered,
        c.probes
    );
}

#[test]
fn legacy_and_modern_paths_render_the_same_image() {
    let data = analytic::cone(129, 8.0, 300.0, 400.0).unwrap();
    let camera = Camera {
        position: DVec3::new(-100.0, -100.0, 400.0),
        yaw_deg: 45.0,
        pitch_deg: -20.0,
        ..Camera::default()
    };
    let modern = render_one(&data, camera, false);
    let legacy = render_one(&data, camera, true);
    let max_diff = modern
        .rgba
        .iter()
        .zip(&legacy.rgba)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(
        max_diff <= 1,
        "render pass and dynamic rendering differ by {max_diff}"
    );
    // And the image is not trivially uniform.
    let distinct: std::collections::HashSet<_> = modern.rgba.chunks(4).take(64_000).collect();
    assert!(distinct.len() > 10);
}

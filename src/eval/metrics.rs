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
    pub median: f64,
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
            median: rank(0.5),
            p99: rank(0.99),
            p999: rank(0.999),
            max: values[values.len() - 1],
        }
    }
}

/// A streaming summary for very many non-negative values (every pixel of every frame of a
/// run): exact count, mean and maximum; percentiles from log-spaced bins 1.2% wide between
/// 1e-6 and 1e5 (values below land in the first bin, reported as 1e-6), each reported as its
/// bin's upper edge, so a percentile is never understated by more than one bin.
#[derive(Clone, Debug)]
pub struct Histogram {
    bins: Vec<u64>,
    count: u64,
    sum: f64,
    max: f64,
}

const HIST_MIN: f64 = 1e-6;
const HIST_BINS: usize = 2200;
const HIST_STEP: f64 = 1.012;

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            bins: vec![0; HIST_BINS],
            count: 0,
            sum: 0.0,
            max: 0.0,
        }
    }
}

impl Histogram {
    pub fn add(&mut self, v: f64) {
        let v = v.max(0.0);
        let bin = if v <= HIST_MIN {
            0
        } else {
            ((v / HIST_MIN).ln() / HIST_STEP.ln()).ceil() as usize
        };
        self.bins[bin.min(HIST_BINS - 1)] += 1;
        self.count += 1;
        self.sum += v;
        self.max = self.max.max(v);
    }

    fn upper_edge(bin: usize) -> f64 {
        HIST_MIN * HIST_STEP.powi(bin as i32)
    }

    fn quantile(&self, q: f64) -> f64 {
        let rank = ((q * self.count as f64).ceil() as u64).clamp(1, self.count);
        let mut seen = 0;
        for (i, &n) in self.bins.iter().enumerate() {
            seen += n;
            if seen >= rank {
                return Self::upper_edge(i).min(self.max);
            }
        }
        self.max
    }

    pub fn summary(&self) -> Summary {
        if self.count == 0 {
            return Summary::default();
        }
        Summary {
            count: self.count as usize,
            mean: self.sum / self.count as f64,
            median: self.quantile(0.5),
            p99: self.quantile(0.99),
            p999: self.quantile(0.999),
            max: self.max,
        }
    }
}

/// [`GeometricError`] accumulated over many frames with bounded memory.
#[derive(Clone, Debug, Default)]
pub struct ErrorHistogram {
    pub metres: Histogram,
    pub pixels: Histogram,
}

impl ErrorHistogram {
    pub fn add(&mut self, errors: &[PixelError]) {
        for e in errors {
            self.metres.add(e.metres.abs());
            self.pixels.add(e.pixels);
        }
    }

    pub fn summary(&self) -> GeometricError {
        GeometricError {
            metres: self.metres.summary(),
            pixels: self.pixels.summary(),
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

/// Holes (cracks, gaps): pixels where the method shows sky although the reference and its 8
/// neighbours all show terrain (inside the reference's silhouette shrunk by one pixel, so a
/// rasterization difference along a skyline is not counted).
pub fn holes(reference_depth: &[f32], method_depth: &[f32], width: u32, height: u32) -> usize {
    let (w, h) = (width as usize, height as usize);
    let mut n = 0;
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let inside = (y - 1..=y + 1)
                .all(|yy| (x - 1..=x + 1).all(|xx| reference_depth[yy * w + xx] > 0.0));
            if inside && method_depth[y * w + x] <= 0.0 {
                n += 1;
            }
        }
    }
    n
}

/// PSNR in dB over the RGB channels of two RGBA8 images (infinite when identical).
pub fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (pa, pb) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for c in 0..3 {
            let d = pa[c] as f64 - pb[c] as f64;
            sum += d * d;
        }
        n += 3;
    }
    let mse = sum / n.max(1) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

/// Mean structural similarity (SSIM, Wang et al. 2004) of the luma of two RGBA8 images over
/// non-overlapping 8x8 windows, with the usual constants `C1 = (0.01 L)^2`, `C2 = (0.03 L)^2`:
/// 1 for identical images, lower as structure differs. A perceptual measure that, unlike PSNR,
/// is insensitive to small uniform shading offsets.
pub fn ssim(a: &[u8], b: &[u8], width: u32, height: u32) -> f64 {
    let luma = |p: &[u8], i: usize| {
        0.299 * p[4 * i] as f64 + 0.587 * p[4 * i + 1] as f64 + 0.114 * p[4 * i + 2] as f64
    };
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    let (mut total, mut windows) = (0.0, 0usize);
    for wy in (0..height.saturating_sub(7)).step_by(8) {
        for wx in (0..width.saturating_sub(7)).step_by(8) {
            let (mut ma, mut mb, mut va, mut vb, mut cov) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for y in wy..wy + 8 {
                for x in wx..wx + 8 {
                    let i = (y * width + x) as usize;
                    let (la, lb) = (luma(a, i), luma(b, i));
                    ma += la;
                    mb += lb;
                    va += la * la;
                    vb += lb * lb;
                    cov += la * lb;
                }
            }
            let n = 64.0;
            let (ma, mb) = (ma / n, mb / n);
            let (va, vb, cov) = (va / n - ma * ma, vb / n - mb * mb, cov / n - ma * mb);
            total += ((2.0 * ma * mb + c1) * (2.0 * cov + c2))
                / ((ma * ma + mb * mb + c1) * (va + vb + c2));
            windows += 1;
        }
    }
    if windows == 0 {
        1.0
    } else {
        total / windows as f64
    }
}

/// Signed screen-space error per pixel (`None`: sky or off the data), row-major.
pub fn error_image(
    camera: &Camera,
    width: u32,
    height: u32,
    depth: &[f32],
    data: &Heightmap,
) -> Vec<Option<f64>> {
    let mut img = vec![None; (width * height) as usize];
    for e in pixel_errors(camera, width, height, depth, data) {
        img[(e.y * width + e.x) as usize] = Some(e.pixels.copysign(e.metres));
    }
    img
}

/// Popping between two consecutive frames: the per-pixel change of the signed screen-space
/// error image over pixels that show terrain in both and are not at a depth discontinuity
/// (a neighbour's depth differs by more than 5%: occlusion edges, where a ray moves from one
/// ridge to another). Under slow motion the image shifts by well under a pixel per frame, so
/// for a method whose surface does not jump this change stays small; a level switch or a
/// resampled grid shows up in full. Returns the values (pixels) for summaries.
pub fn popping(
    previous: &[Option<f64>],
    current: &[Option<f64>],
    depth: &[f32],
    width: u32,
    height: u32,
) -> Vec<f64> {
    let mut out = Vec::new();
    let (w, h) = (width as usize, height as usize);
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let i = y * w + x;
            let (Some(a), Some(b)) = (previous[i], current[i]) else {
                continue;
            };
            let d = depth[i];
            let continuous = [i - 1, i + 1, i - w, i + w]
                .iter()
                .all(|&j| depth[j] > 0.0 && (depth[j] - d).abs() <= 0.05 * d);
            if continuous {
                out.push((b - a).abs());
            }
        }
    }
    out
}

/// Swimming: fixed world points on the exact surface, and for each the method's height error
/// where it is seen, frame after frame. A method whose geometry is attached to the world (brute
/// force, UDLOD between morphs) keeps each point's error nearly constant while the camera
/// moves; one whose grid follows the camera (PGM) resamples the surface every frame, so the
/// error of a fixed point wanders: the swimming of a point is the range (max - min) of its
/// height error over the frames that see it.
#[derive(Default)]
pub struct SwimTracker {
    points: Vec<DVec3>,
    observed: Vec<Vec<f64>>,
    /// Distance at which each point was seen (for the pixel conversion).
    distance: Vec<Vec<f64>>,
}

impl SwimTracker {
    /// No points yet: [`SwimTracker::seed`] adds them from the views.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the exact-surface points seen by an `nx` x `ny` grid of pixels of a reference
    /// frame (brute force: its depth gives points on the exact mesh), so that every method is
    /// tracked at the same world points, ones a flight actually sees.
    #[allow(clippy::too_many_arguments)]
    pub fn seed(
        &mut self,
        camera: &Camera,
        width: u32,
        height: u32,
        reference_depth: &[f32],
        data: &Heightmap,
        nx: u32,
        ny: u32,
    ) {
        for j in 0..ny {
            for i in 0..nx {
                let x = ((i as f64 + 0.5) / nx as f64 * width as f64) as u32;
                let y = ((j as f64 + 0.5) / ny as f64 * height as f64) as u32;
                let d = reference_depth[(y * width + x) as usize];
                if d <= 0.0 {
                    continue;
                }
                let p = world_point(camera, x, y, width, height, d);
                self.points
                    .push(DVec3::new(p.x, p.y, data.mesh_height_at(p.x, p.y)));
                self.observed.push(Vec::new());
                self.distance.push(Vec::new());
            }
        }
    }

    pub fn points(&self) -> usize {
        self.points.len()
    }

    /// Records the frame: each point that projects into the image, where the depth-derived
    /// surface point lies within two pixel footprints of it horizontally (the point is seen,
    /// not hidden), contributes the method's height error there.
    pub fn observe(
        &mut self,
        camera: &Camera,
        width: u32,
        height: u32,
        depth: &[f32],
        data: &Heightmap,
    ) {
        let (right, up, forward) = camera.basis();
        let focal = camera.focal_px(height);
        for (k, p) in self.points.iter().enumerate() {
            let rel = *p - camera.position;
            let z = rel.dot(forward);
            if z <= camera.near {
                continue;
            }
            let px = width as f64 / 2.0 + rel.dot(right) * focal / z - 0.5;
            let py = height as f64 / 2.0 - rel.dot(up) * focal / z - 0.5;
            let (x, y) = (px.round(), py.round());
            if x < 0.0 || y < 0.0 || x >= width as f64 || y >= height as f64 {
                continue;
            }
            let (x, y) = (x as u32, y as u32);
            let d = depth[(y * width + x) as usize];
            if d <= 0.0 {
                continue;
            }
            let q = world_point(camera, x, y, width, height, d);
            let footprint = rel.length() / focal;
            if (q.truncate() - p.truncate()).length() > 2.0 * footprint + 1e-6 {
                continue;
            }
            self.observed[k].push(q.z - data.mesh_height_at(q.x, q.y));
            self.distance[k].push((q - camera.position).length());
        }
    }

    /// Summaries of the per-point swimming (height-error range) in metres and in pixels (the
    /// range projected at the point's median distance), over points seen in >= 3 frames.
    pub fn summary(&self, focal_px: f64) -> (Summary, Summary) {
        let mut metres = Vec::new();
        let mut pixels = Vec::new();
        for (obs, dist) in self.observed.iter().zip(&self.distance) {
            if obs.len() < 3 {
                continue;
            }
            let lo = obs.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = obs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let mut d = dist.clone();
            d.sort_by(f64::total_cmp);
            let median = d[d.len() / 2];
            metres.push(hi - lo);
            pixels.push((hi - lo) * focal_px / median);
        }
        (Summary::of(&mut metres), Summary::of(&mut pixels))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_and_ssim_of_identical_and_different_images() {
        let (w, h) = (32u32, 16u32);
        let a: Vec<u8> = (0..w * h * 4).map(|i| ((i * 7) % 251) as u8).collect();
        assert_eq!(psnr(&a, &a), f64::INFINITY);
        assert!((ssim(&a, &a, w, h) - 1.0).abs() < 1e-12);
        let b: Vec<u8> = a.iter().map(|&v| v.saturating_add(20)).collect();
        let p = psnr(&a, &b);
        assert!(p > 20.0 && p < 30.0, "{p}");
        let noise: Vec<u8> = (0..w * h * 4).map(|i| ((i * 13 + 5) % 253) as u8).collect();
        assert!(ssim(&a, &noise, w, h) < 0.5);
    }

    #[test]
    fn histogram_percentiles_are_within_one_bin() {
        let mut h = Histogram::default();
        let mut v: Vec<f64> = (1..=10_000).map(|i| i as f64 * 0.001).collect();
        for &x in &v {
            h.add(x);
        }
        let exact = Summary::of(&mut v);
        let approx = h.summary();
        assert_eq!(approx.count, exact.count);
        assert!((approx.mean - exact.mean).abs() < 1e-9 && approx.max == exact.max);
        for (a, e) in [
            (approx.p99, exact.p99),
            (approx.p999, exact.p999),
            (approx.median, exact.median),
        ] {
            assert!(a >= e && a <= e * HIST_STEP * 1.0001, "{a} vs {e}");
        }
    }

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

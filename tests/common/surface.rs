//! A method's own surface on the CPU, as a soup of triangles in sample units (x, y) and metres
//! (z), and the ray through a pixel marched over it: the crack tests tell a gap in the drawn
//! mesh (the ray surely enters the method's surface from above, yet the GPU drew sky) from a
//! skyline the method draws lower than brute force (the ray clears the surface, or grazes it
//! within the rasterizer's precision).

use glam::{DVec2, DVec3};
use vkterrain::dataset::Heightmap;
use vkterrain::readback::OwnedFrame;
use vkterrain::scene::Camera;

/// Side of a lookup bin, samples.
const BIN: f64 = 4.0;

/// Triangles binned by the cells their xy bounding boxes overlap.
pub struct Surface<'a> {
    data: &'a Heightmap,
    triangles: Vec<[DVec3; 3]>,
    bins: Vec<Vec<u32>>,
    bins_x: usize,
}

impl<'a> Surface<'a> {
    /// The surface of `triangles` (vertex samples, clamped into the data by the caller as the
    /// vertex stage clamps them) over `data`'s heights; degenerate triangles are dropped.
    pub fn new(data: &'a Heightmap, triangles: impl IntoIterator<Item = [[i32; 2]; 3]>) -> Self {
        let bins_x = ((data.width - 1) as f64 / BIN) as usize + 1;
        let bins_y = ((data.height - 1) as f64 / BIN) as usize + 1;
        let mut s = Surface {
            data,
            triangles: Vec::new(),
            bins: vec![Vec::new(); bins_x * bins_y],
            bins_x,
        };
        for t in triangles {
            let v = t.map(|[x, y]| {
                DVec3::new(x as f64, y as f64, data.sample(x as u32, y as u32) as f64)
            });
            if area2(v) == 0.0 {
                continue;
            }
            let lo = v[0].min(v[1]).min(v[2]).truncate() / BIN;
            let hi = v[0].max(v[1]).max(v[2]).truncate() / BIN;
            let k = s.triangles.len() as u32;
            s.triangles.push(v);
            for by in lo.y as usize..=(hi.y as usize).min(bins_y - 1) {
                for bx in lo.x as usize..=(hi.x as usize).min(bins_x - 1) {
                    s.bins[by * bins_x + bx].push(k);
                }
            }
        }
        s
    }

    /// Height at grid position `(x, y)`: the first triangle containing it; `None` where no
    /// triangle does (outside the data, or over a gap).
    pub fn height_at(&self, x: f64, y: f64) -> Option<f64> {
        if x < 0.0 || y < 0.0 {
            return None;
        }
        let (bx, by) = ((x / BIN) as usize, (y / BIN) as usize);
        let bin = self
            .bins
            .get(by * self.bins_x + bx)
            .filter(|_| bx < self.bins_x)?;
        bin.iter()
            .find_map(|&k| plane_height(self.triangles[k as usize], DVec2::new(x, y)))
    }

    /// How surely the ray through the centre of pixel `(x, y)` of a `width` x `height` image
    /// hits the surface from above, in pixels: over every place where it passes from above the
    /// surface to below it, the smaller of how far above it was before and how far below it
    /// gets after, the largest such (0: the ray never enters the surface from above). Marched
    /// a twentieth of a sample at a time. A ray that enters the data through its open side
    /// below the surface does not count until it has been above.
    pub fn hit_margin_px(
        &self,
        cam: &Camera,
        (x, y): (usize, usize),
        (width, height): (u32, u32),
    ) -> f64 {
        let spacing = self.data.spacing;
        let dir = cam.pixel_ray(x as f64 + 0.5, y as f64 + 0.5, width, height);
        let focal = cam.focal_px(height);
        let top = self.data.height_range().1 as f64;
        let (ex, ey) = self.data.extent();
        let reach = (cam.position.truncate() - DVec2::new(ex, ey) / 2.0).length()
            + ex.hypot(ey)
            + (cam.position.z - top).abs();
        let step = 0.05 * spacing;
        let (mut best, mut above, mut below) = (0.0f64, 0.0f64, 0.0f64);
        let mut t = step;
        while t < reach && !(cam.position.z + dir.z * t > top && dir.z >= 0.0) {
            let p = cam.position + dir * t;
            // Clearance above the surface as an angle, in pixels.
            match self
                .height_at(p.x / spacing, p.y / spacing)
                .map(|z| (p.z - z) / t * focal)
            {
                Some(c) if c > 0.0 => {
                    best = best.max(above.min(below));
                    (above, below) = (if below > 0.0 { c } else { above.max(c) }, 0.0);
                }
                Some(c) => below = below.max(-c),
                None => {
                    best = best.max(above.min(below));
                    (above, below) = (0.0, 0.0);
                }
            }
            t += step;
        }
        best.max(above.min(below))
    }
}

fn area2([a, b, c]: [DVec3; 3]) -> f64 {
    (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y)
}

/// Height at `p` of the plane through `tri` if `p` lies in its xy footprint.
fn plane_height(tri: [DVec3; 3], p: DVec2) -> Option<f64> {
    let [p0, p1, p2] = tri;
    let det = area2(tri);
    let u = ((p.x - p0.x) * (p2.y - p0.y) - (p2.x - p0.x) * (p.y - p0.y)) / det;
    let v = ((p1.x - p0.x) * (p.y - p0.y) - (p.x - p0.x) * (p1.y - p0.y)) / det;
    let eps = 1e-9;
    (u >= -eps && v >= -eps && u + v <= 1.0 + eps)
        .then_some(p0.z + u * (p1.z - p0.z) + v * (p2.z - p0.z))
}

/// Crack candidates: pixels where the method shows sky although brute force shows terrain,
/// with the method's own terrain on both sides (left and right, or above and below). A coarser
/// silhouette's edge is not a candidate (its sky joins the sky above); a gap in the mesh is,
/// and so is a one-pixel notch in a skyline the method draws lower than brute force.
pub fn crack_candidates(reference: &OwnedFrame, method: &OwnedFrame) -> Vec<(usize, usize)> {
    let (r, m) = (
        reference.depth.as_ref().unwrap(),
        method.depth.as_ref().unwrap(),
    );
    let (w, h) = (reference.width as usize, reference.height as usize);
    let t = |x: usize, y: usize| m[y * w + x] > 0.0;
    let mut out = Vec::new();
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            if !t(x, y)
                && r[y * w + x] > 0.0
                && ((t(x - 1, y) && t(x + 1, y)) || (t(x, y - 1) && t(x, y + 1)))
            {
                out.push((x, y));
            }
        }
    }
    out
}

/// A hit margin (px) below which the rasterizer may decide either way: lavapipe snaps vertices
/// to 1/256 px, and f32 positions add their own rounding.
pub const RASTER_SLACK_PX: f64 = 0.01;

/// The crack candidates of one pose split by the hit margin (px) of the ray through the pixel
/// centre on `surface`: cracks (the ray surely hits the method's surface, yet the GPU drew
/// sky) and notches (the ray clears the method's surface, or grazes it within
/// [`RASTER_SLACK_PX`]: a level-of-detail error, not a gap), the margins of each.
pub fn classify(
    cam: &Camera,
    surface: &Surface,
    candidates: &[(usize, usize)],
    size: (u32, u32),
) -> (Vec<f64>, Vec<f64>) {
    candidates
        .iter()
        .map(|&px| surface.hit_margin_px(cam, px, size))
        .partition(|&m| m > RASTER_SLACK_PX)
}

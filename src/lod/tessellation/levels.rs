//! The CPU mirror of the control stage's level rule (`shaders/glsl/tess.tesc`): per triangle
//! patch, as the vertex stage places its corners, whether the control stage discards it and,
//! if not, its outer levels; and from the levels the triangles Vulkan's tessellator makes.
//!
//! The GPU works in f32, this mirror in f64, so a quantity that lands within rounding of a
//! threshold (a level's rounding to whole segments, the frustum test, the sphere reaching the
//! eye plane) is decided both ways: each patch yields a range of triangle counts, a single
//! number for almost every patch. Tests compare the range's sum over a frame with the
//! triangles the GPU's pipeline-statistics query counts (`tests/tessellation.rs`), i.e. the
//! levels the real control stage chose with the rule written out here.

use glam::{DMat4, DVec2, DVec3, DVec4, Mat4};

use super::settings::{EdgeLevels, Spacing, TessellationSettings};
use super::{CHUNK_QUADS, TessUniforms};
use crate::dataset::Level0;
use crate::error::Result;
use crate::geo::lattice::Lattice;
use crate::lod::blocks::BlockBounds;
use crate::lod::brute::grid_indices;
use crate::scene::Camera;

/// Relative slack for f32-vs-f64 differences: a level within it of a rounding step, or a
/// comparison within it (of the compared values' size), counts both ways.
const SLACK: f64 = 1e-4;
/// The same for a clip coordinate, relative to the sizes of the terms it is made of.
const F32_SLACK: f64 = 1e-5;

/// The level rule of one view: the control stage's inputs as the renderer sets them.
pub struct LevelRule<'a> {
    tess: TessUniforms,
    view_proj: DMat4,
    camera: DVec3,
    data: &'a dyn Level0,
    lattice: Option<&'a Lattice>,
    bounds: BlockBounds,
    edge_levels: EdgeLevels,
    spacing: Spacing,
}

/// Whether the control stage discards a patch (level 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Discard {
    No,
    Yes,
    /// The frustum test lies within f32's rounding of its threshold.
    Maybe,
}

/// What the control stage does with one patch: whether it discards it and, if it may not, the
/// raw outer levels (before clamping) as a `[low, high]` range each.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchLevels {
    pub discard: Discard,
    /// Per outer level `[low, high]` of `edge px / edge_px * factor` (the edge opposite corner
    /// i); zero for a discarded patch.
    pub outer: [[f64; 2]; 3],
}

impl<'a> LevelRule<'a> {
    /// The rule for `camera` over `data` (on the earth through `lattice`) at `width` x `height`
    /// pixels, with the device's `maxTessellationGenerationLevel`.
    pub fn new(
        settings: &TessellationSettings,
        data: &'a dyn Level0,
        lattice: Option<&'a Lattice>,
        camera: &Camera,
        (width, height): (u32, u32),
        max_generation_level: u32,
    ) -> Result<Self> {
        let bounds = BlockBounds::new(data, settings.patch_samples)?;
        let tess = TessUniforms::new(
            settings,
            [bounds.cols, bounds.rows],
            height,
            camera.vfov_deg,
            max_generation_level,
        );
        let aspect = width as f64 / height as f64;
        let view_proj: Mat4 = camera.projection(aspect) * camera.view_rotation();
        Ok(LevelRule {
            tess,
            view_proj: view_proj.as_dmat4(),
            camera: camera.position,
            data,
            lattice,
            bounds,
            edge_levels: settings.edge_levels,
            spacing: settings.spacing,
        })
    }

    /// Every patch's corners (samples), in the order the renderer draws them: chunks of
    /// [`CHUNK_QUADS`]² quads, rows of quads past the data not drawn, corners clamped onto the
    /// data (the zero-area patches that makes are discarded).
    pub fn patches(&self) -> Vec<[[i32; 2]; 3]> {
        let q = CHUNK_QUADS;
        let [step, _, qx, qy] = self.tess.grid;
        let indices = grid_indices(q);
        let row_indices = indices.len() / q as usize;
        let (w, h) = (self.data.width() as i32, self.data.height() as i32);
        let chunks_x = qx.div_ceil(q);
        let mut out = Vec::new();
        for chunk_y in 0..qy.div_ceil(q) {
            for chunk_x in 0..chunks_x {
                let rows = (qy - chunk_y * q).min(q) as usize;
                for tri in indices[..rows * row_indices].chunks(3) {
                    out.push([0, 1, 2].map(|k| {
                        let v = tri[k] as u32;
                        let local = [v % (q + 1), v / (q + 1)];
                        let x = ((chunk_x * q + local[0]) * step) as i32;
                        let y = ((chunk_y * q + local[1]) * step) as i32;
                        [x.min(w - 1), y.min(h - 1)]
                    }));
                }
            }
        }
        out
    }

    /// Camera-relative world position of sample `s` at `height` (the shaders'
    /// `relative_position` at a whole sample).
    fn relative(&self, s: [i32; 2], height: f64) -> DVec3 {
        let g = DVec2::new(s[0] as f64, s[1] as f64);
        match self.lattice {
            Some(l) => l.position(g, height) - self.camera,
            None => {
                let spacing = self.data.spacing() as f32 as f64;
                (g * spacing).extend(height) - self.camera
            }
        }
    }

    fn clip(&self, rel: DVec3) -> DVec4 {
        self.view_proj * rel.extend(1.0)
    }

    /// How far the GPU's f32 clip coordinates of `rel` may lie from [`Self::clip`]'s: a few
    /// units in the last place of each term of the product, the position itself good to a
    /// millimetre and a part in a million.
    fn clip_slack(&self, rel: DVec3) -> DVec4 {
        let pos = 1e-3 + 1e-6 * rel.length();
        let v = (rel.abs() + DVec3::splat(pos)).extend(1.0);
        let m = self.view_proj;
        let abs = DMat4::from_cols(
            m.x_axis.abs(),
            m.y_axis.abs(),
            m.z_axis.abs(),
            m.w_axis.abs(),
        );
        abs * v * F32_SLACK
    }

    fn height(&self, s: [i32; 2]) -> Result<f64> {
        Ok(self.data.sample(s[0] as u32, s[1] as u32)? as f64)
    }

    /// The control stage's decision for the patch with corners `c`.
    pub fn patch(&self, c: [[i32; 2]; 3]) -> Result<PatchLevels> {
        let discarded = PatchLevels {
            discard: Discard::Yes,
            outer: [[0.0; 2]; 3],
        };
        let (e1, e2) = (sub(c[1], c[0]), sub(c[2], c[0]));
        if e1[0] as i64 * e2[1] as i64 - e1[1] as i64 * e2[0] as i64 == 0 {
            return Ok(discarded);
        }
        let heights = [self.height(c[0])?, self.height(c[1])?, self.height(c[2])?];
        let rel = [0, 1, 2].map(|i| self.relative(c[i], heights[i]));
        let w = rel.map(|r| self.clip(r).w);
        let mut discard = Discard::No;
        if self.tess.flags[0] != 0 {
            match self.outside_frustum(c) {
                Some(true) => return Ok(discarded),
                Some(false) => {}
                None => discard = Discard::Maybe,
            }
        }
        let level = |a: usize, b: usize| {
            let depth = match self.edge_levels {
                EdgeLevels::Edge => 0.5 * (w[a] + w[b]),
                EdgeLevels::Patch => (w[0] + w[1] + w[2]) / 3.0,
            };
            self.edge_level(rel[a] - rel[b], depth)
        };
        Ok(PatchLevels {
            discard,
            outer: [level(1, 2), level(2, 0), level(0, 1)],
        })
    }

    /// `[low, high]` of an edge's raw level: its bounding sphere's on-screen diameter over the
    /// target edge length, times the factor; the sphere reaching the eye plane gets 1e30 (the
    /// highest level after clamping), one wholly behind it 0.
    fn edge_level(&self, d: DVec3, depth: f64) -> [f64; 2] {
        let [edge_px, factor, focal, _] = self.tess.params.map(|v| v as f64);
        let diameter = d.length();
        let radius = 0.5 * diameter;
        let branch = |front: bool, behind: bool| {
            let px = if front {
                diameter * focal / depth
            } else if behind {
                0.0
            } else {
                1.0e30
            };
            px / edge_px * factor
        };
        let near = |x: f64| (depth - x).abs() <= SLACK * depth.abs().max(radius);
        let mut candidates = vec![branch(depth > radius, depth < -radius)];
        if near(radius) {
            candidates.extend([branch(true, false), branch(false, false)]);
        }
        if near(-radius) {
            candidates.extend([branch(false, true), branch(false, false)]);
        }
        let lo = candidates.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = candidates.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        [lo * (1.0 - SLACK), hi * (1.0 + SLACK)]
    }

    /// The shaders' earth bulge: the sagitta of the patch's longest edge over the lattice's
    /// curve radius plus 1e-3 of it; 0 on the flat world.
    fn bulge(&self, c: [[i32; 2]; 3]) -> f64 {
        let Some(l) = self.lattice else {
            return 0.0;
        };
        let p = c.map(|s| self.relative(s, 0.0));
        let d = p[0]
            .distance(p[1])
            .max(p[1].distance(p[2]))
            .max(p[2].distance(p[0]));
        d * d / (8.0 * l.curve_radius()) + 1e-3 * d
    }

    /// Whether the patch's prism (corners between its quad's lowest and highest height, grown
    /// by the bulge) lies outside one plane of the frustum (reversed-Z clip space: `0 <= z <=
    /// w`): `Some` where f32 decides as f64 does, `None` where a point lies within rounding of
    /// the plane that would decide.
    fn outside_frustum(&self, c: [[i32; 2]; 3]) -> Option<bool> {
        let lo = [
            c[0][0].min(c[1][0]).min(c[2][0]),
            c[0][1].min(c[1][1]).min(c[2][1]),
        ];
        let step = self.tess.grid[0] as i32;
        let quad = (lo[1] / step) as usize * self.bounds.cols as usize + (lo[0] / step) as usize;
        let b = self.bounds.bounds[quad];
        let bulge = self.bulge(c);
        let mut points = Vec::with_capacity(6);
        for s in c {
            for h in [b[0] as f64 - bulge, b[1] as f64 + bulge] {
                let rel = self.relative(s, h);
                points.push((self.clip(rel), self.clip_slack(rel)));
            }
        }
        // Outside a plane iff every point's value (and the slack of its terms) is positive.
        type Plane = fn(DVec4) -> f64;
        let planes: [(Plane, Plane); 6] = [
            (|c| -(c.x + c.w), |t| t.x + t.w),
            (|c| c.x - c.w, |t| t.x + t.w),
            (|c| -(c.y + c.w), |t| t.y + t.w),
            (|c| c.y - c.w, |t| t.y + t.w),
            (|c| -c.z, |t| t.z),
            (|c| c.z - c.w, |t| t.z + t.w),
        ];
        let mut certain = true;
        for (f, slack) in planes {
            if points.iter().all(|&(p, t)| f(p) > slack(t)) {
                return Some(true);
            }
            certain &= points.iter().any(|&(p, t)| f(p) < -slack(t));
        }
        certain.then_some(false)
    }

    /// `[low, high]` triangles the tessellator makes of the patch with corners `c`.
    pub fn patch_triangles(&self, c: [[i32; 2]; 3]) -> Result<[u64; 2]> {
        let p = self.patch(c)?;
        if p.discard == Discard::Yes {
            return Ok([0, 0]);
        }
        let max = self.tess.params[3] as f64;
        let count = |k: usize| {
            let raw = p.outer.map(|r| r[k]);
            triangles(self.spacing, raw.map(|r| r.clamp(1.0, max)), max)
        };
        let lo = if p.discard == Discard::Maybe {
            0
        } else {
            count(0)
        };
        Ok([lo, count(1)])
    }

    /// `[low, high]` triangles of the whole frame.
    pub fn frame_triangles(&self) -> Result<[u64; 2]> {
        let mut sum = [0u64; 2];
        for c in self.patches() {
            let [lo, hi] = self.patch_triangles(c)?;
            sum[0] += lo;
            sum[1] += hi;
        }
        Ok(sum)
    }
}

fn sub(a: [i32; 2], b: [i32; 2]) -> [i32; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// Segments the tessellator cuts an edge of level `level` (already clamped to 1..=`max` by
/// the control stage) into: Vulkan's spacing rules.
fn segments(spacing: Spacing, level: f64, max: f64) -> u64 {
    match spacing {
        Spacing::Equal => level.clamp(1.0, max).ceil() as u64,
        Spacing::FractionalOdd => {
            let n = level.clamp(1.0, max - 1.0).ceil() as u64;
            n + (n % 2 == 0) as u64
        }
        Spacing::FractionalEven => {
            let n = level.clamp(2.0, max).ceil() as u64;
            n + n % 2
        }
    }
}

/// Triangles of a triangle patch with (clamped) outer levels `outer` and the control stage's
/// inner level, their mean: concentric rings, the outer one stitched to the edges' own
/// segment counts (a ring between edges of `a` and `b` segments holds `a + b` triangles).
fn triangles(spacing: Spacing, outer: [f64; 3], max: f64) -> u64 {
    let o = outer.map(|l| segments(spacing, l, max));
    let mut n = segments(spacing, (outer[0] + outer[1] + outer[2]) / 3.0, max);
    if n == 1 {
        if o == [1, 1, 1] {
            return 1;
        }
        // An inner level of 1 with a longer outer edge is taken as 1 + epsilon.
        n = segments(spacing, 1.5, max);
    }
    o.iter().sum::<u64>() + 3 * (n - 2) + uniform_rings(n - 2)
}

/// Triangles of a uniformly tessellated triangle of `n` segments per side.
fn uniform_rings(n: u64) -> u64 {
    match n {
        0 => 0,
        1 => 1,
        _ => 6 * n - 6 + uniform_rings(n - 2),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_levels_give_the_ring_counts() {
        // 1, 6, 13 and 64's 6,144: the tessellator's uniform counts (tests/tessellation.rs
        // measures them on the GPU).
        for (n, t) in [(1.0, 1), (2.0, 6), (3.0, 13), (64.0, 6144)] {
            assert_eq!(triangles(Spacing::Equal, [n; 3], 64.0), t, "level {n}");
        }
        // Fractional odd rounds 2 up to 3; even rounds 1 up to 2.
        assert_eq!(triangles(Spacing::FractionalOdd, [2.0; 3], 64.0), 13);
        assert_eq!(triangles(Spacing::FractionalEven, [1.0; 3], 64.0), 6);
        // Mixed: outer 1, 1, 4 give inner 2: 1 + 1 + 4 triangles stitched to the centre.
        assert_eq!(triangles(Spacing::Equal, [1.0, 1.0, 4.0], 64.0), 6);
        // Outer 1, 1, 2 give inner 4/3 -> 2.
        assert_eq!(triangles(Spacing::Equal, [1.0, 1.0, 2.0], 64.0), 4);
        // Fractional odd clamps to 63 segments.
        assert_eq!(segments(Spacing::FractionalOdd, 64.0, 64.0), 63);
    }
}

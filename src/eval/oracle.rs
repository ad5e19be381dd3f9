//! The triangle oracle: for one frame and a pixel error target `tau`, the fewest triangles of a
//! restricted quadtree triangulation of the exact surface whose every triangle's projected
//! error is at most `tau`. UDLOD's triangle count divided by this is how far the method is
//! from the physical limit of its own kind of mesh (`docs/udlod.md`, "How far from optimal").
//!
//! Definitions (offline, CPU, no speed requirement):
//! - A **cell** of level `k` covers samples `[x 2^k, x 2^k + 2^k] x [y 2^k, ...]` (clamped at
//!   the data's last row and column) and is drawn as two triangles over its four corner
//!   samples, split along the same diagonal as every grid of the renderer (`interp::
//!   triangulated`). Level 0 cells are the exact mesh's quads.
//! - A cell's **projected error** is the largest `|cell surface - sample| * focal /
//!   |sample - eye|` over the full-resolution samples it covers: the exact mesh's vertices,
//!   where the difference of two meshes whose edges run along the exact mesh's edges peaks
//!   (cells cut by the data's edge are measured at samples too).
//! - **Greedy refinement**: from the root, a cell that touches the view frustum (its box:
//!   rectangle x min/max height) and whose projected error exceeds `tau` splits into its four
//!   children; cells outside the frustum never split. Every valid quadtree must split each
//!   cell this splits, so its leaves are the fewest.
//! - **Restriction**: edge neighbours differ by at most one level (the smallest such
//!   refinement of the greedy tree, built bottom-up; leaves it creates that exceed `tau` split
//!   in turn, to a fixpoint); a leaf with `j` finer edge neighbours
//!   has `j` T-junction vertices and is drawn as `2 + j` triangles (a convex polygon of
//!   `4 + j` vertices).
//! - **Count**: the triangles of the leaves whose box touches the frustum.
//!
//! The cell surface with T-junction vertices differs slightly from the two-triangle one
//! measured; the count is a lower bound for the two-triangle criterion.

use std::collections::HashSet;

use glam::DVec3;

use crate::dataset::{Heightmap, interp};
use crate::lod::udlod::params::frustum_planes;
use crate::scene::Camera;

/// Per-cell statistics of one level (`k >= 1`).
struct CellLevel {
    nx: u32,
    /// Largest |cell surface - sample| in metres.
    error: Vec<f32>,
    /// (min, max) height of the cell's samples.
    min_max: Vec<[f32; 2]>,
}

/// The per-data-set part of the oracle: every level's cell errors and height ranges.
pub struct Oracle {
    width: u32,
    height: u32,
    spacing: f64,
    root: u32,
    /// Index `k - 1` holds level `k`.
    levels: Vec<CellLevel>,
}

/// The oracle's answer for one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OracleCount {
    /// Triangles of the visible leaves.
    pub triangles: u64,
    /// Visible leaves.
    pub leaves: u64,
}

/// Per-frame inputs: the eye, the focal length and the frustum.
struct View {
    eye: DVec3,
    focal: f64,
    tau: f64,
    planes: [[f64; 4]; 6],
}

impl Oracle {
    /// Computes every cell's error and height range (each level reads every sample once).
    pub fn new(data: &Heightmap) -> Self {
        let quads = (data.width - 1).max(data.height - 1);
        let mut root = 0;
        while (1u32 << root) < quads {
            root += 1;
        }
        let levels = (1..=root).map(|k| cell_level(data, k)).collect();
        Oracle {
            width: data.width,
            height: data.height,
            spacing: data.spacing,
            root,
            levels,
        }
    }

    fn cells(&self, k: u32) -> (u32, u32) {
        let span = 1u32 << k;
        (
            (self.width - 1).div_ceil(span),
            (self.height - 1).div_ceil(span),
        )
    }

    /// Sample bounds `(c0, c1, r0, r1)` of cell `(x, y)` of level `k`.
    fn bounds(&self, k: u32, x: u32, y: u32) -> (u32, u32, u32, u32) {
        let span = 1u32 << k;
        let (c0, r0) = (x * span, y * span);
        (
            c0,
            (c0 + span).min(self.width - 1),
            r0,
            (r0 + span).min(self.height - 1),
        )
    }

    fn min_max(&self, data: &Heightmap, k: u32, x: u32, y: u32) -> [f32; 2] {
        if k == 0 {
            let (c0, c1, r0, r1) = self.bounds(0, x, y);
            let s = [
                data.sample(c0, r0),
                data.sample(c1, r0),
                data.sample(c0, r1),
                data.sample(c1, r1),
            ];
            return [
                s.iter().copied().fold(f32::INFINITY, f32::min),
                s.iter().copied().fold(f32::NEG_INFINITY, f32::max),
            ];
        }
        let l = &self.levels[k as usize - 1];
        l.min_max[(y * l.nx + x) as usize]
    }

    fn error(&self, k: u32, x: u32, y: u32) -> f32 {
        if k == 0 {
            return 0.0;
        }
        let l = &self.levels[k as usize - 1];
        l.error[(y * l.nx + x) as usize]
    }

    /// The fewest triangles for `camera` at `width x height` with every triangle's projected
    /// error within `tau_px` (see the module documentation).
    pub fn count(
        &self,
        data: &Heightmap,
        camera: &Camera,
        width: u32,
        height: u32,
        tau_px: f64,
    ) -> OracleCount {
        let planes =
            frustum_planes(camera, width as f64 / height as f64).map(|p| p.map(|v| v as f64));
        let view = View {
            eye: camera.position,
            focal: camera.focal_px(height),
            tau: tau_px,
            planes,
        };
        let mut split: Vec<HashSet<(u32, u32)>> = vec![HashSet::new(); self.root as usize + 1];
        self.refine(data, &view, self.root, 0, 0, &mut split);
        // Cells split only for the restriction have children that may exceed tau (a child's
        // grid is not its parent's): refine those, restrict again, until nothing changes.
        loop {
            self.restrict(&mut split);
            let before: usize = split.iter().map(HashSet::len).sum();
            self.refine_leaves(data, &view, self.root, 0, 0, &mut split);
            if split.iter().map(HashSet::len).sum::<usize>() == before {
                break;
            }
        }
        let mut out = OracleCount::default();
        self.count_leaves(data, &view, self.root, 0, 0, &split, &mut out);
        out
    }

    /// Greedy top-down refinement: records every cell that must split.
    fn refine(
        &self,
        data: &Heightmap,
        view: &View,
        k: u32,
        x: u32,
        y: u32,
        split: &mut [HashSet<(u32, u32)>],
    ) {
        if k == 0 || !self.visible(data, view, k, x, y) {
            return;
        }
        let e = self.error(k, x, y) as f64;
        if e * view.focal <= view.tau * self.box_distance(data, view, k, x, y) {
            return; // bounded by the nearest point of its box
        }
        if self.within_tau(data, view, k, x, y) {
            return;
        }
        split[k as usize].insert((x, y));
        let (nx, ny) = self.cells(k - 1);
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let (cx, cy) = (2 * x + dx, 2 * y + dy);
            if cx < nx && cy < ny {
                self.refine(data, view, k - 1, cx, cy, split);
            }
        }
    }

    /// [`Oracle::refine`] from every leaf of the current tree.
    fn refine_leaves(
        &self,
        data: &Heightmap,
        view: &View,
        k: u32,
        x: u32,
        y: u32,
        split: &mut [HashSet<(u32, u32)>],
    ) {
        if !split[k as usize].contains(&(x, y)) {
            return self.refine(data, view, k, x, y, split);
        }
        let (nx, ny) = self.cells(k - 1);
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let (cx, cy) = (2 * x + dx, 2 * y + dy);
            if cx < nx && cy < ny {
                self.refine_leaves(data, view, k - 1, cx, cy, split);
            }
        }
    }

    /// Is every sample's projected error within tau (the exact per-sample test)?
    fn within_tau(&self, data: &Heightmap, view: &View, k: u32, x: u32, y: u32) -> bool {
        let (c0, c1, r0, r1) = self.bounds(k, x, y);
        let corners = [
            data.sample(c0, r0) as f64,
            data.sample(c1, r0) as f64,
            data.sample(c0, r1) as f64,
            data.sample(c1, r1) as f64,
        ];
        let (sx, sy) = ((c1 - c0) as f64, (r1 - r0) as f64);
        for r in r0..=r1 {
            for c in c0..=c1 {
                let h = data.sample(c, r) as f64;
                let fx = (c - c0) as f64 / sx;
                let fy = (r - r0) as f64 / sy;
                let dh = (interp::triangulated(corners, fx, fy) - h).abs();
                let p = DVec3::new(c as f64 * self.spacing, r as f64 * self.spacing, h);
                if dh * view.focal > view.tau * (p - view.eye).length() {
                    return false;
                }
            }
        }
        true
    }

    fn cell_box(&self, data: &Heightmap, k: u32, x: u32, y: u32) -> (DVec3, DVec3) {
        let (c0, c1, r0, r1) = self.bounds(k, x, y);
        let [lo, hi] = self.min_max(data, k, x, y);
        let s = self.spacing;
        (
            DVec3::new(c0 as f64 * s, r0 as f64 * s, lo as f64),
            DVec3::new(c1 as f64 * s, r1 as f64 * s, hi as f64),
        )
    }

    fn box_distance(&self, data: &Heightmap, view: &View, k: u32, x: u32, y: u32) -> f64 {
        let (lo, hi) = self.cell_box(data, k, x, y);
        (view.eye.clamp(lo, hi) - view.eye).length()
    }

    /// Does the cell's box touch the frustum?
    fn visible(&self, data: &Heightmap, view: &View, k: u32, x: u32, y: u32) -> bool {
        let (lo, hi) = self.cell_box(data, k, x, y);
        let (lo, hi) = (lo - view.eye, hi - view.eye);
        let margin = 1e-6 * (hi - lo).length();
        view.planes.iter().all(|pl| {
            let p = DVec3::new(
                if pl[0] >= 0.0 { hi.x } else { lo.x },
                if pl[1] >= 0.0 { hi.y } else { lo.y },
                if pl[2] >= 0.0 { hi.z } else { lo.z },
            );
            pl[0] * p.x + pl[1] * p.y + pl[2] * p.z + pl[3] >= -margin
        })
    }

    /// Bottom-up restriction: a split cell's edge neighbours (same level) must exist, so their
    /// parents split too, as does its own parent. Requirements only move up a level, so one
    /// pass from the finest level is enough.
    fn restrict(&self, split: &mut [HashSet<(u32, u32)>]) {
        for k in 1..self.root {
            let (nx, ny) = self.cells(k);
            let cells: Vec<(u32, u32)> = split[k as usize].iter().copied().collect();
            let up = &mut split[k as usize + 1];
            for (x, y) in cells {
                up.insert((x / 2, y / 2));
                for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (n, m) = (x as i64 + dx, y as i64 + dy);
                    if n >= 0 && m >= 0 && (n as u32) < nx && (m as u32) < ny {
                        up.insert((n as u32 / 2, m as u32 / 2));
                    }
                }
            }
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn count_leaves(
        &self,
        data: &Heightmap,
        view: &View,
        k: u32,
        x: u32,
        y: u32,
        split: &[HashSet<(u32, u32)>],
        out: &mut OracleCount,
    ) {
        if split[k as usize].contains(&(x, y)) {
            let (nx, ny) = self.cells(k - 1);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (cx, cy) = (2 * x + dx, 2 * y + dy);
                if cx < nx && cy < ny {
                    self.count_leaves(data, view, k - 1, cx, cy, split, out);
                }
            }
            return;
        }
        if !self.visible(data, view, k, x, y) {
            return;
        }
        let (nx, ny) = self.cells(k);
        let mut junctions = 0;
        for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            let (n, m) = (x as i64 + dx, y as i64 + dy);
            if n >= 0
                && m >= 0
                && (n as u32) < nx
                && (m as u32) < ny
                && split[k as usize].contains(&(n as u32, m as u32))
            {
                junctions += 1;
            }
        }
        out.leaves += 1;
        out.triangles += 2 + junctions;
    }
}

/// Errors and height ranges of every cell of level `k` (row by row over the data).
fn cell_level(data: &Heightmap, k: u32) -> CellLevel {
    let span = 1u32 << k;
    let (w, h) = (data.width, data.height);
    let (nx, ny) = ((w - 1).div_ceil(span), (h - 1).div_ceil(span));
    let mut error = vec![0f32; (nx * ny) as usize];
    let mut min_max = vec![[f32::INFINITY, f32::NEG_INFINITY]; (nx * ny) as usize];
    for y in 0..ny {
        let (r0, r1) = (y * span, (y * span + span).min(h - 1));
        for x in 0..nx {
            let (c0, c1) = (x * span, (x * span + span).min(w - 1));
            let corners = [
                data.sample(c0, r0) as f64,
                data.sample(c1, r0) as f64,
                data.sample(c0, r1) as f64,
                data.sample(c1, r1) as f64,
            ];
            let (sx, sy) = ((c1 - c0) as f64, (r1 - r0) as f64);
            let (mut e, mut lo, mut hi) = (0f64, f32::INFINITY, f32::NEG_INFINITY);
            for r in r0..=r1 {
                for c in c0..=c1 {
                    let v = data.sample(c, r);
                    lo = lo.min(v);
                    hi = hi.max(v);
                    let fx = (c - c0) as f64 / sx;
                    let fy = (r - r0) as f64 / sy;
                    e = e.max((interp::triangulated(corners, fx, fy) - v as f64).abs());
                }
            }
            let i = (y * nx + x) as usize;
            // Rounded up so that the f32 never understates the f64 error.
            error[i] = next_up(e);
            min_max[i] = [lo, hi];
        }
    }
    CellLevel { nx, error, min_max }
}

/// The smallest f32 not below `v` (v >= 0).
fn next_up(v: f64) -> f32 {
    let f = v as f32;
    if (f as f64) < v {
        f32::from_bits(f.to_bits() + 1)
    } else {
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(size: u32) -> Heightmap {
        let heights = (0..size * size)
            .map(|i| 0.5 * (i % size) as f32 + 0.25 * (i / size) as f32)
            .collect();
        Heightmap::new("plane", size, size, 10.0, heights).unwrap()
    }

    fn looking_down(data: &Heightmap, z: f64) -> Camera {
        let (ex, ey) = data.extent();
        Camera {
            position: DVec3::new(ex / 2.0, ey / 2.0, z),
            pitch_deg: -90.0,
            vfov_deg: 90.0,
            near: 0.5,
            ..Camera::default()
        }
    }

    /// A plane is drawn exactly by its root cell: two triangles.
    #[test]
    fn a_plane_needs_two_triangles() {
        let data = plane(65);
        let o = Oracle::new(&data);
        let c = o.count(&data, &looking_down(&data, 2000.0), 64, 64, 0.1);
        assert_eq!(
            c,
            OracleCount {
                triangles: 2,
                leaves: 1
            }
        );
    }

    /// One spike in a plane: refinement goes down to it, and the restricted tree around it
    /// has more triangles than leaves (T-junctions); a larger tau needs no more triangles.
    #[test]
    fn a_spike_refines_towards_it_and_counts_junctions() {
        let mut data = plane(65);
        let i = (37 * 65 + 21) as usize;
        data.heights[i] += 30.0;
        let o = Oracle::new(&data);
        let cam = looking_down(&data, 2000.0);
        let fine = o.count(&data, &cam, 256, 256, 0.5);
        let coarse = o.count(&data, &cam, 256, 256, 4.0);
        println!("fine {fine:?}, coarse {coarse:?}");
        assert!(fine.leaves > 4 && fine.triangles > 2 * fine.leaves);
        assert!(coarse.triangles <= fine.triangles);
        // Every leaf's error within tau: refining to full resolution where needed, at most
        // the brute-force count.
        assert!(fine.triangles <= 2 * 64 * 64);
    }

    fn bumpy(size: u32) -> Heightmap {
        let mut data = plane(size);
        for (i, h) in data.heights.iter_mut().enumerate() {
            let (c, r) = ((i as u32 % size) as f32, (i as u32 / size) as f32);
            *h += 20.0 * (c * 0.7).sin() * (r * 0.3).cos() + 3.0 * ((c * r) * 0.11).sin();
        }
        data
    }

    fn poses(data: &Heightmap) -> Vec<Camera> {
        let (ex, ey) = data.extent();
        (0..8)
            .map(|i| {
                let f = i as f64 / 8.0;
                Camera {
                    position: DVec3::new(
                        ex * (0.2 + 0.6 * f),
                        ey * (0.7 - 0.5 * f),
                        40.0 + 400.0 * f,
                    ),
                    yaw_deg: 360.0 * f,
                    pitch_deg: -10.0 - 70.0 * f,
                    near: 0.5,
                    ..Camera::default()
                }
            })
            .collect()
    }

    /// A leaf `(level, x, y)` and its sample bounds (an independent copy of the cell layout).
    fn leaf_bounds(data: &Heightmap, (k, x, y): (u32, u32, u32)) -> (u32, u32, u32, u32) {
        let s = 1u32 << k;
        (
            x * s,
            (x * s + s).min(data.width - 1),
            y * s,
            (y * s + s).min(data.height - 1),
        )
    }

    /// The projected error of a leaf, recomputed from the definition: every sample against
    /// the leaf's two triangles, seen from `eye`.
    fn leaf_error_px(data: &Heightmap, leaf: (u32, u32, u32), eye: DVec3, focal: f64) -> f64 {
        let (c0, c1, r0, r1) = leaf_bounds(data, leaf);
        let h = |c, r| data.sample(c, r) as f64;
        let corners = [h(c0, r0), h(c1, r0), h(c0, r1), h(c1, r1)];
        let mut worst = 0.0f64;
        for r in r0..=r1 {
            for c in c0..=c1 {
                let fx = (c - c0) as f64 / (c1 - c0) as f64;
                let fy = (r - r0) as f64 / (r1 - r0) as f64;
                let dh = (interp::triangulated(corners, fx, fy) - h(c, r)).abs();
                let p = DVec3::new(c as f64 * data.spacing, r as f64 * data.spacing, h(c, r));
                worst = worst.max(dh * focal / (p - eye).length());
            }
        }
        worst
    }

    /// The oracle's count equals a naive fixpoint (split any visible leaf over tau and any
    /// leaf with an edge neighbour two levels finer until nothing changes, then count leaves
    /// and T-junctions by scanning all leaf pairs) over poses and taus; every visible leaf of
    /// the fixpoint is within tau. Negative control: without the restriction the count is
    /// smaller for some of these frames (checked below), so skipping it would fail.
    #[test]
    fn count_equals_a_naive_restricted_fixpoint() {
        let data = bumpy(33);
        let o = Oracle::new(&data);
        let (w, h) = (160, 100);
        let mut unrestricted_smaller = 0;
        let mut frames = 0;
        for cam in poses(&data) {
            for tau in [0.5, 2.0] {
                let view = View {
                    eye: cam.position,
                    focal: cam.focal_px(h),
                    tau,
                    planes: frustum_planes(&cam, w as f64 / h as f64).map(|p| p.map(|v| v as f64)),
                };
                let visible = |l: (u32, u32, u32)| o.visible(&data, &view, l.0, l.1, l.2);
                let over = |l: (u32, u32, u32)| {
                    l.0 > 0 && visible(l) && leaf_error_px(&data, l, cam.position, view.focal) > tau
                };
                let mut leaves: HashSet<(u32, u32, u32)> = [(o.root, 0, 0)].into();
                let children = |(k, x, y): (u32, u32, u32)| {
                    let (nx, ny) = o.cells(k - 1);
                    [(0, 0), (1, 0), (0, 1), (1, 1)]
                        .into_iter()
                        .map(move |(dx, dy)| (k - 1, 2 * x + dx, 2 * y + dy))
                        .filter(move |c| c.1 < nx && c.2 < ny)
                };
                // Do the cells share an edge segment (not just a corner)?
                let adjacent = |a: (u32, u32, u32), b: (u32, u32, u32)| {
                    let (a0, a1, a2, a3) = leaf_bounds(&data, a);
                    let (b0, b1, b2, b3) = leaf_bounds(&data, b);
                    let overlap =
                        |lo1: u32, hi1: u32, lo2: u32, hi2: u32| lo1.max(lo2) < hi1.min(hi2);
                    ((a1 == b0 || b1 == a0) && overlap(a2, a3, b2, b3))
                        || ((a3 == b2 || b3 == a2) && overlap(a0, a1, b0, b1))
                };
                let mut unrestricted = None;
                loop {
                    let mut to_split: Vec<_> =
                        leaves.iter().copied().filter(|&l| over(l)).collect();
                    if to_split.is_empty() && unrestricted.is_none() {
                        unrestricted = Some(leaves.iter().filter(|&&l| visible(l)).count());
                    }
                    if to_split.is_empty() {
                        to_split = leaves
                            .iter()
                            .copied()
                            .filter(|&l| leaves.iter().any(|&m| m.0 + 1 < l.0 && adjacent(l, m)))
                            .collect();
                    }
                    if to_split.is_empty() {
                        break;
                    }
                    for l in to_split {
                        leaves.remove(&l);
                        leaves.extend(children(l));
                    }
                }
                let mut want = OracleCount::default();
                for &l in leaves.iter().filter(|&&l| visible(l)) {
                    assert!(l.0 == 0 || leaf_error_px(&data, l, cam.position, view.focal) <= tau);
                    let junctions = leaves
                        .iter()
                        .filter(|&&m| m.0 + 1 == l.0 && adjacent(l, m))
                        .count() as u64
                        / 2;
                    want.leaves += 1;
                    want.triangles += 2 + junctions;
                }
                let got = o.count(&data, &cam, w, h, tau);
                assert_eq!(got, want, "{cam:?} tau {tau}");
                frames += 1;
                unrestricted_smaller += (unrestricted.unwrap() < want.leaves as usize) as usize;
            }
        }
        println!("restriction added leaves in {unrestricted_smaller} of {frames} frames");
        assert!(unrestricted_smaller > 0, "restriction never mattered");
    }
}

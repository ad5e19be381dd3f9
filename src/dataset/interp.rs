//! Interpolation and gradients over a regular grid of samples: one implementation of each for
//! every CPU user (height maps, level-0 readers, void filling, imagery, UDLOD's level errors,
//! the clipmap's shading planes), so they cannot drift apart.
//!
//! The GPU's own arithmetic (f32, `shaders/include/terrain_common.wgsl`) is mirrored where a test
//! compares the two (`clipmap::quadtree`, `lod::udlod::select`), not here: these helpers work in
//! f64 on the host.

use glam::DVec3;

/// Where a position in sample units falls in a `width x height` grid, clamped to the grid: the
/// cell's south-west sample `(c0, r0)`, its far corner `(c1, r1)` (clamped to the last sample)
/// and the fraction `(fx, fy)` inside the cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridCell {
    pub c0: u32,
    pub r0: u32,
    pub c1: u32,
    pub r1: u32,
    pub fx: f64,
    pub fy: f64,
}

impl GridCell {
    /// The cell of `(gx, gy)` (sample units); positions outside the grid clamp onto its edge.
    /// `width` and `height` are at least 1.
    pub fn at(gx: f64, gy: f64, width: u32, height: u32) -> Self {
        let gx = gx.clamp(0.0, (width - 1) as f64);
        let gy = gy.clamp(0.0, (height - 1) as f64);
        let (c0, r0) = (gx.floor() as u32, gy.floor() as u32);
        GridCell {
            c0,
            r0,
            c1: (c0 + 1).min(width - 1),
            r1: (r0 + 1).min(height - 1),
            fx: gx - c0 as f64,
            fy: gy - r0 as f64,
        }
    }

    /// Bilinear interpolation of the cell's corners `[(c0, r0), (c1, r0), (c0, r1), (c1, r1)]`
    /// as `sample` gives them.
    pub fn bilinear(&self, mut sample: impl FnMut(u32, u32) -> f64) -> f64 {
        let Ok(h) = self.try_bilinear(|c, r| Ok::<_, std::convert::Infallible>(sample(c, r)));
        h
    }

    /// [`GridCell::bilinear`] with a fallible `sample` (its first error is returned).
    pub fn try_bilinear<E>(
        &self,
        mut sample: impl FnMut(u32, u32) -> Result<f64, E>,
    ) -> Result<f64, E> {
        let corners = [
            sample(self.c0, self.r0)?,
            sample(self.c1, self.r0)?,
            sample(self.c0, self.r1)?,
            sample(self.c1, self.r1)?,
        ];
        Ok(bilinear(corners, self.fx, self.fy))
    }
}

/// Bilinear interpolation of the corners `[h00, h10, h01, h11]` (south-west, south-east,
/// north-west, north-east) at fraction `(fx, fy)`: along x first, then y. Exact at the corners
/// (weights 1 and 0).
#[inline]
pub fn bilinear([h00, h10, h01, h11]: [f64; 4], fx: f64, fy: f64) -> f64 {
    let south = h00 * (1.0 - fx) + h10 * fx;
    let north = h01 * (1.0 - fx) + h11 * fx;
    south * (1.0 - fy) + north * fy
}

/// The height of a quad drawn as two triangles split along the diagonal from `(1, 0)` to
/// `(0, 1)` (as `lod::brute::grid_indices` orders them), at fraction `(fx, fy)` of the quad with
/// corners `[h00, h10, h01, h11]`: the surface a rasterizer draws between the four samples.
#[inline]
pub fn triangulated([h00, h10, h01, h11]: [f64; 4], fx: f64, fy: f64) -> f64 {
    if fx + fy <= 1.0 {
        h00 + (h10 - h00) * fx + (h01 - h00) * fy
    } else {
        h11 + (h01 - h11) * (1.0 - fx) + (h10 - h11) * (1.0 - fy)
    }
}

/// The axes a normal map's normals are given in.
pub enum NormalAxes<'a> {
    /// The grid's own frame: slopes over the stated metres between texels along x and y.
    Grid([f64; 2]),
    /// World axes: the normal of the surface through the texels' world positions,
    /// `position(col, row, height)` (on the earth the geolocation lattice's, where the drawn
    /// vertices lie).
    World(&'a (dyn Fn(usize, usize, f64) -> DVec3 + Sync)),
}

/// Unit surface normals of a `width x height` grid of heights (`height(col, row)`, metres) from
/// central differences, one-sided at the grid's edges, in `axes`, packed as RGBA8 snorm
/// `(x, y, z, 0)` row by row (the layout of the normal textures). In world axes the normal is
/// the cross product of the two central chords between the texels' world positions, which on
/// a flat grid of the stated spacing is the grid-frame normal exactly.
pub fn normals_snorm8(
    width: usize,
    height: usize,
    axes: &NormalAxes,
    heights: impl Fn(usize, usize) -> f64 + Sync,
) -> Vec<u8> {
    use rayon::prelude::*;
    // Written in place, rows (or bands of rows) in parallel: no copy of the whole map.
    let mut out = vec![0u8; width * height * 4];
    let row_bytes = width * 4;
    match axes {
        NormalAxes::Grid(_) => {
            out.par_chunks_mut(row_bytes.max(1))
                .enumerate()
                .for_each(|(r, row)| {
                    for (c, texel) in row.chunks_exact_mut(4).enumerate() {
                        texel.copy_from_slice(&snorm8(normal_at(
                            width, height, axes, &heights, c, r,
                        )));
                    }
                })
        }
        // In bands of rows, each texel's world position computed once (not once per chord
        // that uses it): the same positions and arithmetic as `normal_at`, a quarter of the
        // lattice evaluations.
        NormalAxes::World(position) => out
            .par_chunks_mut((WORLD_BAND_ROWS * row_bytes).max(1))
            .enumerate()
            .for_each(|(band, texels)| {
                let r0 = band * WORLD_BAND_ROWS;
                let r1 = (r0 + WORLD_BAND_ROWS).min(height);
                let (lo, hi) = (r0.saturating_sub(1), (r1 + 1).min(height));
                let positions: Vec<DVec3> = (lo..hi)
                    .flat_map(|r| (0..width).map(move |c| (c, r)))
                    .map(|(c, r)| position(c, r, heights(c, r)))
                    .collect();
                let at = |c: usize, r: usize| positions[(r - lo) * width + c];
                for (k, texel) in texels.chunks_exact_mut(4).enumerate() {
                    let (c, r) = (k % width, r0 + k / width);
                    texel.copy_from_slice(&snorm8(chord_normal(width, height, at, c, r)));
                }
            }),
    }
    out
}

/// Rows per band of [`normals_snorm8`] in world axes.
const WORLD_BAND_ROWS: usize = 32;

/// The unit normal at sample `(c, r)` of [`normals_snorm8`], before quantization.
pub fn normal_at(
    width: usize,
    height: usize,
    axes: &NormalAxes,
    heights: impl Fn(usize, usize) -> f64,
    c: usize,
    r: usize,
) -> DVec3 {
    match axes {
        NormalAxes::Grid(step) => {
            let (cl, cr) = (c.saturating_sub(1), (c + 1).min(width - 1));
            let (rd, ru) = (r.saturating_sub(1), (r + 1).min(height - 1));
            let dx = (heights(cr, r) - heights(cl, r)) / ((cr - cl) as f64 * step[0]);
            let dy = (heights(c, ru) - heights(c, rd)) / ((ru - rd) as f64 * step[1]);
            DVec3::new(-dx, -dy, 1.0).normalize()
        }
        NormalAxes::World(position) => {
            chord_normal(width, height, |c, r| position(c, r, heights(c, r)), c, r)
        }
    }
}

/// The normal at `(c, r)` of the surface through world positions `at(col, row)`: the cross
/// product of the central chords along columns and rows (one-sided at the grid's edges).
fn chord_normal(
    width: usize,
    height: usize,
    at: impl Fn(usize, usize) -> DVec3,
    c: usize,
    r: usize,
) -> DVec3 {
    let (cl, cr) = (c.saturating_sub(1), (c + 1).min(width - 1));
    let (rd, ru) = (r.saturating_sub(1), (r + 1).min(height - 1));
    let along_x = at(cr, r) - at(cl, r);
    let along_y = at(c, ru) - at(c, rd);
    along_x.cross(along_y).normalize()
}

/// A unit normal from the height gradient (metres per metre), as RGBA8 snorm `(x, y, z, 0)`.
pub fn normal_snorm8(dx: f64, dy: f64) -> [u8; 4] {
    snorm8(DVec3::new(-dx, -dy, 1.0).normalize())
}

/// A unit vector as RGBA8 snorm `(x, y, z, 0)`.
fn snorm8(n: DVec3) -> [u8; 4] {
    [n.x, n.y, n.z, 0.0].map(|v| ((v * 127.0).round().clamp(-127.0, 127.0) as i8) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_is_exact_at_corners_and_linear_along_edges() {
        let k = [1.0, 3.0, 5.0, 11.0];
        assert_eq!(bilinear(k, 0.0, 0.0), 1.0);
        assert_eq!(bilinear(k, 1.0, 0.0), 3.0);
        assert_eq!(bilinear(k, 0.0, 1.0), 5.0);
        assert_eq!(bilinear(k, 1.0, 1.0), 11.0);
        assert_eq!(bilinear(k, 0.5, 0.0), 2.0);
        // The centre: the mean of the corners (the triangulated quad takes the diagonal's).
        assert_eq!(bilinear(k, 0.5, 0.5), 5.0);
        assert_eq!(triangulated(k, 0.5, 0.5), 4.0);
    }

    #[test]
    fn grid_cell_clamps_onto_the_grid() {
        let c = GridCell::at(-3.0, 7.5, 4, 8);
        assert_eq!((c.c0, c.c1, c.fx), (0, 1, 0.0));
        assert_eq!((c.r0, c.r1, c.fy), (7, 7, 0.0));
        let c = GridCell::at(2.25, 3.0, 4, 8);
        assert_eq!(
            (c.c0, c.c1, c.fx, c.r0, c.r1, c.fy),
            (2, 3, 0.25, 3, 4, 0.0)
        );
    }

    #[test]
    fn normals_of_a_plane_are_its_normal_everywhere_including_edges() {
        // z = 0.5 x: normal (-0.5, 0, 1) / |..|, at every sample (one-sided differences agree
        // with central ones on a plane).
        let n = normals_snorm8(5, 3, &NormalAxes::Grid([2.0, 2.0]), |c, _| c as f64);
        let want = normal_snorm8(0.5, 0.0);
        assert!(n.chunks_exact(4).all(|t| t == want));
        assert_eq!(n.len(), 5 * 3 * 4);
    }

    /// The banded world-axes normal map is `normal_at` quantized at every texel, across band
    /// edges and at the grid's edges.
    #[test]
    fn world_normal_maps_are_normal_at_everywhere() {
        let (w, h) = (7, 2 * WORLD_BAND_ROWS + 5);
        let heights = |c: usize, r: usize| ((c * 5 + r * 11) % 7) as f64 * 3.0;
        let bent = |c: usize, r: usize, z: f64| {
            DVec3::new(
                c as f64 * 10.0 + r as f64 * 0.5,
                r as f64 * 9.0,
                z - (c * c) as f64 * 0.01,
            )
        };
        let axes = NormalAxes::World(&bent);
        let map = normals_snorm8(w, h, &axes, heights);
        for r in 0..h {
            for c in 0..w {
                let want = snorm8(normal_at(w, h, &axes, heights, c, r));
                assert_eq!(map[(r * w + c) * 4..][..4], want, "{c},{r}");
            }
        }
    }

    /// World axes through positions that are the grid's own (the flat world: `(c sx, r sy,
    /// h)`) give the grid frame's normals; a mirrored grid (rows running south) flips them.
    #[test]
    fn world_axes_through_the_grids_own_positions_are_the_grid_frame() {
        let heights =
            |c: usize, r: usize| ((c * 7 + r * 3) % 5) as f64 * 1.5 + (c * r) as f64 * 0.25;
        let step = [2.0, 3.0];
        let grid = normals_snorm8(6, 5, &NormalAxes::Grid(step), heights);
        let flat =
            |c: usize, r: usize, h: f64| DVec3::new(c as f64 * step[0], r as f64 * step[1], h);
        let world = normals_snorm8(6, 5, &NormalAxes::World(&flat), heights);
        assert_eq!(world, grid);
        let mirrored =
            |c: usize, r: usize, h: f64| DVec3::new(c as f64 * step[0], -(r as f64) * step[1], h);
        let flipped = normals_snorm8(6, 5, &NormalAxes::World(&mirrored), heights);
        assert_ne!(flipped, grid);
    }
}

//! Normals on the earth without lattice reads per fragment: the normal matrix of a grid
//! (`world_normal` in `shaders/include/terrain_common.wgsl`, docs/coordinates.md "Normals on the
//! earth") modelled as one quadratic polynomial over the whole grid, fitted once at start-up
//! and checked against the lattice at every node.

use glam::{DMat3, DVec2, DVec3};

use super::lattice::{GridFrame, Lattice};

/// The largest angle (radians) by which [`NormalModel`] may turn a normal at any lattice node
/// for `world_normal` to take the model (no lattice reads per fragment): 20 times below the
/// 8-bit normal maps' quantization (up to ~4e-3 rad).
pub const NORMAL_MODEL_TOLERANCE: f64 = 2e-4;

/// vec4 per model on the GPU: three xyz columns per term (`frame.normal_model`).
pub const NORMAL_MODEL_VEC4S: usize = crate::gpu_constants::NORMAL_MODEL_VEC4S as usize;

/// Terms of the model's polynomial in the grid fraction `f` (0 to 1 per axis), in this order:
/// `1, fx, fx^2, fy, fy^2, fx fy`.
pub const NORMAL_MODEL_TERMS: usize = NORMAL_MODEL_VEC4S / 3;

/// The matrix taking a normal given in the grid's frame (the normal maps' `(-dh/dx, -dh/dy, 1)`
/// normalized, slopes per stated metre `stated_spacing`) to world axes, up to its length, where
/// the grid's frame is `[u, tx, ty]`: columns `sx (ty x u)`, `sy (u x tx)`, `tx x ty`. The
/// surface's tangents are `tx + hx u` and `ty + hy u` (`hx = -n.x / n.z * sx` metres per
/// sample), so its normal is their cross product times `n.z`: this matrix times `n` (the
/// cofactor of the grid-to-world map).
pub fn normal_matrix(frame: &GridFrame, stated_spacing: [f64; 2]) -> DMat3 {
    let [u, tx, ty] = *frame;
    DMat3::from_cols(
        ty.cross(u) * stated_spacing[0],
        u.cross(tx) * stated_spacing[1],
        tx.cross(ty),
    )
}

/// The normal matrix of a whole grid as `sum_i w_i(f) M_i` with the weights
/// `1, fx, fx^2, fy, fy^2, fx fy` of the grid fraction `f`.
///
/// Why quadratic: across a grid the frame turns (1 degree per 111 km) and a geographic grid's
/// east-west metres go with cos(latitude). A bilinear model between the corners' matrices
/// shrinks the columns that turn (a chord between two unit vectors `d` radians apart is
/// `d^2 / 8` short in its middle) and misses cos's curvature by as much again: 6.0e-4 rad on
/// the Pyrenees data set (1 x 2 degrees), over the tolerance. The squares take both up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalModel {
    pub terms: [DMat3; NORMAL_MODEL_TERMS],
}

impl NormalModel {
    /// The least-squares fit to the lattice's normal matrices at every node of a `width` x
    /// `height` grid, and the largest angle it turns any normal by at a node. With `E` the
    /// lattice's matrix and `M` the model's there, `M n = (I + K) E n` for
    /// `K = (M - E) E^-1`, so the world normal turns by at most `|K|` (spectral, bounded here
    /// by the Frobenius norm).
    pub fn fit(
        lattice: &Lattice,
        width: u32,
        height: u32,
        stated_spacing: [f64; 2],
    ) -> (Self, f64) {
        let samples = node_matrices(lattice, width, height, stated_spacing);
        let mut gram = [[0.0; NORMAL_MODEL_TERMS]; NORMAL_MODEL_TERMS];
        let mut rhs = [[0.0; 9]; NORMAL_MODEL_TERMS];
        for (f, e) in &samples {
            let w = weights(*f);
            let e = e.to_cols_array();
            for i in 0..NORMAL_MODEL_TERMS {
                for j in 0..NORMAL_MODEL_TERMS {
                    gram[i][j] += w[i] * w[j];
                }
                for (r, v) in rhs[i].iter_mut().zip(e) {
                    *r += w[i] * v;
                }
            }
        }
        let coefficients = solve_ridge(gram, rhs);
        let model = NormalModel {
            terms: coefficients.map(|c| DMat3::from_cols_array(&c)),
        };
        let departure = departure(&samples, |f, n| model.normal(f, n));
        (model, departure)
    }

    /// The model's normal matrix at fraction `f` of the grid, summed in the order
    /// `modelled_matrix` in `shaders/include/terrain_common.wgsl` sums it (its CPU twin).
    pub fn matrix(&self, f: DVec2) -> DMat3 {
        let t = &self.terms;
        t[0] + (t[1] + t[2] * f.x + t[5] * f.y) * f.x + (t[3] + t[4] * f.y) * f.y
    }

    /// The world normal (not normalized) of grid-frame normal `n` at fraction `f` of the grid.
    pub fn normal(&self, f: DVec2, n: DVec3) -> DVec3 {
        self.matrix(f) * n
    }

    /// The GPU's copy: each term's three columns (xyz of one vec4 each).
    pub fn to_gpu(&self) -> [[f32; 4]; NORMAL_MODEL_VEC4S] {
        let mut out = [[0.0f32; 4]; NORMAL_MODEL_VEC4S];
        let columns = self
            .terms
            .iter()
            .flat_map(|m| [m.x_axis, m.y_axis, m.z_axis]);
        for (k, v) in columns.enumerate() {
            out[k] = [v.x as f32, v.y as f32, v.z as f32, 0.0];
        }
        out
    }
}

/// The largest angle a model (`normal`: grid fraction and grid-frame normal to world normal,
/// linear in the normal) turns any normal by at the nodes `samples` ([`NormalModel::fit`]).
fn departure(samples: &[(DVec2, DMat3)], normal: impl Fn(DVec2, DVec3) -> DVec3) -> f64 {
    samples
        .iter()
        .map(|(f, e)| {
            let m = DMat3::from_cols(
                normal(*f, DVec3::X),
                normal(*f, DVec3::Y),
                normal(*f, DVec3::Z),
            );
            matrix_departure(m, *e)
        })
        .fold(0.0, f64::max)
}

/// The largest angle matrix `m` turns any normal by against matrix `e`: `m n = (I + K) e n`
/// with `K = (m - e) e^-1`, bounded by the Frobenius norm of `K`.
fn matrix_departure(m: DMat3, e: DMat3) -> f64 {
    let k = (m - e) * e.inverse();
    (k.x_axis.length_squared() + k.y_axis.length_squared() + k.z_axis.length_squared()).sqrt()
}

fn weights(f: DVec2) -> [f64; NORMAL_MODEL_TERMS] {
    [1.0, f.x, f.x * f.x, f.y, f.y * f.y, f.x * f.y]
}

/// The lattice's normal matrix at every node (the grid fraction and the matrix).
fn node_matrices(
    lattice: &Lattice,
    width: u32,
    height: u32,
    stated_spacing: [f64; 2],
) -> Vec<(DVec2, DMat3)> {
    let last = DVec2::new(width.max(2) as f64 - 1.0, height.max(2) as f64 - 1.0);
    let mut out = Vec::with_capacity((lattice.nodes[0] * lattice.nodes[1]) as usize);
    for j in 0..lattice.nodes[1] {
        for i in 0..lattice.nodes[0] {
            let s = DVec2::new((i * lattice.step) as f64, (j * lattice.step) as f64).min(last);
            out.push((
                s / last,
                normal_matrix(&lattice.grid_frame(s), stated_spacing),
            ));
        }
    }
    out
}

/// Solves `gram c = rhs` (9 right-hand sides) by Gaussian elimination with partial pivoting,
/// with a ridge of 1e-12 of the trace on the diagonal: a grid with fewer than three nodes per
/// axis leaves the squares undetermined, and the ridge sets them to ~0 there.
fn solve_ridge(
    mut gram: [[f64; NORMAL_MODEL_TERMS]; NORMAL_MODEL_TERMS],
    mut rhs: [[f64; 9]; NORMAL_MODEL_TERMS],
) -> [[f64; 9]; NORMAL_MODEL_TERMS] {
    const N: usize = NORMAL_MODEL_TERMS;
    let ridge = 1e-12 * (0..N).map(|i| gram[i][i]).sum::<f64>();
    for (i, row) in gram.iter_mut().enumerate() {
        row[i] += ridge;
    }
    for col in 0..N {
        let pivot = (col..N)
            .max_by(|&a, &b| gram[a][col].abs().total_cmp(&gram[b][col].abs()))
            .unwrap_or(col);
        gram.swap(col, pivot);
        rhs.swap(col, pivot);
        let (pivot_gram, pivot_rhs) = (gram[col], rhs[col]);
        for row in col + 1..N {
            let factor = gram[row][col] / pivot_gram[col];
            for (g, p) in gram[row][col..].iter_mut().zip(&pivot_gram[col..]) {
                *g -= factor * p;
            }
            for (r, p) in rhs[row].iter_mut().zip(&pivot_rhs) {
                *r -= factor * p;
            }
        }
    }
    let mut out = [[0.0; 9]; N];
    for row in (0..N).rev() {
        for k in 0..9 {
            let known: f64 = (row + 1..N).map(|j| gram[row][j] * out[j][k]).sum();
            out[row][k] = (rhs[row][k] - known) / gram[row][row];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn angle(a: DVec3, b: DVec3) -> f64 {
        a.cross(b).length().atan2(a.dot(b))
    }

    /// 1 x 2 degrees of 3" samples at 41-43 N (the Pyrenees data set's shape), the stated
    /// spacing at the centre latitude as the normal maps take it.
    fn pyrenees() -> (Lattice, u32, u32, [f64; 2]) {
        let d = 1.0 / 1200.0;
        let l = Lattice::geographic(1201, 2401, [1.0, 41.0], [d, d]).unwrap();
        let stated = [
            d.to_radians() * 6_378_137.0 * 42f64.to_radians().cos(),
            d.to_radians() * 6_367_000.0,
        ];
        (l, 1201, 2401, stated)
    }

    #[test]
    fn the_departure_bounds_every_normal_at_the_nodes() {
        let (l, w, h, stated) = pyrenees();
        let (model, departure) = NormalModel::fit(&l, w, h, stated);
        // Slopes up to 3 : 1 in eight directions, and flat.
        let normals: Vec<DVec3> = (0..8)
            .flat_map(|k| {
                let (sin, cos) = (k as f64 * 45f64.to_radians()).sin_cos();
                [0.3, 1.0, 3.0].map(|g| DVec3::new(g * cos, g * sin, 1.0).normalize())
            })
            .chain([DVec3::Z])
            .collect();
        let mut worst: f64 = 0.0;
        for (f, e) in node_matrices(&l, w, h, stated) {
            for &n in &normals {
                worst = worst.max(angle(model.normal(f, n), e * n));
            }
        }
        // A bound (never below what it bounds) and not a vacuous one (within 4x of it), under
        // the tolerance that lets the renderer take the model on such a grid.
        println!("worst {worst:.2e} rad, departure {departure:.2e} rad");
        assert!(worst <= departure, "{worst} > {departure}");
        assert!(worst > departure / 4.0, "{worst} vs {departure}");
        assert!(departure < NORMAL_MODEL_TOLERANCE, "{departure}");
    }

    #[test]
    fn the_squares_are_what_the_model_needs_and_wide_grids_are_refused() {
        let (l, w, h, stated) = pyrenees();
        let (_, quadratic) = NormalModel::fit(&l, w, h, stated);
        // Control: the bilinear model between the corners' matrices (no squares) misses.
        let samples = node_matrices(&l, w, h, stated);
        let corner = |f: DVec2| {
            let s = f * DVec2::new((w - 1) as f64, (h - 1) as f64);
            normal_matrix(&l.grid_frame(s), stated)
        };
        let c = [DVec2::ZERO, DVec2::X, DVec2::Y, DVec2::ONE].map(corner);
        let bilinear = |f: DVec2, n: DVec3| {
            let lerp = |a: DVec3, b: DVec3, t: f64| a * (1.0 - t) + b * t;
            lerp(
                lerp(c[0] * n, c[1] * n, f.x),
                lerp(c[2] * n, c[3] * n, f.x),
                f.y,
            )
        };
        let bilinear_departure = departure(&samples, bilinear);
        println!("quadratic {quadratic:.2e} rad, bilinear {bilinear_departure:.2e} rad");
        assert!(
            bilinear_departure > 3.0 * quadratic && bilinear_departure > NORMAL_MODEL_TOLERANCE,
            "{bilinear_departure} vs {quadratic}"
        );
        // 30" samples from 45 N: 8 x 2 degrees still take the model, 16 x 4 degrees (the
        // parallels' sagitta four times as deep) do not.
        let d = 30.0 / 3600.0;
        let stated = [stated[0] * 10.0, stated[1] * 10.0];
        let wide = |(wdeg, hdeg): (f64, f64)| {
            let (w, h) = ((wdeg / d) as u32 + 1, (hdeg / d) as u32 + 1);
            let l = Lattice::geographic(w, h, [-3.0, 45.0], [d, d]).unwrap();
            NormalModel::fit(&l, w, h, stated).1
        };
        assert!(wide((8.0, 2.0)) < NORMAL_MODEL_TOLERANCE);
        assert!(wide((16.0, 4.0)) > NORMAL_MODEL_TOLERANCE);
    }

    /// The drawing shaders evaluate the model at the vertices and interpolate the matrix
    /// linearly across each triangle (`terrain_vertex` in terrain_common.wgsl). The model is
    /// quadratic in the grid fraction, so that departs from it by about the square of the
    /// triangle's extent: a sixteenth of the Pyrenees grid stays far inside the tolerance, the
    /// whole grid (control) does not.
    #[test]
    fn interpolating_the_model_across_a_triangle_departs_by_its_extent_squared() {
        let (l, w, h, stated) = pyrenees();
        let (model, _) = NormalModel::fit(&l, w, h, stated);
        // Both triangles of quads of side `d` (grid fraction) tiling the grid, probed at edge
        // midpoints and centroids against the model there.
        let interpolation_departure = |d: f64| {
            let mut worst: f64 = 0.0;
            let steps = (1.0 / d).round() as usize;
            for j in 0..steps {
                for i in 0..steps {
                    let o = DVec2::new(i as f64, j as f64) * d;
                    let quad = [DVec2::ZERO, DVec2::X, DVec2::Y, DVec2::ONE].map(|c| o + c * d);
                    for tri in [[quad[0], quad[1], quad[2]], [quad[1], quad[3], quad[2]]] {
                        let m = tri.map(|v| model.matrix(v));
                        let probes = [
                            [0.5, 0.5, 0.0],
                            [0.0, 0.5, 0.5],
                            [0.5, 0.0, 0.5],
                            [1.0 / 3.0; 3],
                        ];
                        for w in probes {
                            let f = tri[0] * w[0] + tri[1] * w[1] + tri[2] * w[2];
                            let lerped = m[0] * w[0] + m[1] * w[1] + m[2] * w[2];
                            worst = worst.max(matrix_departure(lerped, model.matrix(f)));
                        }
                    }
                }
            }
            worst
        };
        let sixteenth = interpolation_departure(1.0 / 16.0);
        let whole = interpolation_departure(1.0);
        println!(
            "interpolated across 1/16 of the grid {sixteenth:.2e} rad, across all of it {whole:.2e} rad"
        );
        assert!(sixteenth < NORMAL_MODEL_TOLERANCE / 50.0, "{sixteenth}");
        assert!(whole > NORMAL_MODEL_TOLERANCE, "{whole}");
        // Quadratic: 16 times finer, 256 times closer (within rounding of the sampling).
        assert!(whole / sixteenth > 100.0, "{whole} / {sixteenth}");
    }
}

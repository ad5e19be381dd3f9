//! The crack/popping tests' camera poses: high straight down, grazing, ground level, outside
//! looking in, and ordinary flight, spread over the data set.

use glam::DVec3;
use vkterrain::dataset::Heightmap;
use vkterrain::dataset::procedural::Style;
use vkterrain::geo::{EnuFrame, Geodetic, Lattice, WGS84};
use vkterrain::lod::udlod::levels::{Levels, Tile};
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

/// The CI terrain's shape (513 samples, 60 m) as a procedural grid anchored on the earth at
/// 46.5 N 8 E (config/ci_earth.toml): its far corner lies ~140 m below the tangent plane at
/// sample (0, 0). Returns the grid and its lattice (shared, as the methods hold it).
pub fn anchored_ci(size: u32, spacing: f64) -> (Heightmap, std::sync::Arc<Lattice>) {
    let data = vkterrain::dataset::procedural::generate(
        &vkterrain::dataset::procedural::ProceduralParams {
            size,
            spacing,
            seed: 1,
            ..Default::default()
        },
    )
    .unwrap();
    let frame = EnuFrame::new(&WGS84, Geodetic::new(46.5, 8.0, 0.0));
    let lattice = Lattice::anchored_plane(size, size, spacing, frame).unwrap();
    (data, std::sync::Arc::new(lattice))
}

/// A native geographic grid at 60 N (`size` samples of 3 arc seconds per side, from 8 E, 60 N):
/// east-west samples lie half as far apart as north-south ones. Heights from the procedural
/// generator; `spacing` (the one LOD metric) the smallest metric spacing, the east-west one at
/// the poleward edge, as a geographic data set's (docs/coordinates.md, "Native grids").
pub fn geographic_60n(size: u32) -> (Heightmap, std::sync::Arc<Lattice>) {
    geographic_native(size, 60.0, 3, Style::Classic)
}

/// [`geographic_60n`] from latitude `lat0` (procedural heights of `seed` and `style`).
pub fn geographic_native(
    size: u32,
    lat0: f64,
    seed: u64,
    style: Style,
) -> (Heightmap, std::sync::Arc<Lattice>) {
    let step = 1.0 / 1200.0;
    let lattice = Lattice::geographic(size, size, [8.0, lat0], [step, step]).unwrap();
    let north = lat0 + (size - 1) as f64 * step;
    let ew = WGS84.prime_vertical_radius(north) * north.to_radians().cos() * step.to_radians();
    let ns = WGS84.meridian_radius(lat0) * step.to_radians();
    let mut data = vkterrain::dataset::procedural::generate(
        &vkterrain::dataset::procedural::ProceduralParams {
            size,
            spacing: ew,
            seed,
            style,
            ..Default::default()
        },
    )
    .unwrap();
    data.axis_spacing = [ew, ns];
    (data, std::sync::Arc::new(lattice))
}

/// Where the renderer measures LOD distances from on the earth (`Renderer::grid_viewer`):
/// the sample position under the world point `p` in grid metres, and its height.
pub fn grid_viewer(lattice: &Lattice, spacing: f64, p: DVec3) -> DVec3 {
    let (s, h) = lattice.sample_at(p);
    DVec3::new(s.x * spacing, s.y * spacing, h)
}

/// Culling poses on the earth: `n` of [`poses`] carried onto the ellipsoid through `lattice`
/// (a grid point `(x, y)` at height `z` goes to `lattice.position(x, y, z)`), then 12 views
/// along the data's edges (from each corner 100 m above the ground, 3 degrees down, along an
/// edge and 40 degrees to either side of it: the edge near a side plane of the frustum), and
/// 6 from far away (40, 90 and 150 km from the centre, 2-10 km up, looking at it).
pub fn earth_poses(data: &Heightmap, lattice: &Lattice, n: usize) -> Vec<Camera> {
    let s = data.spacing;
    let on_earth = |x: f64, y: f64, z: f64| lattice.position(glam::DVec2::new(x / s, y / s), z);
    let mut out: Vec<Camera> = poses(data, n)
        .into_iter()
        .map(|mut c| {
            c.position = on_earth(c.position.x, c.position.y, c.position.z);
            c
        })
        .collect();
    let (ex, ey) = data.extent();
    // Corner, and the yaw along the edge that leaves it.
    for (x, y, yaw) in [
        (0.0, 0.0, 90.0),
        (ex, 0.0, 0.0),
        (ex, ey, 270.0),
        (0.0, ey, 180.0),
    ] {
        for turn in [-40.0, 0.0, 40.0] {
            out.push(Camera {
                position: on_earth(x, y, data.height_at(x, y) + 100.0),
                yaw_deg: yaw + turn,
                pitch_deg: -3.0,
                near: 0.25,
                ..Camera::default()
            });
        }
    }
    for (k, (d, z)) in [(40e3, 2e3), (90e3, 5e3), (150e3, 10e3)]
        .into_iter()
        .enumerate()
    {
        for side in [0.0, 1.0] {
            let a = (35.0 + 140.0 * side + 20.0 * k as f64).to_radians();
            let (x, y) = (0.5 * ex + d * a.sin(), 0.5 * ey + d * a.cos());
            let yaw = (a.to_degrees() + 180.0) % 360.0;
            // Down towards the centre (the curvature drops it further: d^2 / 2R).
            let drop = d * d / (2.0 * 6.371e6);
            out.push(Camera {
                position: on_earth(x, y, z),
                yaw_deg: yaw,
                pitch_deg: -((z + drop) / d).atan().to_degrees(),
                near: 1.0,
                far: 400e3,
                ..Camera::default()
            });
        }
    }
    out
}

/// Every tile of `levels` from level `first` up to the root.
pub fn tiles_from(levels: &Levels, first: u32) -> Vec<Tile> {
    (first..=levels.root_lod)
        .flat_map(|lod| {
            let (nx, ny) = levels.tiles_per_side[lod as usize];
            (0..ny).flat_map(move |y| (0..nx).map(move |x| Tile { x, y, lod }))
        })
        .collect()
}

/// The nearest true chord (metres) from world point `from` to tile `t`'s samples (of a
/// `size`-sample grid, `levels`' tiling) through `lattice`: every `(span / 16)`-th sample of
/// its rectangle (and its far edges) at height `height(col, row)`. The oracle the LOD
/// methods' distance lower-bound tests compare with.
pub fn nearest_chord(
    lattice: &Lattice,
    levels: &Levels,
    size: [u32; 2],
    t: Tile,
    height: impl Fn(u32, u32) -> f64,
    from: DVec3,
) -> f64 {
    let span = levels.grid_size << t.lod;
    let c0 = [t.x * span, t.y * span];
    let c1 = [
        ((t.x + 1) * span).min(size[0] - 1),
        ((t.y + 1) * span).min(size[1] - 1),
    ];
    let step = (span / 16).max(1) as usize;
    let mut nearest = f64::INFINITY;
    for r in (c0[1]..=c1[1]).step_by(step).chain([c1[1]]) {
        for c in (c0[0]..=c1[0]).step_by(step).chain([c1[0]]) {
            let q = lattice.position(glam::DVec2::new(c as f64, r as f64), height(c, r));
            nearest = nearest.min((q - from).length());
        }
    }
    nearest
}

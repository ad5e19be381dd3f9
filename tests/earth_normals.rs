//! The normal maps on the earth (docs/coordinates.md, "Normals on the earth"): their normals are
//! baked in world axes on the host, from the drawn surface's positions through the geolocation
//! lattice (`dataset::interp::NormalAxes::World`), and every method shades with them as they
//! are. Compared with the terrain's normal from independent f64 geodesy written out here (the
//! local east/north/up at the sample's latitude/longitude, the true metres per sample there);
//! a rendered image under a low sun is lit by the local vertical, not the world's. Negative
//! controls: the unrotated normal, a rotation that keeps the stated spacing, and a flipped
//! north axis all miss by more than the tolerance; the flat world keeps the grid's normals.

mod common;

use std::sync::Arc;

use glam::{DVec2, DVec3};
use vkterrain::dataset::interp::{NormalAxes, normal_at};
use vkterrain::dataset::{Albedo, Heightmap};
use vkterrain::driver::Gpu;
use vkterrain::geo::Lattice;
use vkterrain::lod::MethodKind;
use vkterrain::readback::CollectSink;
use vkterrain::render::{FrameRequest, Renderer};
use vkterrain::scene::Camera;

// ---- Independent f64 geodesy (the oracle) -------------------------------------------------

const A: f64 = 6_378_137.0;
const F: f64 = 1.0 / 298.257_223_563;

fn e2() -> f64 {
    F * (2.0 - F)
}

/// East, north and up unit vectors (ECEF) at a geodetic latitude/longitude.
fn enu_axes(lat_deg: f64, lon_deg: f64) -> [DVec3; 3] {
    let (p, l) = (lat_deg.to_radians(), lon_deg.to_radians());
    [
        DVec3::new(-l.sin(), l.cos(), 0.0),
        DVec3::new(-p.sin() * l.cos(), -p.sin() * l.sin(), p.cos()),
        DVec3::new(p.cos() * l.cos(), p.cos() * l.sin(), p.sin()),
    ]
}

/// The local east, north, up at `(lat, lon)` in the world frame (ENU at `(lat0, lon0)`).
fn local_axes_in_world(lat0: f64, lon0: f64, lat: f64, lon: f64) -> [DVec3; 3] {
    let world = enu_axes(lat0, lon0);
    enu_axes(lat, lon).map(|v| DVec3::new(v.dot(world[0]), v.dot(world[1]), v.dot(world[2])))
}

/// Metres per radian of longitude (the parallel's radius) and of latitude (the meridian's).
fn metres_per_radian(lat_deg: f64) -> [f64; 2] {
    let w2 = 1.0 - e2() * lat_deg.to_radians().sin().powi(2);
    [
        A / w2.sqrt() * lat_deg.to_radians().cos(),
        A * (1.0 - e2()) / (w2 * w2.sqrt()),
    ]
}

/// A geographic grid `cols x rows`, `d` degrees per sample on both axes, its south-west
/// sample at `(lat0, lon0)`: what the lattice and the stated spacing are.
struct Grid {
    lat0: f64,
    lon0: f64,
    d: f64,
    cols: u32,
    rows: u32,
}

impl Grid {
    fn lat_lon(&self, s: DVec2) -> (f64, f64) {
        (self.lat0 + s.y * self.d, self.lon0 + s.x * self.d)
    }

    /// The stated metres between samples, as a native geographic data set's manifest holds
    /// them: both at the grid's centre latitude.
    fn stated_spacing(&self) -> [f64; 2] {
        let centre = self.lat0 + (self.rows - 1) as f64 * self.d / 2.0;
        metres_per_radian(centre).map(|m| m * self.d.to_radians())
    }

    /// True metres per sample east-west and north-south at sample position `s` (height 0).
    fn true_spacing(&self, s: DVec2) -> [f64; 2] {
        metres_per_radian(self.lat_lon(s).0).map(|m| m * self.d.to_radians())
    }

    fn lattice(&self) -> Lattice {
        Lattice::geographic(
            self.cols,
            self.rows,
            [self.lon0, self.lat0],
            [self.d, self.d],
        )
        .unwrap()
    }

    /// Flat heights `h` with a uniform albedo: the grid's heightmap with its stated spacing.
    fn heightmap(&self, h: f32, albedo: u8) -> Heightmap {
        let n = (self.cols * self.rows) as usize;
        self.heightmap_of(vec![h; n], albedo)
    }

    /// `heights` (row by row) with a uniform albedo and the grid's stated spacing.
    fn heightmap_of(&self, heights: Vec<f32>, albedo: u8) -> Heightmap {
        let n = (self.cols * self.rows) as usize;
        let mut map = Heightmap::new(
            "geographic",
            self.cols,
            self.rows,
            self.stated_spacing()[1],
            heights,
        )
        .unwrap();
        map.axis_spacing = self.stated_spacing();
        map.albedo = Some(Albedo {
            width: self.cols,
            height: self.rows,
            rgba: [albedo, albedo, albedo, 255].repeat(n),
        });
        map
    }

    /// A sample's world position at height `h` (metres above the ellipsoid): ECEF from its
    /// latitude/longitude, in the ENU axes at the grid's origin, relative to it.
    fn world_position(&self, s: DVec2, h: f64) -> DVec3 {
        let ecef = |lat: f64, lon: f64, h: f64| {
            let (p, l) = (lat.to_radians(), lon.to_radians());
            let n = A / (1.0 - e2() * p.sin().powi(2)).sqrt();
            DVec3::new(
                (n + h) * p.cos() * l.cos(),
                (n + h) * p.cos() * l.sin(),
                (n * (1.0 - e2()) + h) * p.sin(),
            )
        };
        let (lat, lon) = self.lat_lon(s);
        let d = ecef(lat, lon, h) - ecef(self.lat0, self.lon0, 0.0);
        let [e, n, u] = enu_axes(self.lat0, self.lon0);
        DVec3::new(d.dot(e), d.dot(n), d.dot(u))
    }

    /// The exact oracle: the normal of the surface through the samples' true positions at
    /// their heights (`heights(col, row)`), from the same central chords as the normal maps
    /// (one-sided at the grid's edges).
    fn chord_normal(&self, c: usize, r: usize, heights: impl Fn(usize, usize) -> f64) -> DVec3 {
        let (w, h) = (self.cols as usize, self.rows as usize);
        let at =
            |c: usize, r: usize| self.world_position(DVec2::new(c as f64, r as f64), heights(c, r));
        let along_x = at((c + 1).min(w - 1), r) - at(c.saturating_sub(1), r);
        let along_y = at(c, (r + 1).min(h - 1)) - at(c, r.saturating_sub(1));
        along_x.cross(along_y).normalize()
    }

    /// The tangent-plane oracle: the world-axes normal of terrain at `s` whose normal map holds `n` (slopes
    /// per stated metre along columns and rows): the slopes per true metre along the local
    /// east and north, `normalize(-gx east - gy north + up)`.
    fn world_normal(&self, s: DVec2, n: DVec3) -> DVec3 {
        let (lat, lon) = self.lat_lon(s);
        let [east, north, up] = local_axes_in_world(self.lat0, self.lon0, lat, lon);
        let (stated, metric) = (self.stated_spacing(), self.true_spacing(s));
        let gx = -n.x / n.z * stated[0] / metric[0];
        let gy = -n.y / n.z * stated[1] / metric[1];
        (-gx * east - gy * north + up).normalize()
    }
}

/// A normal-map normal (grid frame) of slopes `(dh/dx, dh/dy)` per stated metre.
fn grid_normal(slope: [f64; 2]) -> DVec3 {
    DVec3::new(-slope[0], -slope[1], 1.0).normalize()
}

fn angle(a: DVec3, b: DVec3) -> f64 {
    a.normalize()
        .cross(b.normalize())
        .length()
        .atan2(a.normalize().dot(b.normalize()))
}

fn render(
    gpu: &Arc<Gpu>,
    data: &Heightmap,
    lattice: Option<&Lattice>,
    camera: Camera,
    sun: [f32; 3],
) -> Vec<u8> {
    let mut options = common::options(64, 64, 1);
    options.light.sun_dir = sun;
    let mut renderer =
        Renderer::with_world(gpu, data, MethodKind::Brute, options, None, lattice).unwrap();
    let mut sink = CollectSink::default();
    renderer
        .render(FrameRequest::from(camera), &mut sink)
        .unwrap();
    renderer.finish(&mut sink).unwrap();
    sink.frames.pop().expect("a frame").rgba
}

// ---- Tests ---------------------------------------------------------------------------------

/// Slopes (per stated metre along columns and rows) the tests put under the probed samples.
const SLOPES: [[f64; 2]; 6] = [
    [0.0, 0.0],
    [1.0, 0.0],
    [0.0, 1.0],
    [-0.6, 0.8],
    [2.0, -1.5],
    [0.3, 0.05],
];

/// Bakes the normals of `grid` through its lattice and compares them with the oracles at the
/// samples `rows` x `cols` (each under its own slope of [`SLOPES`]: the heights around it rise
/// at that slope per stated metre, zero elsewhere). Returns the worst angle of the unquantized
/// normals (`normal_at`) from the exact (chord) oracle, from the tangent-plane oracle with the
/// bound on their difference (the chords' stretch by `(R + h) / R`: at most `h / R` for the
/// largest height `h`), and the controls' (the unrotated normal 50+ km out: smallest; a
/// rotation keeping the stated spacing on the 10 edge rows: largest; north flipped: smallest).
/// Checks the normal map itself (`Heightmap::normals_snorm8`) against them within its 8-bit
/// quantization.
fn baked_against_geodesy(grid: &Grid, rows: &[usize], cols: &[usize]) -> [f64; 6] {
    let lattice = grid.lattice();
    let (w, h) = (grid.cols as usize, grid.rows as usize);
    let stated = grid.stated_spacing();
    let mut heights = vec![0f32; w * h];
    let mut cases = Vec::new();
    for (k, (&row, &col)) in rows
        .iter()
        .flat_map(|r| cols.iter().map(move |c| (r, c)))
        .enumerate()
    {
        let slope = SLOPES[k % SLOPES.len()];
        for r in row.saturating_sub(1)..(row + 2).min(h) {
            for c in col.saturating_sub(1)..(col + 2).min(w) {
                let dx = (c as f64 - col as f64) * stated[0];
                let dy = (r as f64 - row as f64) * stated[1];
                heights[r * w + c] = (slope[0] * dx + slope[1] * dy) as f32;
            }
        }
        cases.push(((col, row), grid_normal(slope)));
    }
    let data = grid.heightmap_of(heights, 200);
    let position =
        |c: usize, r: usize, height: f64| lattice.position(DVec2::new(c as f64, r as f64), height);
    let axes = NormalAxes::World(&position);
    let sample = |c: usize, r: usize| data.sample(c as u32, r as u32) as f64;
    let baked = data.normals_snorm8(Some(&lattice));
    let (mut worst, mut unrotated, mut stated_control, mut flipped) =
        (0.0f64, f64::MAX, 0.0f64, f64::MAX);
    let mut worst_plane = 0.0f64;
    let highest = data
        .heights
        .iter()
        .fold(0f64, |m, &v| m.max(v.abs() as f64));
    let stretch_bound = highest / 6.3e6;
    let mut worst_quantized = 0.0f64;
    let edge = (h - 1) - 10;
    for &((c, r), n) in &cases {
        let s = DVec2::new(c as f64, r as f64);
        let want = grid.world_normal(s, n);
        let got = normal_at(w, h, &axes, sample, c, r);
        worst = worst.max(angle(got, grid.chord_normal(c, r, sample)));
        worst_plane = worst_plane.max(angle(got, want));
        let t = &baked[(r * w + c) * 4..][..3];
        let decoded = DVec3::new(t[0] as i8 as f64, t[1] as i8 as f64, t[2] as i8 as f64) / 127.0;
        worst_quantized = worst_quantized.max(angle(decoded, got));
        let (lat, lon) = grid.lat_lon(s);
        let [east, north, up] = local_axes_in_world(grid.lat0, grid.lon0, lat, lon);
        if lattice.position(s, 0.0).length() > 50e3 {
            unrotated = unrotated.min(angle(n, want));
        }
        if r < 10 || r > edge {
            stated_control = stated_control.max(angle(n.x * east + n.y * north + n.z * up, want));
        }
        if n.y.abs() > 0.1 {
            flipped = flipped.min(angle(n.x * east - n.y * north + n.z * up, want));
        }
    }
    // An 8-bit snorm normal is within half a step per component of the normal it encodes.
    let half_step = 0.5 / 127.0 * 3f64.sqrt();
    assert!(
        worst_quantized < half_step,
        "the normal map is {worst_quantized} rad off its normals"
    );
    println!(
        "{} samples: worst {worst:.2e} rad (tangent plane {worst_plane:.2e}, stretch bound {stretch_bound:.1e}; normal map within {worst_quantized:.1e}); \
         controls: unrotated >= {unrotated:.2e}, stated spacing up to {stated_control:.2e}, \
         flipped >= {flipped:.2e}",
        cases.len()
    );
    // The flat world: the grid's own normals (to the f32 heights' rounding).
    let grid_axes = NormalAxes::Grid(stated);
    for &((c, r), n) in &cases {
        let got = normal_at(w, h, &grid_axes, sample, c, r);
        assert!(angle(got, n) < 1e-6, "flat world at {c},{r}");
    }
    [
        worst,
        worst_plane,
        stretch_bound,
        unrotated,
        stated_control,
        flipped,
    ]
}

#[test]
fn world_normals_follow_the_local_frame_and_metric_on_a_geographic_grid() {
    let tolerance = 1e-4;
    // 0.5 x 1 degree at 60 N, 3" samples (46 x 93 m): the far rows lie 111 km north of the
    // world origin (the up vector tilted by 1 degree), the stated east-west spacing (at
    // 60.5 N) is 1.5 % off at the south and north edges. Then 16 x 4 degrees at 45 N of 30"
    // samples.
    let cases = [
        (
            Grid {
                lat0: 60.0,
                lon0: 10.0,
                d: 1.0 / 1200.0,
                cols: 601,
                rows: 1201,
            },
            vec![0, 4, 451, 600, 874, 1196, 1200],
            vec![0, 3, 300, 413, 600],
        ),
        (
            Grid {
                lat0: 45.0,
                lon0: -3.0,
                d: 1.0 / 120.0,
                cols: 1921,
                rows: 481,
            },
            vec![0, 4, 240, 476, 480],
            vec![0, 4, 960, 1500, 1920],
        ),
    ];
    for (grid, rows, cols) in cases {
        let [worst, plane, stretch, unrotated, stated, flipped] =
            baked_against_geodesy(&grid, &rows, &cols);
        assert!(worst < tolerance, "world normal off by {worst} rad");
        assert!(
            plane < tolerance + stretch,
            "{plane} from the tangent plane's (stretch {stretch})"
        );
        assert!(unrotated > 20.0 * tolerance, "{unrotated}");
        assert!(stated > 20.0 * tolerance, "{stated}");
        assert!(flipped > 100.0 * tolerance, "{flipped}");
    }
}

/// Renders flat sea-level terrain on `grid` seen straight down from 2,000 m over sample
/// `under` under a sun 10 degrees above the world's northern horizon; returns the expected
/// colour (lit by the local vertical), the unrotated normal's colour, the worst of the middle
/// 16 x 16 pixels' differences from the expected one.
fn low_sun_render(gpu: &Arc<Gpu>, grid: &Grid, under: DVec2) -> (u8, u8, i32) {
    let lattice = grid.lattice();
    let albedo = 200u8;
    let data = grid.heightmap(0.0, albedo);
    let camera = Camera {
        position: lattice.position(under, 2000.0),
        pitch_deg: -90.0,
        vfov_deg: 20.0,
        far: 1e6,
        ..Camera::default()
    };
    let el = 10f64.to_radians();
    let sun = DVec3::new(0.0, el.cos(), el.sin());
    let rgba = render(gpu, &data, Some(&lattice), camera, sun.as_vec3().to_array());
    // The expected colour: albedo x (ambient + diffuse * max(n . sun, 0)), sRGB-encoded.
    let lin = |c: u8| {
        let s = c as f64 / 255.0;
        if s <= 0.04045 {
            s / 12.92
        } else {
            ((s + 0.055) / 1.055).powf(2.4)
        }
    };
    let lit = |n: DVec3| {
        let light = vkterrain::gpu_constants::LIGHT_AMBIENT as f64
            + vkterrain::gpu_constants::LIGHT_DIFFUSE as f64 * n.dot(sun).max(0.0);
        common::srgb8((lin(albedo) * light) as f32)
    };
    let (lat, lon) = grid.lat_lon(under);
    let up = local_axes_in_world(grid.lat0, grid.lon0, lat, lon)[2];
    let (want, unrotated) = (lit(up), lit(DVec3::Z));
    // The middle 16 x 16 pixels (the ground within ~100 m of `under`).
    let mut worst = 0;
    for y in 24..40 {
        for x in 24..40 {
            let p = rgba[(y * 64 + x) * 4] as i32;
            worst = worst.max((p - want as i32).abs());
        }
    }
    (want, unrotated, worst)
}

#[test]
fn a_low_sun_lights_far_terrain_by_its_own_vertical() {
    let gpu = common::gpu(false);
    // Seen 450 km north of the world origin, where the vertical is tilted 4 degrees towards
    // the north: 0.25 x 5 degrees north from 40 N at 30" (926 m); 16 x 4 degrees from 40 N at
    // 30", seen 3.9 degrees north of its origin.
    let cases = [
        (
            Grid {
                lat0: 40.0,
                lon0: 5.0,
                d: 1.0 / 120.0,
                cols: 31,
                rows: 601,
            },
            DVec2::new(15.0, 486.0),
        ),
        (
            Grid {
                lat0: 40.0,
                lon0: 5.0,
                d: 1.0 / 120.0,
                cols: 1921,
                rows: 481,
            },
            DVec2::new(15.0, 470.0),
        ),
    ];
    for (grid, under) in cases {
        let (want, unrotated, worst) = low_sun_render(&gpu, &grid, under);
        println!(
            "{} x {}: expected {want} (unrotated {unrotated}), worst pixel off by {worst}",
            grid.cols, grid.rows
        );
        assert!(
            want as i32 - unrotated as i32 >= 5,
            "{want} vs {unrotated}: no contrast"
        );
        assert!(
            worst <= 1,
            "pixels off by {worst} from {want} (unrotated: {unrotated})"
        );
    }
    common::assert_no_validation_messages(&gpu);
}

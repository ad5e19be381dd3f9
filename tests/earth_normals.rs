//! The normal map on the earth (docs/coordinates.md, "Normals on the earth"): every method
//! shades with `world_normal` (shaders/include/terrain_common.wgsl), which takes the normal
//! map's grid-frame normal into world axes through the geolocation lattice. Probed on the GPU
//! and compared with the terrain's normal from independent f64 geodesy written out here (the
//! local east/north/up at the sample's latitude/longitude, the true metres per sample there);
//! a rendered image under a low sun is lit by the local vertical, not the world's. Negative
//! controls: the unrotated normal, a rotation that keeps the stated spacing, and a flipped
//! north axis all miss by more than the tolerance; the flat world keeps the normal as it is.

mod common;

use std::sync::Arc;

use glam::{DVec2, DVec3};
use vkterrain::dataset::{Albedo, Heightmap};
use vkterrain::driver::Gpu;
use vkterrain::frame::NormalPath;
use vkterrain::geo::Lattice;
use vkterrain::geo::normal_model::NormalModel;
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
        let mut map = Heightmap::new(
            "geographic",
            self.cols,
            self.rows,
            self.stated_spacing()[1],
            vec![h; n],
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

    /// The oracle: the world-axes normal of terrain at `s` whose normal map holds `n` (slopes
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
) -> (Renderer, Vec<u8>) {
    let mut options = common::options(64, 64, 1);
    options.light.sun_dir = sun;
    let mut renderer =
        Renderer::with_world(gpu, data, MethodKind::Brute, options, None, lattice).unwrap();
    let mut sink = CollectSink::default();
    renderer
        .render(FrameRequest::from(camera), &mut sink)
        .unwrap();
    renderer.finish(&mut sink).unwrap();
    let rgba = sink.frames.pop().expect("a frame").rgba;
    (renderer, rgba)
}

// ---- Tests ---------------------------------------------------------------------------------

/// Probes `world_normal` on `grid` at sample positions `rows` x `cols` with six slopes and
/// compares it with the oracle; returns the worst angle and the controls' (the unrotated
/// normal 50+ km out: smallest; a rotation keeping the stated spacing on the 10 edge rows:
/// largest; north flipped: smallest), and which frame the shader took (true: the quadratic normal model).
fn probe_against_geodesy(
    gpu: &Arc<Gpu>,
    grid: &Grid,
    rows: &[f64],
    cols: &[f64],
) -> ([f64; 4], bool) {
    let lattice = grid.lattice();
    let data = grid.heightmap(0.0, 200);
    let camera = Camera {
        position: lattice.position(DVec2::new(cols[0], rows[0]), 3000.0),
        pitch_deg: -90.0,
        far: 1e6,
        ..Camera::default()
    };
    let (renderer, _) = render(gpu, &data, Some(&lattice), camera, [0.0, 0.0, 1.0]);
    let slopes = [
        [0.0, 0.0],
        [1.0, 0.0],
        [0.0, 1.0],
        [-0.6, 0.8],
        [2.0, -1.5],
        [0.3, 0.05],
    ];
    let mut cases = Vec::new();
    for &row in rows {
        for &col in cols {
            for slope in slopes {
                cases.push((DVec2::new(col, row), grid_normal(slope)));
            }
        }
    }
    let points: Vec<([f32; 2], [f32; 3])> = cases
        .iter()
        .map(|(s, n)| (s.as_vec2().to_array(), n.as_vec3().to_array()))
        .collect();
    let got = renderer.probe_world_normals(0, &points).unwrap();
    let modelled = renderer.terrain().normal_model.is_some();
    // The CPU twins of the shader's normals (`NormalModel::normal`, `Lattice::grid_frame` with
    // the cofactor written out here): the GPU must equal them to f32 rounding.
    let stated_spacing = grid.stated_spacing();
    let (model, _) = NormalModel::fit(&lattice, grid.cols, grid.rows, stated_spacing);
    let last = DVec2::new((grid.cols - 1) as f64, (grid.rows - 1) as f64);
    let twin = |s: DVec2, n: DVec3| {
        if modelled {
            return model.normal(s / last, n).normalize();
        }
        let [u, tx, ty] = lattice.grid_frame(s);
        (n.x * stated_spacing[0] * ty.cross(u)
            + n.y * stated_spacing[1] * u.cross(tx)
            + n.z * tx.cross(ty))
        .normalize()
    };
    let mut worst_twin = 0.0f64;
    let (mut worst, mut unrotated, mut stated, mut flipped) = (0.0f64, f64::MAX, 0.0f64, f64::MAX);
    let edge = (grid.rows - 1) as f64 - 10.0;
    for ((s, n), g) in cases.iter().zip(&got) {
        let want = grid.world_normal(*s, *n);
        let g = DVec3::from(g.map(|v| v as f64));
        assert!((g.length() - 1.0).abs() < 1e-5, "{s}: |n| = {}", g.length());
        worst = worst.max(angle(g, want));
        worst_twin = worst_twin.max(angle(g, twin(*s, *n)));
        let (lat, lon) = grid.lat_lon(*s);
        let [east, north, up] = local_axes_in_world(grid.lat0, grid.lon0, lat, lon);
        if lattice.position(*s, 0.0).length() > 50e3 {
            unrotated = unrotated.min(angle(*n, want));
        }
        if s.y < 10.0 || s.y > edge {
            stated = stated.max(angle(n.x * east + n.y * north + n.z * up, want));
        }
        if n.y.abs() > 0.1 {
            flipped = flipped.min(angle(n.x * east - n.y * north + n.z * up, want));
        }
    }
    assert!(
        worst_twin < 2e-6,
        "GPU off its CPU twin by {worst_twin} rad"
    );
    println!(
        "{} points: worst {worst:.2e} rad (CPU twin {worst_twin:.1e}); controls: unrotated >= {unrotated:.2e}, stated \
         spacing up to {stated:.2e}, flipped >= {flipped:.2e}",
        cases.len()
    );
    drop(renderer);

    // The flat world keeps the grid-frame normal bit for bit.
    let flat_camera = Camera {
        position: DVec3::new(10e3, 50e3, 3000.0),
        pitch_deg: -90.0,
        far: 1e6,
        ..Camera::default()
    };
    let (flat, _) = render(gpu, &data, None, flat_camera, [0.0, 0.0, 1.0]);
    let got = flat.probe_world_normals(0, &points).unwrap();
    for ((_, n), g) in points.iter().zip(&got) {
        assert_eq!(n, g);
    }
    ([worst, unrotated, stated, flipped], modelled)
}

#[test]
fn world_normals_follow_the_local_frame_and_metric_on_a_geographic_grid() {
    let gpu = common::gpu(false);
    let tolerance = 1e-4;
    // 0.5 x 1 degree at 60 N, 3" samples (46 x 93 m): lattice nodes every 5 samples; the far
    // rows lie 111 km north of the world origin (the up vector tilted by 1 degree), the stated
    // east-west spacing (at 60.5 N) is 1.5 % off at the south and north edges. The normal
    // model holds here. Then 16 x 4 degrees at 45 N of 30" samples: the parallels bend too far
    // for one quadratic over the grid (6.7e-4 rad), so the lattice is read.
    let cases = [
        (
            Grid {
                lat0: 60.0,
                lon0: 10.0,
                d: 1.0 / 1200.0,
                cols: 601,
                rows: 1201,
            },
            vec![0.0, 3.4, 451.0, 600.0, 873.7, 1199.2, 1200.0],
            vec![0.0, 2.5, 300.0, 412.9, 600.0],
            true,
        ),
        (
            Grid {
                lat0: 45.0,
                lon0: -3.0,
                d: 1.0 / 120.0,
                cols: 1921,
                rows: 481,
            },
            vec![0.0, 0.5, 240.3, 479.9, 480.0],
            vec![0.0, 1.7, 960.0, 1500.5, 1920.0],
            false,
        ),
    ];
    for (grid, rows, cols, model) in cases {
        let ([worst, unrotated, stated, flipped], modelled) =
            probe_against_geodesy(&gpu, &grid, &rows, &cols);
        assert_eq!(modelled, model, "normal model at {} N", grid.lat0);
        assert!(worst < tolerance, "world normal off by {worst} rad");
        assert!(unrotated > 20.0 * tolerance, "{unrotated}");
        assert!(stated > 20.0 * tolerance, "{stated}");
        assert!(flipped > 100.0 * tolerance, "{flipped}");
    }
    common::assert_no_validation_messages(&gpu);
}

/// Renders flat sea-level terrain on `grid` seen straight down from 2,000 m over sample
/// `under` under a sun 10 degrees above the world's northern horizon; returns the expected
/// colour (lit by the local vertical), the unrotated normal's colour, the worst of the middle
/// 16 x 16 pixels' differences from the expected one, and the drawing shaders' normal path.
fn low_sun_render(gpu: &Arc<Gpu>, grid: &Grid, under: DVec2) -> (u8, u8, i32, NormalPath) {
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
    let (renderer, rgba) = render(gpu, &data, Some(&lattice), camera, sun.as_vec3().to_array());
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
    (want, unrotated, worst, renderer.terrain().normal_path())
}

#[test]
fn a_low_sun_lights_far_terrain_by_its_own_vertical() {
    let gpu = common::gpu(false);
    // Seen 450 km north of the world origin, where the vertical is tilted 4 degrees towards
    // the north: 0.25 x 5 degrees north from 40 N at 30" (926 m), drawn with the normal model;
    // 16 x 4 degrees from 40 N at 30", too wide for the model (the lattice), seen 3.9 degrees
    // north of its origin. Each drawing pipeline compiles only its own path (`NormalPath`).
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
            NormalPath::Model,
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
            NormalPath::Lattice,
        ),
    ];
    for (grid, under, path) in cases {
        let (want, unrotated, worst, got_path) = low_sun_render(&gpu, &grid, under);
        println!("{path:?}: expected {want} (unrotated {unrotated}), worst pixel off by {worst}");
        assert_eq!(got_path, path);
        assert!(
            want as i32 - unrotated as i32 >= 5,
            "{want} vs {unrotated}: no contrast"
        );
        assert!(
            worst <= 1,
            "{path:?}: pixels off by {worst} from {want} (unrotated: {unrotated})"
        );
    }
    common::assert_no_validation_messages(&gpu);
}

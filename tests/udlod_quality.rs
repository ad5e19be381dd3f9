//! UDLOD quality against the exact surface (validation on): the screen-space geometric error
//! stays within the pixel target, the surface does not pop while the LOD viewer moves (and
//! does without morphing), the per-region error field saves triangles without breaking the
//! bound, and a camera 100 km from the origin sees a stable, watertight surface.
//! Errors are measured with `vkterrain::eval::metrics` (definitions in docs/metrics.md).

mod common;

use glam::DVec3;
use vkterrain::dataset::Heightmap;
use vkterrain::dataset::procedural::{self, ProceduralParams};
use vkterrain::eval::metrics::{self, GeometricError, PixelError};
use vkterrain::lod::udlod::field::{FieldKey, SplitField};
use vkterrain::lod::udlod::levels::Levels;
use vkterrain::lod::udlod::settings::BackFaces;
use vkterrain::lod::{MethodKind, UdlodSettings};
use vkterrain::readback::OwnedFrame;
use vkterrain::render::FrameRequest;
use vkterrain::scene::Camera;

const W: u32 = 240;
const H: u32 = 150;

/// Rough terrain (features of 1.5 km on 7.7 km): the pixel target, not the crack-free chain,
/// decides the split distances here, so the error bound is actually exercised.
fn terrain() -> Heightmap {
    procedural::generate(&ProceduralParams {
        size: 257,
        spacing: 30.0,
        feature_size: 1500.0,
        ..Default::default()
    })
    .unwrap()
}

/// Rough in the east, a gentle plain in the west (heights scaled down by 50 there, with a
/// smooth transition): where a per-region error field should pay.
fn half_flat_terrain() -> Heightmap {
    let rough = terrain();
    let w = rough.width;
    let heights = (0..rough.height)
        .flat_map(|r| (0..w).map(move |c| (c, r)))
        .map(|(c, r)| {
            let t = ((c as f64 / (w - 1) as f64 - 0.4) / 0.2).clamp(0.0, 1.0);
            let scale = 0.02 + 0.98 * t * t * (3.0 - 2.0 * t);
            (rough.sample(c, r) as f64 * scale) as f32
        })
        .collect();
    Heightmap::new("half flat", w, rough.height, rough.spacing, heights).unwrap()
}

fn lod(grid_size: u32, tau_px: f64, morph: bool, error_field_max: f64) -> UdlodSettings {
    UdlodSettings {
        grid_size,
        tau_px,
        morph,
        error_field_max,
        ..UdlodSettings::default()
    }
}

fn render(
    data: &Heightmap,
    method: MethodKind,
    lod: UdlodSettings,
    requests: &[FrameRequest],
) -> Vec<OwnedFrame> {
    let gpu = common::gpu(false);
    let options = common::options(W, H, 2);
    common::render_method(
        &gpu,
        data,
        common::method_with(method, lod),
        options,
        requests,
    )
}

fn errors(frame: &OwnedFrame, data: &Heightmap) -> Vec<PixelError> {
    metrics::pixel_errors(
        &frame.camera,
        frame.width,
        frame.height,
        frame.depth.as_ref().expect("depth read back"),
        data,
    )
}

/// Poses that look at terrain from ordinary flight heights and pitches (no camera inside the
/// ground), deterministic.
fn flight_poses(data: &Heightmap, n: usize) -> Vec<Camera> {
    let (ex, ey) = data.extent();
    (0..n)
        .map(|i| {
            let f = i as f64 / n as f64;
            let (x, y) = (
                (0.15 + 0.7 * (f * 7.31).fract()) * ex,
                (0.15 + 0.7 * (f * 3.17 + 0.13).fract()) * ey,
            );
            let ground = data.height_at(x, y);
            Camera {
                position: DVec3::new(x, y, ground + 30.0 + 1500.0 * (f * 5.3).fract()),
                yaw_deg: 360.0 * (f * 11.7).fract(),
                pitch_deg: -8.0 - 70.0 * (f * 2.9).fract(),
                near: 0.5,
                ..Camera::default()
            }
        })
        .collect()
}

/// The rendered surface's screen-space error stays within tau (+ tolerance) at the 99.9th
/// percentile over 40 poses, and within 2 tau at its worst pixel, for tau = 1 and 4, with the
/// error field on; brute force measures
/// ~0 (the metric's own noise), and tau = 4 shows errors above 1 px (the metric can fail).
#[test]
fn screen_space_error_is_within_tau() {
    for grid in common::udlod_grids() {
        screen_space_error_is_within_tau_at(grid);
    }
}

fn screen_space_error_is_within_tau_at(grid: u32) {
    let data = terrain();
    let poses = flight_poses(&data, 40);
    let requests: Vec<FrameRequest> = poses.iter().map(|&c| c.into()).collect();
    let summary = |frames: &[OwnedFrame]| {
        let all: Vec<PixelError> = frames.iter().flat_map(|f| errors(f, &data)).collect();
        GeometricError::of(&all)
    };
    let brute = summary(&render(
        &data,
        MethodKind::Brute,
        lod(grid, 1.0, true, 8.0),
        &requests,
    ));
    println!("brute: {brute:?}");
    assert!(brute.pixels.count > 40 * W as usize * H as usize / 3);
    // The metric's noise on the exact mesh (depth precision, a few rasterization outliers).
    assert!(
        brute.pixels.p999 < 0.01,
        "reference error should be ~0: {brute:?}"
    );
    // Tolerance: 25% of tau. The bound is exact at the mesh vertices; the distance is taken
    // at the reference height (terrain under the viewer), so terrain rising towards the
    // camera is slightly nearer than the selection assumed, and morphing blends two levels.
    let tolerance = 1.25;
    for tau in [1.0, 4.0] {
        let udlod = summary(&render(
            &data,
            MethodKind::Udlod,
            lod(grid, tau, true, UdlodSettings::default().error_field_max),
            &requests,
        ));
        println!("grid {grid}, udlod tau {tau}: {udlod:?}");
        assert!(
            udlod.pixels.p999 <= tau * tolerance,
            "grid {grid}, tau {tau}: 99.9th percentile {} px",
            udlod.pixels.p999
        );
        // The worst pixel too: a fold of the morph (triangles turned over where the factor
        // jumped between neighbouring vertices, docs/udlod-rounds.md "The morph cascade") showed as
        // single pixels 5-10 tau off, or far more. Measured: 1.30-1.54 tau.
        assert!(
            udlod.pixels.max <= 2.0 * tau,
            "grid {grid}, tau {tau}: worst pixel {} px",
            udlod.pixels.max
        );
        if tau == 4.0 {
            assert!(
                udlod.pixels.p999 > 1.0,
                "tau 4 should exceed 1 px somewhere: {udlod:?}"
            );
        }
    }
}

/// The error field keeps fewer triangles than the distance-only selection on terrain that
/// mixes rough and smooth regions, and the bound still holds (previous test); selection
/// structure is checked with the field on by tests/udlod.rs.
#[test]
fn error_field_saves_triangles() {
    for grid in common::udlod_grids() {
        error_field_saves_triangles_at(grid);
    }
}

fn error_field_saves_triangles_at(grid: u32) {
    let data = half_flat_terrain();
    let poses = flight_poses(&data, 12);
    let requests: Vec<FrameRequest> = poses.iter().map(|&c| c.into()).collect();
    let tris = |field: f64| -> u64 {
        render(
            &data,
            MethodKind::Udlod,
            lod(grid, 1.0, true, field),
            &requests,
        )
        .iter()
        .map(|f| f.triangles)
        .sum()
    };
    let (distance_only, with_field) = (tris(1.0), tris(UdlodSettings::default().error_field_max));
    println!("grid {grid}, triangles: distance-only {distance_only}, error field {with_field}");
    assert!(
        (with_field as f64) < 0.9 * distance_only as f64,
        "field {with_field} vs distance-only {distance_only}"
    );
}

/// World points of a frame's terrain pixels (`None`: sky).
fn world_points(frame: &OwnedFrame) -> Vec<Option<DVec3>> {
    let depth = frame.depth.as_ref().expect("depth read back");
    (0..frame.height)
        .flat_map(|y| (0..frame.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let d = depth[(y * frame.width + x) as usize];
            (d > 0.0)
                .then(|| metrics::world_point(&frame.camera, x, y, frame.width, frame.height, d))
        })
        .collect()
}

/// The least sine of the angle between a measured pixel's ray and its surface
/// ([`largest_pop`]): the grazing hit described there met its facet at 0.15; the controls'
/// pops (no morphing) are seen at about 0.5.
const GRAZING: f64 = 0.2;

/// Popping: the LOD viewer flies slowly (`step` metres per frame); every frame is rendered
/// twice from the same camera, with the LOD viewer at its previous and at its new position, so
/// the two depth buffers differ only by the surface's change. Per pixel, the vertical
/// displacement of the surface is `((P_new - P_old) . n) / n.z` with `n` the old surface's
/// normal from neighbouring pixels (first order, robust at grazing angles), projected to
/// pixels at the point's distance. Pixels at depth discontinuities (occlusion edges, where a
/// ray moves from one ridge to another) are skipped, and so are pixels whose ray meets the
/// surface at a grazing angle ([`GRAZING`]): there the hit jumps across a crest in front when
/// the crest rises a little, and the first-order estimate reads that as a large move (found
/// with a CPU ray cast through both morphed meshes: a vertex rising 0.09 m moved a grazing
/// hit 44 m nearer, read as 7.8 m, 0.51 px; the morphing maxima of 0.46-0.67 px this test
/// reported before were all at grazing pixels). Returns the largest change over the flight.
fn largest_pop(
    data: &Heightmap,
    settings: UdlodSettings,
    start: DVec3,
    step: DVec3,
    frames: usize,
) -> f64 {
    let viewer = |k: usize| {
        let p = start + step * k as f64;
        DVec3::new(p.x, p.y, data.height_at(start.x, start.y) + start.z)
    };
    let mut requests = Vec::new();
    for k in 1..=frames {
        let camera = Camera {
            position: viewer(k),
            yaw_deg: step.y.atan2(step.x).to_degrees(),
            pitch_deg: -30.0,
            near: 0.5,
            ..Camera::default()
        };
        for lod_viewer in [viewer(k - 1), viewer(k)] {
            requests.push(FrameRequest {
                camera,
                sky: None,
                lod_viewer: Some(lod_viewer),
            });
        }
    }
    let out = render(data, MethodKind::Udlod, settings, &requests);
    let (w, h) = (W as usize, H as usize);
    let mut largest = 0.0f64;
    for pair in out.chunks(2) {
        let (a, b) = (world_points(&pair[0]), world_points(&pair[1]));
        let eye = pair[0].camera.position;
        let focal = pair[0].camera.focal_px(H);
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let at = |v: &Vec<Option<DVec3>>, dx: isize, dy: isize| {
                    v[(y as isize + dy) as usize * w + (x as isize + dx) as usize]
                };
                let (Some(pa), Some(pb)) = (at(&a, 0, 0), at(&b, 0, 0)) else {
                    continue;
                };
                let dist = (pa - eye).length();
                let neighbours = [(-1, 0), (1, 0), (0, -1), (0, 1)];
                let smooth = [&a, &b].iter().all(|v| {
                    neighbours.iter().all(|&(dx, dy)| {
                        at(v, dx, dy)
                            .is_some_and(|q| ((q - eye).length() - dist).abs() < 0.05 * dist)
                    })
                });
                if !smooth {
                    continue;
                }
                let n = (at(&a, 1, 0).unwrap() - at(&a, -1, 0).unwrap())
                    .cross(at(&a, 0, 1).unwrap() - at(&a, 0, -1).unwrap())
                    .normalize();
                if n.z.abs() < 0.2 {
                    continue; // a near-vertical facet: vertical displacement is ill-defined
                }
                if ((pa - eye) / dist).dot(n).abs() < GRAZING {
                    continue; // the ray grazes the surface: its hit jumps across crests
                }
                let vertical = (pb - pa).dot(n) / n.z;
                largest = largest.max(vertical.abs() * focal / dist);
            }
        }
    }
    largest
}

/// Largest change per frame of the LOD viewer's distance to any point at the reference
/// height: its horizontal step plus the change of its height above the terrain under it.
fn effective_step(data: &Heightmap, start: DVec3, step: DVec3, frames: usize) -> f64 {
    let ground = |p: DVec3| data.height_at(p.x, p.y);
    (0..frames)
        .map(|k| {
            let (p, q) = (start + step * k as f64, start + step * (k + 1) as f64);
            step.length() + (ground(q) - ground(p)).abs()
        })
        .fold(0.0, f64::max)
}

/// The bound, for the distance-only selection (field of ones). One level step first: a step
/// `s` of the LOD viewer (horizontal step plus the change of its height above the reference
/// terrain) changes a point's distance by at most `s`, so the morph factor of a vertex of a
/// level-`l` tile by at most `s / w[l + 1]`, `w[l + 1]` the width of level `l + 1`'s morph
/// zone: `r * D[l + 1]` with one level step, `max(W[l + 1], r * D[l + 1])` with the cascade
/// (`SplitField::zone`). A full morph slides an odd vertex onto its lower even neighbour with
/// its height re-sampled: `2^l` samples along a grid line, or, where both of its grid
/// coordinates are odd, `2^l` samples along both axes at once (the diagonal). The surface
/// over a fixed point moves by the vertex's own height change plus the triangle's slope times
/// its horizontal slide, each at most `S * spacing` per sample slid per axis (`S`: the data's
/// steepest slope between neighbouring samples; a triangle's plane rises at most `S` along
/// each axis): `4 * S * spacing` per sample of a diagonal slide (the bound before issue 18's
/// third round counted axis slides only, `2 * S`, and grid 4 measured 1.4x that bound). The
/// point is in its morph zone, at least `D[l + 1] - w[l + 1]` away, so the per-frame change
/// of the error image is at most `4 * S * spacing * slide * focal / (D[l + 1] - w[l + 1])`
/// pixels, `slide = s * 2^l / w[l + 1]` samples per axis.
///
/// The cascade (`morph::morph_cascade`): the walk's points `p_0, p_1, ...` (levels
/// `j_0 < j_1 < ...`, at most `morph_levels` of them from the tile's level) with factors
/// `f_k` end at `x_0 = p_0 + f_0 d_0 + f_0 f_1 d_1 + ...`, `d_k = p_{k+1} - p_k` (`2^{j_k}`
/// samples per axis), so a change of `f_k` moves the vertex by its own slide plus every later
/// one weighted by their factors (`lever_k = 2^{j_k} + f_{k+1} 2^{j_{k+1}} + f_{k+1} f_{k+2}
/// 2^{j_{k+2}} + ...`). Over a field of ones the zones of successive levels can overlap
/// where the reach, not the pixel term, sets the distances (here at grid 4 level 4's factor
/// reaches 0.41 while level 3's moves), so several factors move at once. Taking `m` as the
/// lowest level whose factor moves, its point is nearer than `D[m + 1]` and every later point
/// at most the slides in between further, so
/// a later level `j` has a factor of at most `phi_j = clamp(1 - (D[j + 1] - D[m + 1] -
/// slides) / w[j + 1])`; the slide per frame is `sum_j s / w[j + 1] * lever_j` over the levels
/// with `phi_j > 0`, each lever weighted by the `phi`s. With one level step (or zones apart)
/// every later `phi` is 0 and this is the bound above. Without morphing a level switch moves
/// the surface by a level's whole error at once.
fn pop_bound(data: &Heightmap, settings: &UdlodSettings, step: f64) -> f64 {
    let levels = Levels::for_settings(data, settings).unwrap();
    let focal = Camera::default().focal_px(H);
    let field = SplitField::new(&levels, FieldKey::new(settings, focal));
    let mut slope = 0.0f64;
    for r in 0..data.height - 1 {
        for c in 0..data.width - 1 {
            let h = data.sample(c, r);
            slope = slope
                .max((data.sample(c + 1, r) - h).abs() as f64 / data.spacing)
                .max((data.sample(c, r + 1) - h).abs() as f64 / data.spacing);
        }
    }
    let r = settings.morph_range;
    let top = levels.root_lod as usize;
    // Level `j`'s factor: split distance `D[j + 1]` and zone width.
    let split = |j: usize| field.split[j + 1] as f64;
    let width = |j: usize| (field.zone[j + 1] as f64).max(r * split(j));
    let samples = |j: usize| (1u64 << j) as f64;
    let walk = settings.morph_levels() as usize;
    (0..top)
        .map(|m| {
            let last = (m + walk).min(top);
            // The largest factor each level of the walk can have while level m's moves.
            let phi: Vec<f64> = (m..last)
                .map(|j| {
                    let slides =
                        std::f64::consts::SQRT_2 * (samples(j) - samples(m)) * data.spacing;
                    (1.0 - (split(j) - split(m) - slides) / width(j)).clamp(0.0, 1.0)
                })
                .collect();
            let lever = |k: usize| {
                let (mut sum, mut weight) = (0.0, 1.0);
                for (i, j) in (m + k..last).enumerate() {
                    if i > 0 {
                        weight *= phi[j - m];
                    }
                    sum += weight * samples(j);
                }
                sum
            };
            let slide: f64 = (m..last)
                .filter(|&j| phi[j - m] > 0.0)
                .map(|j| step / width(j) * lever(j - m))
                .sum();
            4.0 * slope * data.spacing * slide * focal / (split(m) - width(m))
        })
        .fold(0.0, f64::max)
}

/// The bound above is derived for the field of ones (`error_field_max = 1`). The default
/// split field (cap 1024) lets a smooth tile keep its level up to `m` times nearer, which
/// multiplies the distance's pace through a zone and divides the distance by `m` (a factor
/// `m^2` in the bound, which is then far too loose to test against: the surface moves little
/// where `m` is large, but the slope-based bound does not see that). So the default is held
/// to the field of ones' number as a guard, not a derived bound: measured 0.08-0.35 px against
/// 0.35-0.47 px (x 1.5 tolerance), and without morphing it pops 1.23-1.49 px (the control).
#[test]
fn no_popping_along_a_slow_flight_and_popping_without_morphing() {
    // Both morph variants: one level step (`morph_levels = 1`) and the cascade (0); the
    // field of ones and the default split field.
    let default_field = UdlodSettings::default().error_field_max;
    // The cascade with two field nodes per tile side (`field_density = 2`) too. Not with one
    // level step: there grid 8 without morphing pops only 0.475 px on this flight, under 1.5 x
    // its 0.475 px bound, too weak a control.
    let measured: Vec<_> = common::udlod_grids()
        .into_iter()
        .flat_map(|grid| [1, 0].map(|levels| (grid, levels)))
        .flat_map(|(grid, levels)| [1.0, default_field].map(|field| (grid, levels, field, 1)))
        .chain(
            common::udlod_grids()
                .into_iter()
                .map(|g| (g, 0, default_field, 2)),
        )
        .map(|(grid, levels, field, d)| (grid, levels, popping_at(grid, levels, field, d)))
        .collect();
    for (grid, levels, (pop_on, pop_off, bound)) in measured {
        // Tolerance 1.5: the measurement is first order (a plane through neighbouring pixels),
        // so a hit that slides across a triangle kink reads a little more than the surface
        // moved.
        let bound = 1.5 * bound;
        assert!(
            pop_on <= bound,
            "grid {grid}, morph_levels {levels}, morphing: {pop_on} px > bound {bound} px"
        );
        assert!(
            pop_off > bound,
            "grid {grid}, morph_levels {levels}: without morphing the surface should pop: {pop_off} px <= {bound} px"
        );
    }
}

/// The largest per-frame change with and without morphing and the bound (without tolerance),
/// with `morph_levels` and the split field's cap `field_max` as given.
fn popping_at(grid: u32, morph_levels: u32, field_max: f64, field_density: u32) -> (f64, f64, f64) {
    // Hills of moderate roughness seen from 400 m: several levels and their morph zones and
    // switches are in view.
    let data = procedural::generate(&ProceduralParams {
        size: 257,
        spacing: 30.0,
        feature_size: 4000.0,
        max_height: 1200.0,
        ..Default::default()
    })
    .unwrap();
    let (ex, ey) = data.extent();
    let start = DVec3::new(0.1 * ex, 0.15 * ey, 400.0);
    let step = DVec3::new(0.6 * ex, 0.5 * ey, 0.0).normalize() * 2.0;
    let frames = 160;
    let with_levels = |morph| UdlodSettings {
        morph_levels,
        field_density,
        ..lod(grid, 2.0, morph, field_max)
    };
    let on = with_levels(true);
    let bound = pop_bound(&data, &on, effective_step(&data, start, step, frames));
    let pop_on = largest_pop(&data, on, start, step, frames);
    let pop_off = largest_pop(&data, with_levels(false), start, step, frames);
    println!(
        "grid {grid}, morph_levels {morph_levels}, field_max {field_max}, field_density {field_density}, largest per-frame change: morphing {pop_on:.4} px, no morphing {pop_off:.4} px, bound {bound:.4} px"
    );
    (pop_on, pop_off, bound)
}

/// A camera 100 km from the origin (data 128 km wide, 1 km spacing), moving 1 mm per frame
/// along its view direction: f32 world coordinates there have ~8 mm steps, so a renderer that
/// used them would move the surface in 8 mm jumps. The terrain repeats every 64 km, and the
/// same flight 64 km nearer the origin must see the same centre pixel (its distance within
/// 10 um, frame by frame): precision does not depend on the distance from the origin, for
/// brute force and UDLOD. On llvmpipe the centre distance also drops by 1 mm +- 0.2 mm per
/// frame. Other drivers may snap the vertices' window positions before interpolating depth
/// (Vulkan's `subPixelPrecisionBits`): on NVIDIA's (H200, 2026-12-05) the centre distance of
/// these kilometre-wide triangles 30 m below the camera changed by -0.59 to -6.33 mm per 1 mm
/// step 1 km from the origin as well as at 100 km, so that bound is llvmpipe's alone. UDLOD
/// stays watertight against brute force there. Negative control by hand: the nearer flight
/// moved 4 mm east (half an f32 step at 100 km) fails the comparison (0.1 mm apart).
#[test]
fn camera_100_km_from_the_origin_is_stable_and_watertight() {
    let exact_raster = {
        let gpu = common::gpu(false);
        gpu.info.device_type == ash::vk::PhysicalDeviceType::CPU
            && gpu.info.name.contains("llvmpipe")
    };
    for grid in common::udlod_grids() {
        camera_100_km_from_the_origin_is_stable_and_watertight_at(grid, exact_raster);
    }
}

/// Samples after which [`periodic_terrain`] repeats.
const PERIOD: u32 = 64;

/// 129² samples 1 km apart, hills of 16-64 km that repeat every [`PERIOD`] samples along both
/// axes (whole sine waves: no seam).
fn periodic_terrain() -> Heightmap {
    let n = 2 * PERIOD + 1;
    let wave = |k: f64, v: u32| (std::f64::consts::TAU * k * v as f64 / PERIOD as f64).sin();
    let heights = (0..n)
        .flat_map(|r| (0..n).map(move |c| (c, r)))
        .map(|(c, r)| {
            let h = 600.0
                + 400.0 * wave(1.0, c) * wave(1.0, r + 7)
                + 150.0 * wave(2.0, c + 3) * wave(3.0, r)
                + 60.0 * wave(4.0, c + r);
            h as f32
        })
        .collect();
    Heightmap::new("periodic hills", n, n, 1000.0, heights).unwrap()
}

/// The centre pixel's distance from the camera in each frame, and the frames, of `method`
/// flying 12 frames 1 mm apart along its view direction from `(x, y)`, 30 m above the ground.
fn centre_distances(
    data: &Heightmap,
    method: MethodKind,
    grid: u32,
    (x, y): (f64, f64),
) -> (Vec<f64>, Vec<OwnedFrame>) {
    let base = Camera {
        position: DVec3::new(x, y, data.height_at(x, y) + 30.0),
        yaw_deg: 40.0,
        pitch_deg: -20.0,
        near: 0.5,
        ..Camera::default()
    };
    let (_, _, forward) = base.basis();
    let requests: Vec<FrameRequest> = (0..12)
        .map(|k| {
            Camera {
                position: base.position + forward * (STEP_M * k as f64),
                ..base
            }
            .into()
        })
        .collect();
    let frames = render(data, method, lod(grid, 1.0, true, 8.0), &requests);
    let (cx, cy) = (W / 2, H / 2);
    let distance = |f: &OwnedFrame| {
        let d = f.depth.as_ref().unwrap()[(cy * W + cx) as usize];
        assert!(d > 0.0, "the centre pixel should see terrain");
        (metrics::world_point(&f.camera, cx, cy, W, H, d) - f.camera.position).length()
    };
    (frames.iter().map(distance).collect(), frames)
}

/// The camera's step per frame in [`camera_100_km_from_the_origin_is_stable_and_watertight`].
const STEP_M: f64 = 0.001;

fn camera_100_km_from_the_origin_is_stable_and_watertight_at(grid: u32, exact_raster: bool) {
    let data = periodic_terrain();
    let far = (100_000.0, 100_500.0);
    let period_m = PERIOD as f64 * data.spacing;
    let near = (far.0 - period_m, far.1 - period_m);
    let mut per_method = Vec::new();
    for method in [MethodKind::Brute, MethodKind::Udlod] {
        let (d, frames) = centre_distances(&data, method, grid, far);
        let (d_near, _) = centre_distances(&data, method, grid, near);
        // Each frame's change in mm (docs/udlod.md quotes the GPU machine's).
        let changes = |d: &[f64]| {
            d.windows(2)
                .map(|w| format!("{:.3}", (w[1] - w[0]) * 1000.0))
                .collect::<Vec<_>>()
                .join(" ")
        };
        println!(
            "{method:?}, grid {grid}: centre distance changes per frame, mm: at 100 km {}; 64 km nearer {}",
            changes(&d),
            changes(&d_near)
        );
        for (k, (a, b)) in d.iter().zip(&d_near).enumerate() {
            assert!(
                (a - b).abs() < 1e-5,
                "{method:?}, grid {grid}: frame {k}: centre distance {a:.6} m at 100 km from the origin, {b:.6} m over the same terrain 64 km nearer"
            );
        }
        for k in 1..d.len() {
            let change = d[k] - d[k - 1];
            assert!(
                !exact_raster || (change + STEP_M).abs() < 0.0002,
                "{method:?}: frame {k}: centre distance changed by {:.3} mm, expected -1 mm",
                change * 1000.0
            );
        }
        per_method.push(frames);
    }
    // Watertight: no sky pixel where brute force and its 8 neighbours show terrain.
    let (brute, udlod) = (&per_method[0], &per_method[1]);
    for (b, u) in brute.iter().zip(udlod) {
        let (bd, ud) = (b.depth.as_ref().unwrap(), u.depth.as_ref().unwrap());
        let mut holes = 0;
        for y in 1..H - 1 {
            for x in 1..W - 1 {
                let inside = (-1i32..=1).all(|dy| {
                    (-1i32..=1).all(|dx| {
                        bd[((y as i32 + dy) as u32 * W + (x as i32 + dx) as u32) as usize] > 0.0
                    })
                });
                if inside && ud[(y * W + x) as usize] <= 0.0 {
                    holes += 1;
                }
            }
        }
        assert_eq!(holes, 0, "holes 100 km from the origin");
    }
}

/// Vertex pulling (no index buffer) draws the same triangles as the indexed grid: identical
/// depth buffers over 12 poses, grid 2 (whose collapsed tiles are the parent's one quad) too.
#[test]
fn vertex_pulling_draws_the_same_surface_as_the_indexed_grid() {
    for grid in common::udlod_grids().into_iter().chain([2]) {
        vertex_pulling_draws_the_same_surface_as_the_indexed_grid_at(grid);
    }
}

fn vertex_pulling_draws_the_same_surface_as_the_indexed_grid_at(grid: u32) {
    let data = terrain();
    let requests: Vec<FrameRequest> = flight_poses(&data, 12).iter().map(|&c| c.into()).collect();
    let indexed = render(
        &data,
        MethodKind::Udlod,
        lod(grid, 1.0, true, 8.0),
        &requests,
    );
    let pulled = render(
        &data,
        MethodKind::Udlod,
        UdlodSettings {
            vertex_pulling: true,
            ..lod(grid, 1.0, true, 8.0)
        },
        &requests,
    );
    for (a, b) in indexed.iter().zip(&pulled) {
        assert_eq!(a.triangles, b.triangles);
        let (da, db) = (a.depth.as_ref().unwrap(), b.depth.as_ref().unwrap());
        let differing = da.iter().zip(db).filter(|(x, y)| x != y).count();
        assert!(
            differing <= da.len() / 1000,
            "frame {}: {differing} depth values differ",
            a.index
        );
        assert!(da.iter().filter(|&&d| d > 0.0).count() > da.len() / 4);
    }
}

/// Morphing makes sliver triangles; far away (100 km, Puget Sound seen from 40-76 km up) some
/// of them face away from the camera while still being part of the surface, and with back-face
/// culling they left single-pixel holes surrounded by terrain (first seen in the Improved-PGM
/// flight at 640x360, frames 85 and 127 at tau 4; with today's selection frames 102 and 150 at
/// tau 1, one pixel each, in a scan of every third frame, with one level step,
/// `morph_levels = 1`; with the morph cascade, `morph_levels = 0`, frames 139 and 179 only,
/// one pixel each, in a scan of all 330 frames; with two field nodes per tile side
/// (`field_density = 2`) frames 109, 111, 215 and 227 with one level step and 145, 160, 196
/// and 228 with the cascade, one pixel each, and none with `"static"` in any of the 330; all
/// at the share of 0.72, which the test keeps). Since a point odd along both axes morphs at
/// most `(1 + b) / 2` (`b` its neighbours', docs/udlod-rounds.md "Folds at the quads' diagonal"),
/// no triangle turns over in the grid, and culling every tile left one such pixel in one frame with
/// the cascade (frame 245 with one node per tile corner, 228 with two per side; `eval
/// --sweep morph_levels=1,0 --sweep field_density=1,2`, all 330 frames) and none with one
/// level step; the cascade's two variants are checked on those frames and on one of the
/// frames found before. UDLOD culls back faces only on tiles none of whose vertices can morph
/// (`back_faces = "static"`, the default): no sky pixel there has terrain on all 8 sides.
/// Control: culling every tile (`"all"`) leaves such pixels. Skipped (with a note) without
/// ../shared/data, except under CI (`CI` set), where that fails; any other error (e.g. a
/// missing Puget Sound file in a present data directory) fails.
#[test]
fn no_pinholes_from_back_facing_slivers_far_away() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = root.join("config/puget.toml");
    let scenario = root.join("config/scenarios/puget_improved_pgm_flight.toml");
    let args = vkterrain::cli::render::RenderArgs {
        config: Some(config),
        scenario: Some(scenario),
        ..Default::default()
    };
    // Absent ../shared/data: a skip with a note, a failure under CI (`common::shared_data`).
    if common::shared_data().is_none() {
        return;
    }
    let p = vkterrain::cli::render::prepare(&args).expect("the Puget Sound flight prepares");
    let (w, h) = (640u32, 360u32);
    let gpu = common::gpu(false);
    // Each morph variant and field density with frames where culling every tile showed
    // pinholes.
    let variants = [(0, 1, &[245u64, 139][..]), (0, 2, &[228, 145][..])];
    for (morph_levels, field_density, frames) in variants {
        let requests: Vec<FrameRequest> = frames
            .iter()
            .map(|&k| p.scenario.camera(k).into())
            .collect();
        let pinholes = |back_faces| -> Vec<usize> {
            let frames = common::render_method(
                &gpu,
                p.data.grid().expect("a grid data set"),
                UdlodSettings {
                    tau_px: 1.0,
                    back_faces,
                    morph_levels,
                    field_density,
                    // The share the frames were scanned with (the finer field has its own
                    // since the eighteenth round, which selects other tiles on them).
                    worst_case_share: 0.72,
                    ..Default::default()
                },
                common::options(w, h, 1),
                &requests,
            );
            frames.iter().map(|f| enclosed_sky(f, w, h)).collect()
        };
        let (default, control) = (pinholes(BackFaces::Static), pinholes(BackFaces::All));
        println!(
            "morph_levels {morph_levels}, field_density {field_density}: pinholes per frame: {default:?}; culling every tile: {control:?}"
        );
        assert!(
            default.iter().all(|&n| n == 0),
            "morph_levels {morph_levels}: {default:?} pinholes"
        );
        assert!(
            control.iter().sum::<usize>() > 0,
            "morph_levels {morph_levels}: the control found no pinholes: {control:?}"
        );
    }
    common::assert_no_validation_messages(&gpu);
}

/// Sky pixels of `f` with terrain on all 8 sides, after checking the view shows terrain.
fn enclosed_sky(f: &OwnedFrame, w: u32, h: u32) -> usize {
    let d = f.depth.as_ref().unwrap();
    let (w, h) = (w as usize, h as usize);
    let mut pinholes = 0;
    let mut terrain = 0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            if d[y * w + x] > 0.0 {
                terrain += 1;
                continue;
            }
            let enclosed = (y - 1..=y + 1)
                .all(|yy| (x - 1..=x + 1).all(|xx| (yy, xx) == (y, x) || d[yy * w + xx] > 0.0));
            pinholes += enclosed as usize;
        }
    }
    assert!(
        terrain > w * h / 3,
        "frame {}: the view should show terrain",
        f.index
    );
    pinholes
}

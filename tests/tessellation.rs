//! Hardware tessellation (Fischer 2024): every spacing renders validation clean and covers what
//! brute force covers; the level rule's bounds (1 and 64) give the triangle counts the
//! tessellator must make; the control stage's levels are the CPU mirror's, patch by patch
//! through the triangles they make (flat and on the earth); watertight over 200 poses (with a crack-prone ablation as the
//! control); on a device without `tessellationShader` (masked) a one-line error, no crash.

mod common;

use glam::DVec3;
use vkterrain::dataset::Heightmap;
use vkterrain::dataset::procedural::{self, ProceduralParams};
use vkterrain::driver::{Gpu, GpuOptions};
use vkterrain::geo::Lattice;
use vkterrain::lod::tessellation::levels::LevelRule;
use vkterrain::lod::tessellation::settings::{EdgeLevels, Spacing};
use vkterrain::lod::{MethodConfig, MethodKind, TessellationSettings};
use vkterrain::readback::{CollectSink, OwnedFrame};
use vkterrain::render::{FrameRequest, Renderer};
use vkterrain::scene::Camera;

const W: u32 = 96;
const H: u32 = 64;

fn terrain() -> Heightmap {
    procedural::generate(&ProceduralParams {
        size: 129,
        spacing: 30.0,
        ..Default::default()
    })
    .unwrap()
}

/// The shared poses, the low cameras above the highest nearby sample.
fn poses(data: &Heightmap, n: usize) -> Vec<Camera> {
    common::poses::poses_over(data, n, |x, y| local_top(data, x, y))
}

/// The highest sample within two samples of `(x, y)`: tessellated triangles between bilinear
/// vertices stay below it near the camera (where levels are high), while half a metre above
/// brute force's triangles a camera can be under the tessellated surface and see its back
/// faces culled (docs/tessellation.md: a different surface, not a crack).
fn local_top(data: &Heightmap, x: f64, y: f64) -> f64 {
    let (c, r) = (
        (x / data.spacing).round() as i64,
        (y / data.spacing).round() as i64,
    );
    let mut top = f64::NEG_INFINITY;
    for dy in -2..=2 {
        for dx in -2..=2 {
            let cc = (c + dx).clamp(0, data.width as i64 - 1) as u32;
            let rr = (r + dy).clamp(0, data.height as i64 - 1) as u32;
            top = top.max(data.sample(cc, rr) as f64);
        }
    }
    top
}

/// Renders `cams` with `method` (2 frames in flight, sentinel sky), validation checked.
fn render(
    data: &Heightmap,
    method: impl Into<MethodConfig>,
    cams: &[Camera],
    sky: [f32; 3],
) -> Vec<OwnedFrame> {
    let gpu = common::gpu(false);
    let mut sink = CollectSink::default();
    {
        let mut r = Renderer::new(&gpu, data, method, common::options(W, H, 2)).unwrap();
        for c in cams {
            r.render(
                FrameRequest {
                    camera: *c,
                    sky: Some(sky),
                    lod_viewer: None,
                },
                &mut sink,
            )
            .unwrap();
        }
        r.finish(&mut sink).unwrap();
    }
    common::assert_no_validation_messages(&gpu);
    sink.frames
}

fn depth(f: &OwnedFrame) -> &[f32] {
    f.depth.as_deref().expect("depth read back")
}

/// Pixels where the method shows sky although the reference shows terrain there and within
/// `margin` pixels around (eval's hole metric has margin 1; tessellation's silhouette is coarser
/// than brute force's, so a skyline may move by more than a pixel without being a crack).
fn holes(reference: &OwnedFrame, method: &OwnedFrame, margin: i64) -> usize {
    let (r, m) = (depth(reference), depth(method));
    let (w, h) = (W as i64, H as i64);
    let terrain = |x: i64, y: i64| r[(y * w + x) as usize] > 0.0;
    let mut n = 0;
    for y in margin..h - margin {
        for x in margin..w - margin {
            let inside =
                (-margin..=margin).all(|dy| (-margin..=margin).all(|dx| terrain(x + dx, y + dy)));
            if inside && m[(y * w + x) as usize] <= 0.0 {
                n += 1;
            }
        }
    }
    n
}

#[test]
fn every_spacing_renders_validation_clean_and_covers_what_brute_force_covers() {
    let data = terrain();
    let cams: Vec<Camera> = poses(&data, 10).into_iter().skip(1).step_by(2).collect();
    let sky = [1.0, 0.0, 1.0];
    let brute = render(&data, MethodKind::Brute, &cams, sky);
    for spacing in [
        Spacing::Equal,
        Spacing::FractionalOdd,
        Spacing::FractionalEven,
    ] {
        let settings = TessellationSettings {
            spacing,
            edge_px: 4.0,
            ..Default::default()
        };
        let frames = render(&data, settings, &cams, sky);
        for (i, (b, t)) in brute.iter().zip(&frames).enumerate() {
            assert!(
                t.triangles > 0,
                "{spacing:?} pose {i}: no triangles counted"
            );
            // Coverage: terrain where brute force has terrain, bar a silhouette's width.
            let differ = depth(b)
                .iter()
                .zip(depth(t))
                .filter(|(b, t)| (**b > 0.0) != (**t > 0.0))
                .count();
            assert!(
                differ * 50 < (W * H) as usize,
                "{spacing:?} pose {i}: coverage differs from brute force on {differ} px"
            );
        }
    }
}

/// Triangles of a triangle patch whose three outer levels and inner level are all `n` after
/// the spacing's rounding (Vulkan's tessellator: concentric rings of n, n-2, ... segments).
fn uniform_patch_triangles(n: u64) -> u64 {
    let rings: u64 = (0..)
        .map(|k| n.saturating_sub(2 * k))
        .take_while(|&a| a >= 2)
        .map(|a| 6 * a - 6)
        .sum();
    rings + n % 2
}

#[test]
fn levels_clamp_to_1_and_64_and_count_what_the_tessellator_makes() {
    assert_eq!(uniform_patch_triangles(1), 1);
    assert_eq!(uniform_patch_triangles(2), 6);
    assert_eq!(uniform_patch_triangles(3), 13);
    assert_eq!(uniform_patch_triangles(64), 6144);
    let data = terrain();
    // 129² samples in 32-sample quads: 4 x 4 quads, 32 triangle patches, none of zero area.
    let patches = 32;
    let (ex, ey) = data.extent();
    let (_, hi) = data.height_range();
    let above = Camera {
        position: DVec3::new(0.5 * ex, 0.5 * ey, hi as f64 + 1500.0),
        pitch_deg: -90.0,
        ..Camera::default()
    };
    let cases = [
        // Edges of hundreds of pixels over a 10,000-px target: every level clamps to 1 ...
        (Spacing::Equal, 10_000.0, 1),
        (Spacing::FractionalOdd, 10_000.0, 1),
        // ... which fractional even spacing rounds to 2.
        (Spacing::FractionalEven, 10_000.0, 2),
        // Edges of tens of pixels over a quarter-pixel target: every level clamps to 64.
        (Spacing::Equal, 0.25, 64),
        (Spacing::FractionalEven, 0.25, 64),
    ];
    for (spacing, edge_px, level) in cases {
        let settings = TessellationSettings {
            spacing,
            edge_px,
            patch_samples: 32,
            cull: false,
            ..Default::default()
        };
        let frames = render(&data, settings, &[above, above, above], [0.0; 3]);
        let expected = patches * uniform_patch_triangles(level);
        // The last frame's count is complete (its slot's query was read after its fence).
        assert_eq!(
            frames.last().unwrap().triangles,
            expected,
            "{spacing:?}, edge {edge_px} px: all levels {level}"
        );
    }
}

/// Triangles the GPU counted for each of `cams` (one frame in flight, so each frame's count is
/// its own), and the device's highest tessellation level.
fn gpu_triangles(
    data: &Heightmap,
    lattice: Option<&Lattice>,
    settings: &TessellationSettings,
    cams: &[Camera],
) -> (Vec<u64>, u32) {
    let gpu = common::gpu(false);
    let max_level = gpu.info.limits.max_tessellation_generation_level;
    let mut sink = CollectSink::default();
    {
        let options = common::options(W, H, 1);
        let mut r =
            Renderer::with_world(&gpu, data, settings.clone(), options, None, lattice).unwrap();
        for c in cams {
            r.render(*c, &mut sink).unwrap();
        }
        r.finish(&mut sink).unwrap();
    }
    common::assert_no_validation_messages(&gpu);
    (sink.frames.iter().map(|f| f.triangles).collect(), max_level)
}

/// The poses of the mirror test where `edge_levels` on the GPU counts triangles outside the
/// range the CPU mirror of the edge rule gives (`lod::tessellation::levels`), and the
/// triangles the mirror's ranges leave open (high minus low) against those it fixes (low),
/// summed over the poses.
fn poses_off_the_mirror(
    data: &Heightmap,
    lattice: Option<&Lattice>,
    spacing: Spacing,
    edge_levels: EdgeLevels,
    cams: &[Camera],
) -> (Vec<String>, [u64; 2]) {
    let settings = TessellationSettings {
        spacing,
        edge_px: 6.0,
        patch_samples: 8,
        edge_levels,
        ..Default::default()
    };
    let (counted, max_level) = gpu_triangles(data, lattice, &settings, cams);
    let mirror_settings = TessellationSettings {
        edge_levels: EdgeLevels::Edge,
        ..settings
    };
    let (mut off, mut open) = (Vec::new(), [0, 0]);
    for (i, (cam, &gpu)) in cams.iter().zip(&counted).enumerate() {
        let rule = LevelRule::new(&mirror_settings, data, lattice, cam, (W, H), max_level).unwrap();
        let [lo, hi] = rule.frame_triangles().unwrap();
        open[0] += hi - lo;
        open[1] += lo;
        if !(lo..=hi).contains(&gpu) {
            off.push(format!("pose {i}: GPU {gpu}, mirror {lo}..={hi}"));
        }
    }
    (off, open)
}

/// The control stage's level rule (`shaders/glsl/tess.tesc`) is the CPU mirror's
/// (`lod::tessellation::levels::LevelRule`): over 40 poses per spacing, on the flat world and
/// on a native geographic grid at 60 N, the triangles the GPU's pipeline-statistics query
/// counts equal the tessellator's count for the mirror's culling and levels of every patch (a
/// range where f32 may round a level, or decide the frustum test, the other way). Control:
/// the centroid ablation (`edge_levels = "patch"`) on the GPU falls outside the edge rule's
/// counts on most poses.
#[test]
fn control_stage_levels_equal_the_cpu_mirror() {
    let flat = terrain();
    let flat_cams = poses(&flat, 40);
    let (earth, lattice) = common::poses::geographic_60n(129);
    let earth_cams: Vec<Camera> = common::poses::earth_poses(&earth, &lattice, 22);
    let cases = [
        ("flat", &flat, None, &flat_cams),
        ("60 N", &earth, Some(&*lattice), &earth_cams),
    ];
    for (name, data, lattice, cams) in cases {
        for spacing in [
            Spacing::Equal,
            Spacing::FractionalOdd,
            Spacing::FractionalEven,
        ] {
            let (off, [open, fixed]) =
                poses_off_the_mirror(data, lattice, spacing, EdgeLevels::Edge, cams);
            println!(
                "{name} {spacing:?}: {} poses, {} off the mirror; {fixed} triangles, {open} more \
                 where f32 may round the other way",
                cams.len(),
                off.len()
            );
            assert!(off.is_empty(), "{name} {spacing:?}: {off:#?}");
            // The ranges are narrow: the comparison pins the levels.
            assert!(
                open * 200 <= fixed,
                "{name} {spacing:?}: {open} of {fixed} open"
            );
        }
        let (off, _) = poses_off_the_mirror(data, lattice, Spacing::Equal, EdgeLevels::Patch, cams);
        println!(
            "{name} control (centroid levels): {} poses off the mirror",
            off.len()
        );
        assert!(
            off.len() * 2 > cams.len(),
            "{name}: the centroid rule matched the edge rule's counts on {} of {} poses",
            cams.len() - off.len(),
            cams.len()
        );
    }
}

/// Sentinel pixels inside the brute-force silhouette (shrunk by 2 px) over 200 poses
/// (ground-level poses above the local top sample, see [`local_top`]), per spacing, with
/// Fischer's edge rule and with the control (levels from each patch's centroid, so neighbours
/// disagree on a shared edge), which must crack, or the check could not see cracks.
/// Equal spacing is watertight; the fractional modes leave isolated one-pixel pinholes on
/// lavapipe (measured: docs/tessellation.md), far fewer than the control's cracks.
#[test]
fn watertight_over_200_poses() {
    let data = terrain();
    let cams = poses(&data, 200);
    let sky = [1.0, 0.0, 1.0];
    let brute = render(&data, MethodKind::Brute, &cams, sky);
    let terrain_px: usize = brute
        .iter()
        .map(|b| depth(b).iter().filter(|d| **d > 0.0).count())
        .sum();
    assert!(terrain_px > 200 * (W * H) as usize / 4, "{terrain_px}");
    for spacing in [
        Spacing::Equal,
        Spacing::FractionalOdd,
        Spacing::FractionalEven,
    ] {
        let settings = |edge_levels| TessellationSettings {
            edge_px: 2.0,
            patch_samples: 32,
            edge_levels,
            spacing,
            ..Default::default()
        };
        let edge = render(&data, settings(EdgeLevels::Edge), &cams, sky);
        let patch = render(&data, settings(EdgeLevels::Patch), &cams, sky);
        let (mut edge_holes, mut patch_holes, mut worst) = (0, 0, 0);
        for (i, b) in brute.iter().enumerate() {
            let h = holes(b, &edge[i], 2);
            if h > 0 {
                println!("{spacing:?}: pose {i}: {h} holes {:?}", cams[i]);
            }
            worst = worst.max(h);
            edge_holes += h;
            patch_holes += holes(b, &patch[i], 2);
        }
        println!(
            "watertight {spacing:?}: {terrain_px} terrain px, {edge_holes} holes (worst pose {worst}); {patch_holes} with per-patch levels"
        );
        assert!(
            patch_holes >= 20,
            "{spacing:?}: per-patch levels should crack; the check would not see cracks"
        );
        if spacing == Spacing::Equal {
            assert_eq!(edge_holes, 0, "{spacing:?}");
        } else {
            assert!(
                worst <= 2 && edge_holes * 10 <= patch_holes,
                "{spacing:?}: {edge_holes} holes, worst pose {worst}"
            );
        }
    }
}

#[test]
fn a_masked_tessellation_shader_is_a_one_line_error() {
    let gpu = Gpu::new(&GpuOptions {
        validation: true,
        mask_features: vec!["tessellationShader".into()],
        ..GpuOptions::default()
    })
    .unwrap();
    let data = terrain();
    let e = Renderer::new(
        &gpu,
        &data,
        MethodKind::Tessellation,
        common::options(W, H, 2),
    )
    .err()
    .expect("tessellation without tessellationShader must fail")
    .to_string();
    assert_eq!(
        e,
        "method tessellation needs the Vulkan feature tessellationShader, which is masked by VKTERRAIN_MASK_FEATURES"
    );
    // Other methods still run on that device.
    drop(
        Renderer::new(&gpu, &data, MethodKind::Udlod, common::options(W, H, 2))
            .expect("udlod needs no tessellation"),
    );
    common::assert_no_validation_messages(&gpu);
}

#[test]
fn cli_selects_tessellation_and_names_the_masked_feature() {
    let dir = tempfile::tempdir().unwrap();
    let config = common::cli::ci_config();
    let out = dir.path().join("render");
    let args = [
        "render",
        "--config",
        &config,
        "--method",
        "tessellation",
        "--frames",
        "2",
        "--out",
        out.to_str().unwrap(),
    ];
    // Control: the same command on the unmasked device renders.
    let ok = common::cli::run(&args);
    let stdout = String::from_utf8_lossy(&ok.stdout);
    assert!(
        ok.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    assert!(stdout.contains("method:          tessellation"), "{stdout}");
    let masked_out = dir.path().join("masked");
    let masked = common::cli::command()
        .env("VKTERRAIN_MASK_FEATURES", "tessellationShader")
        .args(&args[..7])
        .args(["--out", masked_out.to_str().unwrap()])
        .output()
        .unwrap();
    common::cli::assert_one_line_error(&masked, &["tessellation", "tessellationShader"]);
}

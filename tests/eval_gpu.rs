//! The evaluator's GPU metrics (`src/eval/gpu/`, `shaders/eval_metrics.wgsl`) equal the CPU
//! definitions (`src/eval/metrics.rs`) on small frames: per frame, the height-error,
//! screen-space-error and popping histograms within one bin, means and maxima to f32
//! precision, holes and PSNR exactly, SSIM to 1e-4 — for the reference itself, for a method
//! with real errors (PGM) and for one with cracks (UDLOD without morphing). Negative control:
//! the same frames measured on the CPU against a surface 0.3 m higher must differ. On the earth (the terrain drawn through an anchored
//! geolocation lattice, the GPU inverting it per pixel, the CPU by `Lattice::sample_at`) the
//! same, with a second negative control: the CPU mapping the points to the grid as on the
//! flat world must differ. Validation (incl. synchronization) on.

mod common;

use std::sync::Arc;

use vkterrain::dataset::procedural::{self, ProceduralParams};
use vkterrain::dataset::{Heightmap, Terrain};
use vkterrain::eval::check::{CpuFrame, Floors, FrameMeasures, compare, cpu_measures};
use vkterrain::eval::gpu::reference::ViewCone;
use vkterrain::eval::gpu::{EvalShared, FrameShape, GpuAnalysis, Role};
use vkterrain::eval::metrics::{OnEarth, ViewColumns};
use vkterrain::geo::{EnuFrame, Geodetic, Lattice, WGS84};
use vkterrain::lod::{MethodConfig, PgmSettings, UdlodSettings};
use vkterrain::readback::CollectSink;
use vkterrain::render::Renderer;
use vkterrain::scene::Scenario;

fn raised(data: &Heightmap, dz: f32) -> Heightmap {
    let mut h = data.clone();
    h.heights.iter_mut().for_each(|v| *v += dz);
    h
}

#[test]
fn gpu_metrics_equal_the_cpu_path_on_small_frames() {
    gpu_metrics_equal_the_cpu_path(30.0, None);
}

/// 257 samples of 120 m (31 km) anchored at 60 N: the far side lies ~75 m below the tangent
/// plane at the origin.
#[test]
fn gpu_metrics_equal_the_cpu_path_on_the_earth() {
    let frame = EnuFrame::new(&WGS84, Geodetic::new(60.0, 20.0, 0.0));
    let lattice = Lattice::anchored_plane(257, 257, 120.0, frame).unwrap();
    gpu_metrics_equal_the_cpu_path(120.0, Some(&lattice));
}

fn gpu_metrics_equal_the_cpu_path(spacing: f64, lattice: Option<&Lattice>) {
    let gpu = common::gpu(false);
    let data = Arc::new(
        procedural::generate(&ProceduralParams {
            size: 257,
            seed: 3,
            spacing,
            ..Default::default()
        })
        .unwrap(),
    );
    let higher = raised(&data, 0.3);
    let terrain = Terrain::Grid(data.clone());
    let scenario = Scenario::builtin_default(&terrain).unwrap();
    let (w, h, frames) = (80u32, 48u32, 6u64);
    let shape = FrameShape {
        width: w,
        height: h,
        views: 1,
    };
    let shared = EvalShared::new(&gpu, &terrain, lattice, shape, frames, 3, 64 << 20).unwrap();
    let mut runs = Vec::new();
    for (method, role) in methods_compared(lattice.is_some()) {
        let mut renderer = Renderer::with_world(
            &gpu,
            data.clone(),
            method,
            common::options(w, h, 1),
            None,
            lattice,
        )
        .unwrap();
        let (analysis, results) = GpuAnalysis::new(&shared, role, vec![0, frames - 1]).unwrap();
        renderer.set_analysis(Box::new(analysis)).unwrap();
        runs.push((renderer, results, None::<Vec<Option<f64>>>));
    }
    let mut variant_errors = 0;
    let mut cracks = 0;
    for k in 0..frames {
        let camera = scenario.camera(k * 4);
        let views = ViewColumns::whole(camera, w);
        let floors = Floors::of(&views, h);
        shared
            .prepare(
                k,
                &[ViewCone {
                    camera,
                    aspect: w as f64 / h as f64,
                }],
            )
            .unwrap();
        let mut delivered = Vec::new();
        for (renderer, results, _) in &mut runs {
            let mut sink = CollectSink::default();
            renderer.render(camera, &mut sink).unwrap();
            let frame = sink.frames.pop().expect("one frame in flight: delivered");
            delivered.push((frame, results.try_recv().expect("GPU metrics of the frame")));
        }
        let reference = delivered[0].0.clone();
        for (i, (frame, metrics)) in delivered.iter().enumerate() {
            assert_eq!((metrics.index, metrics.missing_reference), (k, 0));
            let cpu_frame = CpuFrame {
                rgba: &frame.rgba,
                depth: frame.depth.as_deref(),
                reference_rgba: Some(&reference.rgba),
                reference_depth: reference.depth.as_deref(),
            };
            let previous = runs[i].2.as_deref();
            let measure = |surface: &Heightmap, earth: bool| match (lattice, earth) {
                (Some(lattice), true) => {
                    let on_earth = OnEarth { surface, lattice };
                    cpu_measures(&on_earth, &views, shape, &cpu_frame, previous)
                }
                _ => cpu_measures(surface, &views, shape, &cpu_frame, previous),
            };
            let (cpu, image) = measure(&data, true).unwrap();
            let gpu_measures = FrameMeasures::from(metrics);
            let problems = compare(&gpu_measures, &cpu, floors);
            assert!(problems.is_empty(), "run {i}, frame {k}: {problems:#?}");
            assert!(
                cpu.pixels.count() > (w * h / 4) as u64,
                "frame {k} shows terrain"
            );
            if i == 1 {
                variant_errors += (cpu.pixels.quantile(0.99) > 0.05) as usize;
            }
            if i == 2 {
                cracks += cpu.holes.cracks;
            }
            // Negative control: a surface 0.3 m higher is not the one the GPU measured against.
            let (shifted, _) = measure(&higher, true).unwrap();
            assert!(
                !compare(&gpu_measures, &shifted, floors).is_empty(),
                "run {i}, frame {k}: a raised surface went unnoticed"
            );
            // On the earth: the flat world's mapping is not the one the GPU measured with.
            if lattice.is_some() {
                let (flat, _) = measure(&data, false).unwrap();
                assert!(
                    !compare(&gpu_measures, &flat, floors).is_empty(),
                    "run {i}, frame {k}: the flat mapping went unnoticed"
                );
            }
            runs[i].2 = Some(image);
        }
    }
    assert!(
        variant_errors > 0,
        "the variant (PGM at a quarter grid, UDLOD tau 4) has visible errors"
    );
    assert!(cracks > 0, "UDLOD without morphing shows cracks");
    drop(runs);
    drop(shared);
    common::assert_no_validation_messages(&gpu);
}

/// Brute force (the reference), a method with real errors (PGM at a quarter grid; on the
/// earth, which PGM refuses, UDLOD at tau 4 px) and one with cracks (UDLOD without morphing
/// opens T-junction gaps between levels, so the crack count is compared where it is not 0).
fn methods_compared(on_earth: bool) -> [(MethodConfig, Role); 3] {
    let variant: MethodConfig = if !on_earth {
        let mut pgm: MethodConfig = PgmSettings::default().into();
        pgm.apply_sweep("grid_scale", 0.25).unwrap();
        pgm
    } else {
        UdlodSettings {
            tau_px: 4.0,
            ..Default::default()
        }
        .into()
    };
    let cracked: MethodConfig = UdlodSettings {
        tau_px: 4.0,
        morph: false,
        ..Default::default()
    }
    .into();
    [
        (MethodConfig::Brute {}, Role::Reference),
        (variant, Role::Variant),
        (cracked, Role::Variant),
    ]
}

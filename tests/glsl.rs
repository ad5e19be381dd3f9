//! The GLSL toolchain (`build/glsl.rs`, glslangValidator): build errors name the original file
//! and line (main file, includes, the generated prelude), the `#define` prelude carries every
//! shared constant, and the GLSL port of the shared geometry helpers
//! (`shaders/glsl/include/terrain_common.glsl`) computes the same bits as the WGSL ones
//! (`shaders/include/terrain_common.wgsl`) on the GPU, through the set 0 a renderer drew with,
//! on the single-texture path and through the clipmap. Mutated ports are told apart (negative
//! controls). GPU work runs with validation on.

mod common;

#[path = "../build/glsl.rs"]
mod glsl;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DVec3;
use vkterrain::clipmap::{Clipmap, ClipmapSettings, DatasetSource, Geometry};
use vkterrain::dataset::procedural::ProceduralParams;
use vkterrain::dataset::{Heightmap, tiles};
use vkterrain::driver::shaders::{
    ShaderHeights, ShaderWorld, Spirv, TERRAIN_PROBE_COMP_GLSL, TERRAIN_PROBE_COMP_SPV,
    TERRAIN_PROBE_SPV, TerrainVariant,
};
use vkterrain::gpu_constants::WGSL_CONSTANTS;
use vkterrain::lod::MethodKind;
use vkterrain::readback::CollectSink;
use vkterrain::render::{Renderer, TerrainProbePoint};
use vkterrain::scene::Camera;

fn prelude() -> Vec<String> {
    glsl::prelude(WGSL_CONSTANTS.iter().map(|(n, v)| (*n, v.wgsl().1)))
}

/// A fresh temporary directory for this test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vkterrain-glsl-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("include")).unwrap();
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn compile(dir: &Path, main: &Path) -> Result<glsl::Compiled, String> {
    let glslang = glsl::Glslang::find().expect("glslangValidator (make deps)");
    glsl::compile(&glslang, main, &dir.join("include"), &prelude(), dir)
}

/// The first line of a build error.
fn first_line(e: &str) -> &str {
    e.lines().next().unwrap_or("")
}

#[test]
fn build_errors_name_the_original_file_and_line() {
    let dir = scratch("errors");
    let inc = write(
        &dir,
        "include/helpers.glsl",
        "// helpers\nfloat twice(float x) {\n    return 2.0 * x;\n}\nfloat broken() { return undefined_in_include; }\n",
    );
    // An error after an include: the main file's own line number, not the composed one.
    let main = write(
        &dir,
        "after.comp",
        "#version 450\n// comment\n//!include helpers.glsl\nlayout(local_size_x = 1) in;\nvoid main() {\n    float y = twice(undefined_in_main);\n}\n",
    );
    let e = compile(&dir, &main).unwrap_err();
    // glslang stops at the include's error first (it comes first in the composed source).
    assert_eq!(
        first_line(&e),
        format!(
            "{}:5: 'undefined_in_include' : undeclared identifier",
            inc.display()
        ),
        "{e}"
    );
    // Fixed include: now the main file's error, at its own line 6.
    write(
        &dir,
        "include/helpers.glsl",
        "float twice(float x) { return 2.0 * x; }\n",
    );
    let e = compile(&dir, &main).unwrap_err();
    assert_eq!(
        first_line(&e),
        format!(
            "{}:6: 'undefined_in_main' : undeclared identifier",
            main.display()
        ),
        "{e}"
    );
    // Fixed: compiles, valid SPIR-V, the include recorded as a source.
    write(
        &dir,
        "after.comp",
        "#version 450\n//!include helpers.glsl\nlayout(local_size_x = 1) in;\nvoid main() { float y = twice(1.0); }\n",
    );
    let ok = compile(&dir, &main).unwrap();
    assert_eq!(&ok.spv[..4], &0x0723_0203u32.to_le_bytes());
    assert_eq!(ok.sources.len(), 2);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_shaders_are_one_line_errors_naming_the_file() {
    let dir = scratch("malformed");
    let cases: &[(&str, &str, &str)] = &[
        (
            "no_version.comp",
            "void main() {}\n",
            ":1: the first statement must be #version",
        ),
        (
            "missing_include.comp",
            "#version 450\n\n//!include nowhere.glsl\nvoid main() {}\n",
            ":3: cannot include",
        ),
        (
            "stage.glsl",
            "#version 450\nvoid main() {}\n",
            "unknown GLSL stage",
        ),
        // A link-stage error carries no file of its own: the shader is named.
        (
            "nolayout.tese",
            "#version 450\nvoid main() { gl_Position = vec4(0.0); }\n",
            "nolayout.tese: ",
        ),
        // A constant redefined by the shader clashes with the prelude's #define.
        (
            "redefine.comp",
            "#version 450\n#define UDLOD_WORKGROUP 32u\nlayout(local_size_x = 1) in;\nvoid main() {}\n",
            "redefine.comp:2:",
        ),
    ];
    for (name, text, words) in cases {
        let path = write(&dir, name, text);
        let e = compile(&dir, &path).unwrap_err();
        assert!(
            first_line(&e).contains(words),
            "{name}: {words:?} not in the first line of {e:?}"
        );
        assert!(first_line(&e).contains(name), "{name}: {e:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every shared constant reaches the GLSL as a `#define` with the WGSL's literal, before the
/// shader's own text, with `#line` bringing the numbering back to the file's.
#[test]
fn the_prelude_defines_every_shared_constant() {
    for (name, value) in WGSL_CONSTANTS {
        let line = format!("#define {name} {}", value.wgsl().1);
        assert!(
            TERRAIN_PROBE_COMP_GLSL.lines().any(|l| l == line),
            "{line:?} missing from the composed GLSL"
        );
    }
    let lines: Vec<&str> = TERRAIN_PROBE_COMP_GLSL.lines().collect();
    assert!(lines[0].starts_with("#version"));
    assert!(lines.contains(&"#line 2 \"shaders/glsl/terrain_probe.comp\""));
    assert!(lines.contains(&"#line 1 \"shaders/glsl/include/terrain_common.glsl\""));
}

/// Probe inputs all over (and past) a `w` x `h` data set: integer samples, fractional
/// positions, positions outside (clamping), and fractions for `project`.
fn probe_points(w: u32, h: u32) -> Vec<TerrainProbePoint> {
    (0..4096u32)
        .map(|k| {
            let u = (k as f32 * 0.618_034).fract();
            let v = (k as f32 * 0.414_213_6).fract();
            // 10% of the points up to 8 samples outside the data on either side.
            let spread = |t: f32, n: u32| -8.0 + t * (n as f32 + 15.0);
            let (x, y) = if k % 10 == 0 {
                (spread(u, w), spread(v, h))
            } else {
                (u * (w - 1) as f32, v * (h - 1) as f32)
            };
            let pos = if k % 3 == 0 {
                [x.floor(), y.floor()]
            } else {
                [x, y]
            };
            TerrainProbePoint {
                cell: [x.floor() as i32, y.floor() as i32, 0, 0],
                pos: [pos[0], pos[1], (u * 7.0).fract(), (v * 5.0).fract()],
                ..Default::default()
            }
        })
        .collect()
}

/// Points where the two probes' outputs differ in any bit.
fn differing(a: &[TerrainProbePoint], b: &[TerrainProbePoint]) -> usize {
    let bits = |p: &TerrainProbePoint| {
        let mut v: Vec<u32> = p.heights.iter().map(|f| f.to_bits()).collect();
        v.extend(p.clip.iter().map(|f| f.to_bits()));
        v
    };
    a.iter().zip(b).filter(|(x, y)| bits(x) != bits(y)).count()
}

/// Renders a few frames of brute force with `clipmap` and returns the renderer, finished.
fn rendered(
    gpu: &Arc<vkterrain::driver::Gpu>,
    data: &Heightmap,
    clipmap: Option<Clipmap>,
) -> Renderer {
    let (ex, ey) = data.extent();
    let (_, hi) = data.height_range();
    let cam = Camera {
        position: DVec3::new(0.37 * ex, 0.61 * ey, hi as f64 + 300.0),
        yaw_deg: 30.0,
        pitch_deg: -35.0,
        ..Camera::default()
    };
    let mut r = Renderer::with_clipmap(
        gpu,
        data,
        MethodKind::Brute,
        common::options(160, 100, 2),
        clipmap,
    )
    .unwrap();
    let mut sink = CollectSink::default();
    for _ in 0..6 {
        r.render(cam, &mut sink).unwrap();
    }
    r.finish(&mut sink).unwrap();
    r
}

/// The WGSL and GLSL probes over the same points through the renderer's last set 0.
fn both(
    r: &Renderer,
    points: &[TerrainProbePoint],
    glsl_spv: Spirv,
) -> [Vec<TerrainProbePoint>; 2] {
    // The WGSL build is the terrain's; callers pass the GLSL build of the same variant.
    [
        r.probe_terrain_helpers(
            0,
            TERRAIN_PROBE_SPV.variant(r.terrain_variant()),
            c"probe_main",
            points,
        )
        .unwrap(),
        r.probe_terrain_helpers(0, glsl_spv, c"main", points)
            .unwrap(),
    ]
}

/// The GLSL probe with one mutation (needle, replacement) in the port, built for `variant` in
/// both frame-block variants as build.rs builds them (leaked: embedded shaders are `'static`).
fn mutated_probe(
    name: &str,
    (needle, replacement): (&str, &str),
    variant: TerrainVariant,
) -> Spirv {
    let dir = scratch(name);
    let port = std::fs::read_to_string("shaders/glsl/include/terrain_common.glsl").unwrap();
    assert!(
        port.contains(needle),
        "mutation target {needle:?} not in the port"
    );
    write(
        &dir,
        "include/terrain_common.glsl",
        &port.replacen(needle, replacement, 1),
    );
    let probe = std::fs::read_to_string("shaders/glsl/terrain_probe.comp").unwrap();
    let main = write(&dir, "terrain_probe.comp", &probe);
    let mut defines = prelude();
    defines.extend(glsl::terrain_defines(
        variant.world == ShaderWorld::Earth,
        variant.heights == ShaderHeights::Clipmap,
    ));
    let glslang = glsl::Glslang::find().expect("glslangValidator (make deps)");
    let include = dir.join("include");
    let uniform = glsl::compile(&glslang, &main, &include, &defines, &dir)
        .unwrap()
        .spv;
    defines.push("#define VKTERRAIN_FRAME_STORAGE 1".into());
    let storage_dir = dir.join("frame_storage");
    std::fs::create_dir_all(&storage_dir).unwrap();
    let storage = glsl::compile(&glslang, &main, &include, &defines, &storage_dir)
        .unwrap()
        .spv;
    let _ = std::fs::remove_dir_all(&dir);
    Spirv {
        frame_uniform: Vec::leak(uniform),
        frame_storage: Some(Vec::leak(storage)),
    }
}

#[test]
fn glsl_port_equals_the_wgsl_helpers_on_the_single_texture_path() {
    let gpu = common::gpu(false);
    let data = vkterrain::dataset::procedural::generate(&ProceduralParams {
        size: 257,
        ..Default::default()
    })
    .unwrap();
    let points = probe_points(data.width, data.height);
    let r = rendered(&gpu, &data, None);
    let [wgsl, port] = both(
        &r,
        &points,
        TERRAIN_PROBE_COMP_SPV.variant(r.terrain_variant()),
    );
    assert_eq!(
        differing(&wgsl, &port),
        0,
        "GLSL port differs from the WGSL"
    );
    // The probe measured something: heights vary and clip positions are not all zero.
    assert!(wgsl.iter().any(|p| p.heights[0] != wgsl[0].heights[0]));
    assert!(wgsl.iter().all(|p| p.clip[3] != 0.0));
    // Negative control: a port that clamps one sample too far differs at points past the
    // data's edges (and only reads the texture out of range there).
    let wrong = mutated_probe(
        "clamp",
        (
            "ivec2 c = clamp(s, ivec2(0), hi);",
            "ivec2 c = clamp(s, ivec2(0), hi - ivec2(1));",
        ),
        r.terrain_variant(),
    );
    let [_, mutated] = both(&r, &points, wrong);
    assert!(
        differing(&wgsl, &mutated) > 0,
        "a wrong clamp went unnoticed"
    );
    drop(r);
    common::assert_no_validation_messages(&gpu);
}

#[test]
fn glsl_port_equals_the_wgsl_helpers_through_the_clipmap() {
    let gpu = common::gpu(false);
    let dir = common::procedural_pyramid("glsl-port", 257, 5, 32);
    let data = tiles::load(&dir, Some(0), u64::MAX).unwrap();
    let ds = DatasetSource::open(&dir).unwrap();
    let settings = ClipmapSettings {
        enabled: true,
        atlas_capacity: 64,
        node_count: 4,
        max_in_flight: 16,
        max_uploads_per_frame: 16,
        workers: 1,
        retry_frames: 3,
        blend_nodes: 0.5,
    };
    let cm = Clipmap::new(Geometry::of(&ds.dataset), settings, Arc::new(ds), 1).unwrap();
    let points = probe_points(data.width, data.height);
    let r = rendered(&gpu, &data, Some(cm));
    let [wgsl, port] = both(
        &r,
        &points,
        TERRAIN_PROBE_COMP_SPV.variant(r.terrain_variant()),
    );
    assert_eq!(
        differing(&wgsl, &port),
        0,
        "GLSL port differs through the clipmap"
    );
    // Negative control: a port with the wrong blend band between clipmap levels.
    let wrong = mutated_probe(
        "blend",
        (
            "clamp(d * blend_inv, 0.0, 1.0)",
            "clamp(d * blend_inv * 0.5, 0.0, 1.0)",
        ),
        r.terrain_variant(),
    );
    let [_, mutated] = both(&r, &points, wrong);
    assert!(
        differing(&wgsl, &mutated) > 0,
        "a wrong blend band went unnoticed"
    );
    drop(r);
    common::assert_no_validation_messages(&gpu);
    let _ = std::fs::remove_dir_all(dir.parent().unwrap());
}

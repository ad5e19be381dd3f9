//! Compiles every `shaders/*.wgsl` to SPIR-V with naga, validator on, so a broken shader fails the
//! build with its file, line and message.
//!
//! Shaders are composed before parsing: the shared constants of `src/gpu_constants.rs` come
//! first, then each `//!include NAME.wgsl` line is replaced by `shaders/include/NAME.wgsl`.
//! A line map turns naga's error position back into the original file and line.
//!
//! Every shader that reads the frame's block (set 0, binding 0) is compiled twice: as the
//! uniform buffer it is written as, and with that one declaration a read-only storage buffer
//! ([`FRAME_UNIFORM`] -> [`FRAME_STORAGE`]; GLSL: `VKTERRAIN_FRAME_STORAGE` defined). The
//! device picks one (`driver::shaders::FrameBlock`, docs/architecture.md, "Uniform buffers on
//! Mesa 22.3").
//!
//! Every shader that includes `terrain_common.wgsl` declares the overrides [`TERRAIN_OVERRIDES`]
//! (its world, flat or the earth, and its source of heights, the clipmap or one texture) and is
//! compiled once per [`TERRAIN_VARIANTS`] entry with them set (naga's `process_overrides`: the
//! branches they decide keep a constant condition, whose dead side the driver drops), in both
//! frame-block variants: `TerrainSpirv` in `driver::shaders`, picked per terrain
//! (docs/architecture.md, "Shaders per terrain").
//!
//! Workgroup memory is zero-filled at the start of every compute entry point (WGSL's rule,
//! naga's polyfill) unless the shader's own file has the line [`WORKGROUP_WRITTEN_FIRST`]: it
//! then promises to write every workgroup variable before reading it, and the fill is left out
//! (docs/architecture.md, "Workgroup memory written first").
//!
//! The stages naga cannot compile (tessellation, task, mesh) are GLSL under `shaders/glsl/`,
//! composed the same way (a `#define` per shared constant) and compiled by glslangValidator:
//! see `build/glsl.rs`. The terrain variants are `#define`s there (`EARTH_WORLD` and
//! `CLIPMAP_HEIGHTS`, `true` or `false`), the frame block's storage variant
//! `VKTERRAIN_FRAME_STORAGE`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[path = "build/glsl.rs"]
mod glsl;

#[allow(dead_code)]
mod gpu_constants {
    include!("src/gpu_constants.rs");
}

/// The frame block's declaration in `shaders/include/terrain_common.wgsl`, and what the storage
/// variant of every shader that includes it declares instead (the same layout: vec4 members).
const FRAME_UNIFORM: &str = "@group(0) @binding(0) var<uniform> frame: Frame;";
const FRAME_STORAGE: &str = "@group(0) @binding(0) var<storage, read> frame: Frame;";
/// A line in a shader's own file (not an include): each of its compute entry points writes every
/// workgroup variable it reads before reading it, so naga's zero-fill is left out. The fill is
/// one invocation storing every word of workgroup memory behind a branch; Mesa 22.3's llvmpipe
/// turns each word's store into a loop over the SIMD lanes and runs them all for every 8
/// invocations (a fifth of UDLOD's prepass there; docs/architecture.md, "Workgroup memory
/// written first").
const WORKGROUP_WRITTEN_FIRST: &str = "//!workgroup-memory written-first";
/// The overrides of a terrain shader (`shaders/include/terrain_common.wgsl`): whether it is built
/// for the earth (the geolocation lattice) or the flat world, and whether its heights come from
/// the clipmap or from the single height texture. build.rs compiles every shader that declares
/// them once per [`TERRAIN_VARIANTS`] entry; the renderer picks one per terrain
/// (`driver::shaders::TerrainVariant`). Lavapipe before Mesa 24 runs every branch of a shader
/// whose condition comes from a storage buffer, so a build that holds both worlds or both
/// height sources pays for the one it does not draw (docs/architecture.md, "Shaders per
/// terrain").
const TERRAIN_OVERRIDES: [&str; 2] = glsl::TERRAIN_SETTINGS;

/// One terrain variant: its field name in `driver::shaders::TerrainSpirv` (and file suffix) and
/// the values of [`TERRAIN_OVERRIDES`].
struct TerrainBuild {
    name: &'static str,
    earth: bool,
    clipmap: bool,
}

const TERRAIN_VARIANTS: [TerrainBuild; 4] = [
    TerrainBuild {
        name: "flat_texture",
        earth: false,
        clipmap: false,
    },
    TerrainBuild {
        name: "flat_clipmap",
        earth: false,
        clipmap: true,
    },
    TerrainBuild {
        name: "earth_texture",
        earth: true,
        clipmap: false,
    },
    TerrainBuild {
        name: "earth_clipmap",
        earth: true,
        clipmap: true,
    },
];
/// Defined in the GLSL storage variant (`shaders/glsl/include/terrain_common.glsl`).
const GLSL_FRAME_STORAGE: &str = "VKTERRAIN_FRAME_STORAGE";

/// Where each line of a composed shader came from.
struct LineOrigin {
    file: PathBuf,
    line: usize,
}

fn compose(path: &Path, out: &mut String, map: &mut Vec<LineOrigin>, depth: usize) {
    if depth > 8 {
        fail(&format!("{}: includes nest deeper than 8", path.display()));
    }
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| fail(&format!("{}: cannot read: {e}", path.display())));
    println!("cargo:rerun-if-changed={}", path.display());
    for (index, line) in text.lines().enumerate() {
        if let Some(name) = line.trim().strip_prefix("//!include ") {
            let inc = Path::new("shaders/include").join(name.trim());
            compose(&inc, out, map, depth + 1);
        } else {
            out.push_str(line);
            out.push('\n');
            map.push(LineOrigin {
                file: path.to_path_buf(),
                line: index + 1,
            });
        }
    }
}

/// `path` composed after `prelude`, with the origin of every line.
fn compose_wgsl(path: &Path, prelude: &str) -> (String, Vec<LineOrigin>) {
    let mut source = String::new();
    let mut map = Vec::new();
    for line in prelude.lines() {
        source.push_str(line);
        source.push('\n');
        map.push(LineOrigin {
            file: PathBuf::from("src/gpu_constants.rs"),
            line: 0,
        });
    }
    compose(path, &mut source, &mut map, 0);
    (source, map)
}

/// How naga initializes the workgroup memory of `path`'s compute entry points: not at all when
/// the file itself has the line [`WORKGROUP_WRITTEN_FIRST`], else zero-filled as WGSL requires.
fn workgroup_memory_init(path: &Path) -> naga::back::spv::ZeroInitializeWorkgroupMemoryMode {
    use naga::back::spv::ZeroInitializeWorkgroupMemoryMode as Mode;
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| fail(&format!("{}: cannot read: {e}", path.display())));
    if text.lines().any(|l| l.trim() == WORKGROUP_WRITTEN_FIRST) {
        Mode::None
    } else {
        Mode::Polyfill
    }
}

/// Parses and validates composed WGSL (`compose_wgsl` of `path`) with naga; fails the build with
/// the file and line of an error.
fn parse_wgsl(
    path: &Path,
    source: &str,
    map: &[LineOrigin],
) -> (naga::Module, naga::valid::ModuleInfo) {
    let locate = |offset: Option<usize>| -> String {
        let Some(offset) = offset else {
            return path.display().to_string();
        };
        let line = source[..offset.min(source.len())].matches('\n').count();
        match map.get(line) {
            Some(o) if o.line > 0 => format!("{}:{}", o.file.display(), o.line),
            Some(o) => format!("{} (generated constants)", o.file.display()),
            None => path.display().to_string(),
        }
    };

    let module = match naga::front::wgsl::parse_str(source) {
        Ok(m) => m,
        Err(e) => {
            let offset = e.location(source).map(|l| l.offset as usize);
            fail(&format!(
                "{}: {}\n{}",
                locate(offset),
                e.message(),
                e.emit_to_string_with_path(source, &path.display().to_string())
            ));
        }
    };
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .unwrap_or_else(|e| {
        let offset = e.location(source).map(|l| l.offset as usize);
        fail(&format!(
            "{}: {}\n{}",
            locate(offset),
            e.as_inner(),
            e.emit_to_string_with_path(source, &path.display().to_string())
        ))
    });
    (module, info)
}

/// Whether `module` declares the terrain variant's overrides ([`TERRAIN_OVERRIDES`]); fails the
/// build on any other override, or on one of them without the other.
fn has_terrain_overrides(path: &Path, module: &naga::Module) -> bool {
    let names: Vec<&str> = module
        .overrides
        .iter()
        .map(|(_, o)| o.name.as_deref().unwrap_or("(unnamed)"))
        .collect();
    if let Some(other) = names.iter().find(|n| !TERRAIN_OVERRIDES.contains(n)) {
        fail(&format!(
            "{}: override {other} is not one of {TERRAIN_OVERRIDES:?}, the only ones build.rs sets",
            path.display()
        ));
    }
    match names.len() {
        0 => false,
        n if n == TERRAIN_OVERRIDES.len() => true,
        _ => fail(&format!(
            "{}: declares {names:?}; a terrain shader declares all of {TERRAIN_OVERRIDES:?}",
            path.display()
        )),
    }
}

/// SPIR-V of a validated module; a terrain shader's overrides set to `variant`'s values first.
fn write_spirv(
    path: &Path,
    module: &naga::Module,
    info: &naga::valid::ModuleInfo,
    variant: Option<&TerrainBuild>,
) -> Vec<u8> {
    let mut constants = naga::back::PipelineConstants::default();
    if let Some(v) = variant {
        constants.insert(
            TERRAIN_OVERRIDES[0].to_string(),
            f64::from(u8::from(v.earth)),
        );
        constants.insert(
            TERRAIN_OVERRIDES[1].to_string(),
            f64::from(u8::from(v.clipmap)),
        );
    }
    let (module, info) =
        naga::back::pipeline_constants::process_overrides(module, info, None, &constants)
            .unwrap_or_else(|e| fail(&format!("{}: overrides: {e}", path.display())));
    let options = naga::back::spv::Options {
        lang_version: (1, 3),
        // Shaders are written in WebGPU clip space (y up); naga flips y for Vulkan.
        flags: naga::back::spv::WriterFlags::ADJUST_COORDINATE_SPACE
            | naga::back::spv::WriterFlags::LABEL_VARYINGS,
        // No binding map: naga then writes each resource's own @group/@binding.
        fake_missing_bindings: true,
        zero_initialize_workgroup_memory: workgroup_memory_init(path),
        ..Default::default()
    };
    let words = naga::back::spv::write_vec(&module, &info, &options, None).unwrap_or_else(|e| {
        fail(&format!(
            "{}: SPIR-V generation failed: {e}",
            path.display()
        ))
    });
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

/// A `Spirv { frame_uniform, frame_storage }` value from the files `{file}.spv` and, for a shader
/// that reads the frame's block, `{file}.frame_storage.spv`.
fn spirv_value(file: &str, has_storage: bool) -> String {
    let bytes = |name: String| format!("include_bytes!(concat!(env!(\"OUT_DIR\"), \"/{name}\"))");
    let storage = if has_storage {
        format!("Some({})", bytes(format!("{file}.frame_storage.spv")))
    } else {
        "None".to_string()
    };
    format!(
        "Spirv {{ frame_uniform: {}, frame_storage: {storage} }}",
        bytes(format!("{file}.spv"))
    )
}

/// The Rust item for one shader's SPIR-V: a [`spirv_value`] of `file`.
fn spirv_item(doc: &str, upper: &str, file: &str, has_storage: bool) -> String {
    format!(
        "/// SPIR-V of {doc}.\npub static {upper}_SPV: Spirv = {};",
        spirv_value(file, has_storage)
    )
}

/// The Rust item for a terrain shader's SPIR-V: `TerrainSpirv` with a [`spirv_value`] per
/// variant (`{file}.{variant}.spv`).
fn terrain_spirv_item(doc: &str, upper: &str, file: &str, has_storage: bool) -> String {
    let mut fields = String::new();
    for v in &TERRAIN_VARIANTS {
        let value = spirv_value(&format!("{file}.{}", v.name), has_storage);
        writeln!(fields, "    {}: {value},", v.name).unwrap();
    }
    format!(
        "/// SPIR-V of {doc}, per terrain variant.\npub static {upper}_SPV: TerrainSpirv = TerrainSpirv {{\n{fields}}};"
    )
}

fn fail(message: &str) -> ! {
    // cargo shows build-script stderr when the script fails; keep the first line self-contained.
    eprintln!("shader error: {message}");
    std::process::exit(1);
}

fn main() {
    println!("cargo:rerun-if-changed=src/gpu_constants.rs");
    println!("cargo:rerun-if-changed=shaders");
    println!("cargo:rerun-if-changed=shaders/include");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").unwrap());

    let mut prelude = String::from("// Generated from src/gpu_constants.rs by build.rs.\n");
    for (name, value) in gpu_constants::WGSL_CONSTANTS {
        let (ty, literal) = value.wgsl();
        writeln!(prelude, "const {name}: {ty} = {literal};").unwrap();
    }

    let mut shader_files: Vec<PathBuf> = std::fs::read_dir("shaders")
        .unwrap_or_else(|e| fail(&format!("shaders/: {e}")))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "wgsl"))
        .collect();
    shader_files.sort();

    let mut generated =
        String::from("// Generated by build.rs: SPIR-V and composed WGSL per shader.\n");
    for path in &shader_files {
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        let (source, map) = compose_wgsl(path, &prelude);
        std::fs::write(out_dir.join(format!("{stem}.composed.wgsl")), &source).unwrap();
        let has_storage = source.lines().any(|l| l.trim() == FRAME_UNIFORM);
        if !has_storage && source.contains("frame: Frame;") {
            fail(&format!(
                "{}: declares the frame block otherwise than `{FRAME_UNIFORM}`, so no storage variant can be built",
                path.display()
            ));
        }
        let uniform = parse_wgsl(path, &source, &map);
        let storage = has_storage
            .then(|| parse_wgsl(path, &source.replace(FRAME_UNIFORM, FRAME_STORAGE), &map));
        let terrain = has_terrain_overrides(path, &uniform.0);
        let variants: Vec<Option<&TerrainBuild>> = if terrain {
            TERRAIN_VARIANTS.iter().map(Some).collect()
        } else {
            vec![None]
        };
        for variant in variants {
            let file = match variant {
                Some(v) => format!("{stem}.{}", v.name),
                None => stem.clone(),
            };
            let bytes = write_spirv(path, &uniform.0, &uniform.1, variant);
            std::fs::write(out_dir.join(format!("{file}.spv")), bytes).unwrap();
            if let Some((module, info)) = &storage {
                let bytes = write_spirv(path, module, info, variant);
                std::fs::write(out_dir.join(format!("{file}.frame_storage.spv")), bytes).unwrap();
            }
        }
        let upper = stem.to_uppercase();
        let doc = format!("`shaders/{stem}.wgsl`");
        let item = if terrain {
            terrain_spirv_item(&doc, &upper, &stem, has_storage)
        } else {
            spirv_item(&doc, &upper, &stem, has_storage)
        };
        writeln!(
            generated,
            "/// `shaders/{stem}.wgsl` as compiled (constants and includes expanded).\npub static {upper}_WGSL: &str = include_str!(concat!(env!(\"OUT_DIR\"), \"/{stem}.composed.wgsl\"));\n{item}"
        )
        .unwrap();
    }
    compile_glsl(&out_dir, &mut generated);
    std::fs::write(out_dir.join("shaders.rs"), generated).unwrap();
}

/// Compiles every `shaders/glsl/*.<stage>` with glslangValidator; appends `<STEM>_<STAGE>_SPV`
/// and `<STEM>_<STAGE>_GLSL` (the composed source, before any variant's defines) to
/// `generated`. A file whose composed source names [`TERRAIN_OVERRIDES`] is a terrain shader:
/// compiled once per [`TERRAIN_VARIANTS`] entry with them `#define`d, as the WGSL's overrides
/// are set, into a `TerrainSpirv`.
fn compile_glsl(out_dir: &Path, generated: &mut String) {
    let dir = Path::new("shaders/glsl");
    let include_dir = dir.join("include");
    println!("cargo:rerun-if-changed={}", dir.display());
    println!("cargo:rerun-if-changed={}", include_dir.display());
    println!("cargo:rerun-if-env-changed={}", glsl::GLSLANG_ENV);
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| fail(&format!("{}: {e}", dir.display())))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    if files.is_empty() {
        return;
    }
    let glslang = glsl::Glslang::find().unwrap_or_else(|e| fail(&e));
    let prelude = glsl::prelude(
        gpu_constants::WGSL_CONSTANTS
            .iter()
            .map(|(name, value)| (*name, value.wgsl().1)),
    );
    let (major, minor, patch) = glslang.version;
    writeln!(
        generated,
        "// GLSL compiled by {} (glslang {major}.{minor}.{patch}).",
        glslang.exe.display()
    )
    .unwrap();
    for path in &files {
        let item = compile_glsl_file(&glslang, path, &include_dir, &prelude, out_dir);
        writeln!(generated, "{item}").unwrap();
    }
}

/// Compiles one GLSL file: every build of it (per terrain variant where it names
/// [`TERRAIN_OVERRIDES`], per frame block where it reads the frame), written to `out_dir`, the
/// builds at once (glslang runs single-threaded). Returns its Rust items.
fn compile_glsl_file(
    glslang: &glsl::Glslang,
    path: &Path,
    include_dir: &Path,
    prelude: &[String],
    out_dir: &Path,
) -> String {
    let (composed, sources) =
        glsl::compose(path, include_dir, prelude).unwrap_or_else(|e| fail(&e));
    for source in &sources {
        println!("cargo:rerun-if-changed={}", source.display());
    }
    let has_storage = composed.contains(GLSL_FRAME_STORAGE);
    let terrain = TERRAIN_OVERRIDES
        .iter()
        .any(|name| glsl_names(&composed, name));
    let name = path
        .file_name()
        .unwrap()
        .to_string_lossy()
        .replace('.', "_");
    let variants: Vec<Option<&TerrainBuild>> = if terrain {
        TERRAIN_VARIANTS.iter().map(Some).collect()
    } else {
        vec![None]
    };
    let mut builds = Vec::new();
    for variant in variants {
        let file = match variant {
            Some(v) => format!("{name}.{}", v.name),
            None => name.clone(),
        };
        let mut defines = prelude.to_vec();
        if let Some(v) = variant {
            defines.extend(glsl::terrain_defines(v.earth, v.clipmap));
        }
        if has_storage {
            let mut storage = defines.clone();
            storage.push(format!("#define {GLSL_FRAME_STORAGE} 1"));
            builds.push((format!("{file}.frame_storage"), storage));
        }
        builds.push((file, defines));
    }
    let warnings = compile_glsl_builds(glslang, path, include_dir, &builds, out_dir);
    for w in &warnings {
        println!("cargo:warning={}: {w}", path.display());
    }
    std::fs::write(out_dir.join(format!("{name}.glsl")), &composed).unwrap();
    let upper = name.to_uppercase();
    let doc = format!("`{}` (glslangValidator)", path.display());
    let item = if terrain {
        terrain_spirv_item(&doc, &upper, &name, has_storage)
    } else {
        spirv_item(&doc, &upper, &name, has_storage)
    };
    format!(
        "/// `{}` as compiled (constants and includes expanded).\npub static {upper}_GLSL: &str = include_str!(concat!(env!(\"OUT_DIR\"), \"/{name}.glsl\"));\n{item}",
        path.display()
    )
}

/// Every `(file, defines)` build of `path` at once, each to `out_dir/{file}.spv`; returns the
/// builds' warnings, each once.
fn compile_glsl_builds(
    glslang: &glsl::Glslang,
    path: &Path,
    include_dir: &Path,
    builds: &[(String, Vec<String>)],
    out_dir: &Path,
) -> Vec<String> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = builds
            .iter()
            .map(|(file, defines)| {
                scope.spawn(move || {
                    let work = out_dir.join("glsl").join(file);
                    let build = compile_glsl_build(glslang, path, include_dir, defines, &work);
                    std::fs::write(out_dir.join(format!("{file}.spv")), &build.spv).unwrap();
                    build.warnings
                })
            })
            .collect();
        let mut warnings: Vec<String> = handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect();
        warnings.sort();
        warnings.dedup();
        warnings
    })
}

/// One glslang build of `path` in its own work directory; fails the build on an error.
fn compile_glsl_build(
    glslang: &glsl::Glslang,
    path: &Path,
    include_dir: &Path,
    prelude: &[String],
    work: &Path,
) -> glsl::Compiled {
    std::fs::create_dir_all(work).unwrap();
    glsl::compile(glslang, path, include_dir, prelude, work).unwrap_or_else(|e| fail(&e))
}

/// Whether `source` uses `name` as an identifier (not as part of a longer one).
fn glsl_names(source: &str, name: &str) -> bool {
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    source.match_indices(name).any(|(i, _)| {
        let before = source[..i].chars().next_back();
        let after = source[i + name.len()..].chars().next();
        !before.is_some_and(ident) && !after.is_some_and(ident)
    })
}

//! The GLSL half of the shader build: the stages naga cannot compile (tessellation control and
//! evaluation; task and mesh) are written in GLSL under `shaders/glsl/` and compiled to SPIR-V
//! by Khronos' reference compiler, `glslangValidator` (Debian/Ubuntu package `glslang-tools`),
//! run as a command. WGSL stays the language of every stage naga handles.
//!
//! A GLSL shader is composed like the WGSL ones: after its `#version` line come a `#define`
//! for every constant of `src/gpu_constants.rs` (one source of truth for both languages), then
//! the file, with every `//!include NAME.glsl` line replaced by `shaders/glsl/include/NAME.glsl`.
//! `#line N "file"` directives (GL_GOOGLE_cpp_style_line_directive) keep the original file
//! names and lines, so glslang's own messages read `file:line: message`.
//!
//! Used by `build.rs` and, through `#[path]`, by `tests/glsl.rs` (which compiles broken and
//! mutated shaders with it), so it only uses `std` and reports problems as `Err(String)`.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// Environment variable naming the compiler executable (default: `glslangValidator` on PATH).
pub const GLSLANG_ENV: &str = "GLSLANG_VALIDATOR";

/// Oldest glslang that compiles every stage vkterrain uses (GL_EXT_mesh_shader came in 11.12).
pub const MIN_VERSION: (u32, u32) = (11, 12);

/// A GLSL stage by file extension: (extension, glslang `-S` name, extra target).
/// Task and mesh shaders need SPIR-V 1.4 (SPV_EXT_mesh_shader); everything else is built for
/// Vulkan 1.1 (SPIR-V 1.3, the version naga writes for the WGSL).
pub const STAGES: &[(&str, Option<&str>)] = &[
    ("vert", None),
    ("tesc", None),
    ("tese", None),
    ("geom", None),
    ("frag", None),
    ("comp", None),
    ("task", Some("spirv1.4")),
    ("mesh", Some("spirv1.4")),
];

/// The compiler found on this machine.
#[derive(Clone, Debug)]
pub struct Glslang {
    pub exe: PathBuf,
    /// (major, minor, patch) as `--version` prints it.
    pub version: (u32, u32, u32),
}

impl Glslang {
    /// `$GLSLANG_VALIDATOR` or `glslangValidator` from PATH, at least [`MIN_VERSION`].
    pub fn find() -> Result<Glslang, String> {
        let exe = std::env::var_os(GLSLANG_ENV)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from("glslangValidator"));
        let output = Command::new(&exe).arg("--version").output().map_err(|e| {
            format!(
                "cannot run {} ({e}): install Debian's glslang-tools (`make deps` does) or set {GLSLANG_ENV}",
                exe.display()
            )
        })?;
        let text = String::from_utf8_lossy(&output.stdout);
        let version = parse_version(&text).ok_or_else(|| {
            format!(
                "{}: no version in `--version` output {:?}",
                exe.display(),
                text.lines().next().unwrap_or("")
            )
        })?;
        if (version.0, version.1) < MIN_VERSION {
            return Err(format!(
                "{} is glslang {}.{}.{}; vkterrain needs {}.{} or newer (mesh shaders)",
                exe.display(),
                version.0,
                version.1,
                version.2,
                MIN_VERSION.0,
                MIN_VERSION.1
            ));
        }
        Ok(Glslang { exe, version })
    }
}

/// `Glslang Version: 11:12.0.0` -> (12, 0, 0): the part after the colon is the release.
fn parse_version(text: &str) -> Option<(u32, u32, u32)> {
    let line = text.lines().find(|l| l.starts_with("Glslang Version:"))?;
    let release = line.rsplit(':').next()?.trim();
    let mut parts = release.split('.').map(|p| p.trim().parse::<u32>().ok());
    Some((
        parts.next()??,
        parts.next()??,
        parts.next().flatten().unwrap_or(0),
    ))
}

/// One compiled GLSL shader.
#[derive(Debug)]
pub struct Compiled {
    pub spv: Vec<u8>,
    /// The source glslang compiled (prelude and includes expanded, `#line` directives in).
    pub composed: String,
    /// Every file it was composed from (for `cargo:rerun-if-changed`).
    pub sources: Vec<PathBuf>,
    /// glslang's warnings, one per line.
    pub warnings: Vec<String>,
}

/// The stage of a GLSL file from its extension, with its extra target environment.
pub fn stage_of(path: &Path) -> Option<(&'static str, Option<&'static str>)> {
    let ext = path.extension()?.to_str()?;
    STAGES.iter().find(|(e, _)| *e == ext).copied()
}

/// `path` composed with `prelude` (`#define` lines) after its `#version` line and its includes
/// from `include_dir` expanded, with `#line` directives naming the original files. Returns the
/// source and the files it read.
pub fn compose(
    path: &Path,
    include_dir: &Path,
    prelude: &[String],
) -> Result<(String, Vec<PathBuf>), String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    let mut lines = text.lines().enumerate();
    let version = loop {
        match lines.next() {
            Some((_, l)) if l.trim().is_empty() || l.trim_start().starts_with("//") => continue,
            Some((i, l)) if l.trim_start().starts_with("#version") => break (i, l.trim()),
            other => {
                let line = other.map_or(text.lines().count().max(1), |(i, _)| i + 1);
                return Err(format!(
                    "{}:{line}: the first statement must be #version",
                    path.display()
                ));
            }
        }
    };
    let mut out = format!(
        "{}\n#extension GL_GOOGLE_cpp_style_line_directive : require\n#line 1 \"{} (generated prelude)\"\n",
        version.1, "src/gpu_constants.rs"
    );
    for p in prelude {
        out.push_str(p);
        out.push('\n');
    }
    let mut sources = vec![path.to_path_buf()];
    out.push_str(&format!("#line {} \"{}\"\n", version.0 + 2, path.display()));
    append_lines(
        path,
        &mut lines.map(|(i, l)| (i + 1, l)),
        include_dir,
        &mut out,
        &mut sources,
        0,
    )?;
    Ok((out, sources))
}

/// Appends numbered `lines` of `path`, expanding includes.
fn append_lines(
    path: &Path,
    lines: &mut dyn Iterator<Item = (usize, &str)>,
    include_dir: &Path,
    out: &mut String,
    sources: &mut Vec<PathBuf>,
    depth: usize,
) -> Result<(), String> {
    for (number, line) in lines {
        let Some(name) = line.trim().strip_prefix("//!include ") else {
            out.push_str(line);
            out.push('\n');
            continue;
        };
        if depth >= 8 {
            return Err(format!(
                "{}:{number}: includes nest deeper than 8",
                path.display()
            ));
        }
        let inc = include_dir.join(name.trim());
        let text = std::fs::read_to_string(&inc).map_err(|e| {
            format!(
                "{}:{number}: cannot include {}: {e}",
                path.display(),
                inc.display()
            )
        })?;
        sources.push(inc.clone());
        out.push_str(&format!("#line 1 \"{}\"\n", inc.display()));
        append_lines(
            &inc,
            &mut text.lines().enumerate().map(|(i, l)| (i + 1, l)),
            include_dir,
            out,
            sources,
            depth + 1,
        )?;
        out.push_str(&format!("#line {} \"{}\"\n", number + 1, path.display()));
    }
    Ok(())
}

/// The names of a terrain variant's two settings, its world (the earth or the flat one) and its
/// source of heights (the clipmap or the single texture): WGSL overrides in
/// `shaders/include/terrain_common.wgsl`, `#define`s in the GLSL port.
pub const TERRAIN_SETTINGS: [&str; 2] = ["EARTH_WORLD", "CLIPMAP_HEIGHTS"];

/// The `#define`s that make a GLSL build one terrain variant's, as the WGSL's overrides do.
pub fn terrain_defines(earth: bool, clipmap: bool) -> [String; 2] {
    let [world, heights] = TERRAIN_SETTINGS;
    [
        format!("#define {world} {earth}"),
        format!("#define {heights} {clipmap}"),
    ]
}

/// The `#define` prelude for `(name, literal)` constants.
pub fn prelude<'a>(constants: impl IntoIterator<Item = (&'a str, String)>) -> Vec<String> {
    constants
        .into_iter()
        .map(|(name, literal)| format!("#define {name} {literal}"))
        .collect()
}

/// Composes `path` and compiles it with `glslang` (SPIR-V validation on), using `work_dir`
/// for the composed source and the SPIR-V. The error is glslang's first error as
/// `file:line: message`, followed by the rest of its report.
pub fn compile(
    glslang: &Glslang,
    path: &Path,
    include_dir: &Path,
    prelude: &[String],
    work_dir: &Path,
) -> Result<Compiled, String> {
    let (ext, extra_target) = stage_of(path).ok_or_else(|| {
        let known: Vec<&str> = STAGES.iter().map(|s| s.0).collect();
        format!(
            "{}: unknown GLSL stage (extension one of {})",
            path.display(),
            known.join(", ")
        )
    })?;
    let (composed, sources) = compose(path, include_dir, prelude)?;
    let stem = path
        .file_name()
        .map(|n| n.to_string_lossy().replace('.', "_"))
        .unwrap_or_default();
    let src = work_dir.join(format!("{stem}.composed.{ext}"));
    let spv = work_dir.join(format!("{stem}.spv"));
    std::fs::write(&src, &composed).map_err(|e| format!("{}: {e}", src.display()))?;
    let _ = std::fs::remove_file(&spv);
    let mut cmd = Command::new(&glslang.exe);
    cmd.args(["-V", "--target-env", "vulkan1.1"]);
    if let Some(t) = extra_target {
        cmd.args(["--target-env", t]);
    }
    cmd.args(["--spirv-val", "-S", ext, "-o"])
        .arg(&spv)
        .arg(&src);
    let output = cmd.output().map_err(|e| {
        format!(
            "{}: cannot run {}: {e}",
            path.display(),
            glslang.exe.display()
        )
    })?;
    let report = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    let errors: Vec<&str> = report
        .lines()
        .filter_map(|l| l.strip_prefix("ERROR: "))
        .filter(|l| !l.contains("compilation errors.") && !l.ends_with("compilation terminated "))
        .collect();
    if !output.status.success() || !errors.is_empty() {
        let first = errors
            .first()
            .map(|e| e.trim().to_string())
            .unwrap_or_else(|| format!("glslangValidator failed ({})", output.status));
        // Link-stage messages carry no file: name the shader.
        let first = if first.starts_with("Linking") || !first.contains(':') {
            format!("{}: {first}", path.display())
        } else {
            first
        };
        return Err(format!("{first}\n{}", report.trim_end()));
    }
    let warnings = report
        .lines()
        .filter_map(|l| l.strip_prefix("WARNING: "))
        .map(|l| l.trim().to_string())
        .collect();
    let spv = std::fs::read(&spv).map_err(|e| format!("{}: {e}", spv.display()))?;
    if spv.len() < 20 || spv.len() % 4 != 0 || spv[..4] != 0x0723_0203u32.to_le_bytes() {
        return Err(format!("{}: glslang wrote no valid SPIR-V", path.display()));
    }
    Ok(Compiled {
        spv,
        composed,
        sources,
        warnings,
    })
}

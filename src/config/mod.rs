//! Configuration (`config/*.toml`): device, render size, data set, LOD method, scenario, output.
//!
//! The top of the library: each section's type lives next to what it configures
//! (`driver::GpuOptions`, `render::settings`, `dataset::settings`, `lod::MethodConfig`,
//! `clipmap::ClipmapSettings`, `output::ring::RingConfig`,
//! `service::settings`), and this module only assembles them, checks what spans
//! sections, and opens what a configuration names ([`open`]). No lower module imports it.
//!
//! Every field has a default, so an empty file is a valid configuration. Relative paths in a
//! config file are relative to the file's directory. Values are checked in [`Config::validate`]
//! before anything is created, so bad input never leaves partial output behind.

pub mod open;

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::clipmap::ClipmapSettings;
use crate::dataset::settings::DatasetConfig;
use crate::driver::GpuOptions;
use crate::error::{Error, Result};
use crate::lod::{MethodConfig, MethodKind};
pub use crate::output::ring::RingConfig;
use crate::render::settings::RenderSettings;
pub use crate::service::{ServiceConfig, ZenohSettings};

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    pub device: GpuOptions,
    pub render: RenderSettings,
    pub dataset: DatasetConfig,
    /// The LOD method and its settings (`name` selects it).
    pub method: MethodConfig,
    pub scenario: ScenarioConfig,
    /// Heights through the chunked clipmap (`dataset.kind = "tiles"` or `"xyz"`).
    pub clipmap: ClipmapSettings,
    pub output: OutputConfig,
    pub ring: RingConfig,
    pub service: ServiceConfig,
    /// Frames, control and status over Zenoh (`serve`).
    pub zenoh: ZenohSettings,
    /// Directory relative paths are resolved against (the config file's directory).
    #[serde(skip)]
    pub base_dir: PathBuf,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
#[derive(Default)]
pub struct ScenarioConfig {
    /// Scenario file; none: the built-in default flight (`config/scenarios/default.toml`,
    /// compiled into the binary).
    pub path: Option<PathBuf>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutputConfig {
    pub dir: PathBuf,
    /// Frame indices written as PNG (negative: counted from the end, -1 = last frame).
    pub png_frames: Vec<i64>,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            dir: PathBuf::from("out"),
            png_frames: vec![0, -1],
        }
    }
}

impl Default for Config {
    fn default() -> Self {
        Config {
            device: Default::default(),
            render: Default::default(),
            dataset: Default::default(),
            method: Default::default(),
            scenario: Default::default(),
            clipmap: Default::default(),
            output: Default::default(),
            ring: Default::default(),
            service: Default::default(),
            zenoh: Default::default(),
            // No config file: relative paths are relative to the working directory.
            base_dir: PathBuf::new(),
        }
    }
}

impl Config {
    /// Reads a config file (no file: the built-in defaults).
    pub fn load(path: Option<&Path>) -> Result<Self> {
        let Some(path) = path else {
            return Ok(Config::default());
        };
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let mut config: Config = toml::from_str(&text).map_err(|e| Error::toml(path, &text, &e))?;
        config.base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        config.validate().map_err(|e| Error::Config {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        Ok(config)
    }

    /// A path from the config, resolved against the config file's directory.
    /// `config/../out` comes back as `out`: `..` is folded lexically (symbolic links in the
    /// config's own path are not followed), so messages and summaries print clean paths.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            fold_parents(&self.base_dir.join(p))
        }
    }

    /// Checks values that serde cannot (ranges, names), section by section and across them.
    pub fn validate(&self) -> Result<()> {
        self.render.validate()?;
        self.dataset.validate()?;
        self.method.validate()?;
        self.clipmap.validate()?;
        self.validate_service()?;
        self.validate_clipmap_use()
    }

    fn validate_service(&self) -> Result<()> {
        self.ring.validate()?;
        self.service.validate()?;
        self.zenoh.validate()
    }

    /// The clipmap streams a tile pyramid to methods that read heights through set 0.
    fn validate_clipmap_use(&self) -> Result<()> {
        if !self.clipmap.enabled {
            if self.dataset.streams_only() {
                return Err(Error::invalid(
                    "dataset.kind",
                    "\"xyz\" tiles stream through the clipmap: set [clipmap] enabled = true",
                ));
            }
            return Ok(());
        }
        let lod = match &self.dataset {
            DatasetConfig::Tiles(tiles) => tiles.lod,
            DatasetConfig::Xyz(_) => None,
            _ => {
                return Err(Error::invalid(
                    "clipmap.enabled",
                    format!(
                        "needs dataset.kind = \"tiles\" (a vkterrain preprocess data set) or \"xyz\", not {:?}",
                        self.dataset.kind_name()
                    ),
                ));
            }
        };
        if lod.is_some_and(|l| l != 0) {
            return Err(Error::invalid(
                "clipmap.enabled",
                "the clipmap streams every level; dataset.lod must be 0 or absent",
            ));
        }
        if self.method.kind() == MethodKind::Pgm {
            return Err(Error::invalid(
                "clipmap.enabled",
                "method pgm needs the whole height map in memory (its own height texture); use udlod or brute with the clipmap, or set clipmap.enabled = false",
            ));
        }
        Ok(())
    }
}

/// `a/b/../c` -> `a/c`; a leading `..` (or one past the root) is kept.
fn fold_parents(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out: Vec<Component<'_>> = Vec::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir if matches!(out.last(), Some(Component::Normal(_))) => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    if out.is_empty() {
        PathBuf::from(".")
    } else {
        out.iter().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::fold_parents;
    use std::path::Path;

    #[test]
    fn parents_fold_lexically() {
        for (a, b) in [
            ("config/../out", "out"),
            ("config/./../../shared/x", "../shared/x"),
            ("/etc/../tmp", "/tmp"),
            ("a/b/..", "a"),
            ("a/..", "."),
            ("../x", "../x"),
        ] {
            assert_eq!(fold_parents(Path::new(a)), Path::new(b), "{a}");
        }
    }
}

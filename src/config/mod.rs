//! Configuration (`config/*.toml`): device, render size, data set, LOD method, scenario, output.
//!
//! The top of the library: each section's type lives next to what it configures
//! (`driver::GpuOptions`, `render::settings`, `dataset::settings`, `lod::MethodConfig`,
//! `clipmap::ClipmapSettings`), and this module only assembles them, checks what spans
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
use crate::render::settings::RenderSettings;

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

/// The shared-memory ring `vkterrain serve` publishes into (`docs/ring.md`).
#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RingConfig {
    /// Segment name: `/dev/shm/<name>`, 1..=200 characters from `[A-Za-z0-9._-]`.
    pub name: String,
    /// Slots in the ring (2..=64): how far a consumer may fall behind before it skips frames.
    pub slots: u32,
    /// Group allowed to read the ring (mode 0640); none: owner only (mode 0600).
    pub group: Option<String>,
    /// Leave the segment (marked closed) in place after shutdown.
    pub keep_segment: bool,
}

impl Default for RingConfig {
    fn default() -> Self {
        RingConfig {
            name: "vkterrain".into(),
            slots: 4,
            group: None,
            keep_segment: false,
        }
    }
}

/// `vkterrain serve`: control channel, status file, pacing.
#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServiceConfig {
    /// Unix datagram socket for live camera control (JSON messages); none: scripted only.
    pub control: Option<PathBuf>,
    /// JSON status file, rewritten atomically every `status_interval_s`.
    pub status_file: Option<PathBuf>,
    pub status_interval_s: f64,
    /// Frame-rate cap (0: as fast as the device renders).
    pub max_fps: f64,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        ServiceConfig {
            control: None,
            status_file: None,
            status_interval_s: 1.0,
            max_fps: 0.0,
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
        crate::output::ring::validate_name(&self.ring.name)?;
        if !(2..=64).contains(&self.ring.slots) {
            return Err(Error::invalid(
                "ring.slots",
                format!("{} is outside 2..=64", self.ring.slots),
            ));
        }
        let s = &self.service;
        if !(s.status_interval_s.is_finite() && (0.05..=3600.0).contains(&s.status_interval_s)) {
            return Err(Error::invalid(
                "service.status_interval_s",
                format!("{} is outside 0.05..=3600", s.status_interval_s),
            ));
        }
        if !(s.max_fps.is_finite() && (0.0..=10000.0).contains(&s.max_fps)) {
            return Err(Error::invalid(
                "service.max_fps",
                format!("{} is outside 0..=10000", s.max_fps),
            ));
        }
        Ok(())
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

//! The data set a configuration names (`[dataset]`; `kind` selects the variant and is
//! required whenever the section is present, so a `path` without a `kind` is an error rather
//! than a silent procedural render).

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::{Heightmap, MAX_SIDE, load_png16, procedural, tiles};
use crate::error::{Error, Result};

#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum DatasetConfig {
    /// Generated in code (the embedded default: no files needed).
    Procedural(ProceduralConfig),
    /// A 16-bit greyscale PNG height map (and an optional albedo image).
    Png16(Png16Config),
    /// A tile pyramid made by `vkterrain preprocess` (`docs/dataset-format.md`).
    Tiles(TilesConfig),
}

#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProceduralConfig {
    /// Samples per side.
    pub size: u32,
    pub seed: u64,
    /// Sample spacing in metres.
    pub spacing: f64,
}

#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Png16Config {
    /// The height PNG (relative to the config file).
    pub path: PathBuf,
    /// Metres between samples.
    #[serde(default = "default_spacing")]
    pub spacing: f64,
    /// Metres per PNG unit.
    #[serde(default = "one")]
    pub vertical_scale: f64,
    /// An albedo image covering the same extent.
    #[serde(default)]
    pub albedo: Option<PathBuf>,
}

#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TilesConfig {
    /// A `vkterrain preprocess` output directory (relative to the config file).
    pub path: PathBuf,
    /// The level to load whole when the clipmap is off; none: the finest level that fits.
    #[serde(default)]
    pub lod: Option<u32>,
}

fn default_spacing() -> f64 {
    30.0
}

fn one() -> f64 {
    1.0
}

impl Default for ProceduralConfig {
    fn default() -> Self {
        let p = procedural::ProceduralParams::default();
        ProceduralConfig {
            size: p.size,
            seed: p.seed,
            spacing: p.spacing,
        }
    }
}

impl Default for DatasetConfig {
    fn default() -> Self {
        DatasetConfig::Procedural(ProceduralConfig::default())
    }
}

impl DatasetConfig {
    /// The tile pyramid's directory, for a `tiles` data set.
    pub fn tiles_path(&self) -> Option<&Path> {
        match self {
            DatasetConfig::Tiles(t) => Some(&t.path),
            _ => None,
        }
    }

    pub fn kind_name(&self) -> &'static str {
        match self {
            DatasetConfig::Procedural(_) => "procedural",
            DatasetConfig::Png16(_) => "png16",
            DatasetConfig::Tiles(_) => "tiles",
        }
    }

    /// Checks what serde cannot.
    pub fn validate(&self) -> Result<()> {
        let positive = |what: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(what, format!("{v} must be positive")))
            }
        };
        match self {
            DatasetConfig::Procedural(p) => {
                if !(2..=MAX_SIDE).contains(&p.size) {
                    return Err(Error::invalid(
                        "dataset.size",
                        format!("{} is outside 2..={MAX_SIDE}", p.size),
                    ));
                }
                positive("dataset.spacing", p.spacing)
            }
            DatasetConfig::Png16(p) => {
                positive("dataset.spacing", p.spacing)?;
                positive("dataset.vertical_scale", p.vertical_scale)
            }
            DatasetConfig::Tiles(_) => Ok(()),
        }
    }

    /// Loads the whole height grid; relative paths are resolved with `resolve`.
    pub fn load(&self, resolve: impl Fn(&Path) -> PathBuf) -> Result<Heightmap> {
        match self {
            DatasetConfig::Procedural(p) => procedural::generate(&procedural::ProceduralParams {
                size: p.size,
                seed: p.seed,
                spacing: p.spacing,
                ..Default::default()
            }),
            DatasetConfig::Png16(p) => load_png16(
                &resolve(&p.path),
                p.spacing,
                p.vertical_scale,
                p.albedo.as_deref().map(&resolve).as_deref(),
            ),
            DatasetConfig::Tiles(t) => {
                tiles::load(&resolve(&t.path), t.lod, tiles::DEFAULT_MAX_SAMPLES)
            }
        }
    }
}

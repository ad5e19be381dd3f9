//! The data set a configuration names (`[dataset]`; `kind` selects the variant and is
//! required whenever the section is present, so a `path` without a `kind` is an error rather
//! than a silent procedural render).

use std::path::{Path, PathBuf};

use serde::Deserialize;

use std::sync::Arc;

use super::xyz::{XyzPyramid, XyzSettings};
use super::{DiskStore, Heightmap, MAX_SIDE, NodeStore, load_png16, procedural, tiles};
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
    /// Live Terrarium / Mapbox terrain-RGB tiles (a `z/x/y.png` directory or an HTTP
    /// template), streamed through the clipmap (`docs/dataset-format.md` "XYZ terrain tiles").
    Xyz(XyzSettings),
}

#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProceduralConfig {
    /// Samples per side.
    pub size: u32,
    pub seed: u64,
    /// Sample spacing in metres.
    pub spacing: f64,
    /// The terrain's character (`classic`, the tests' terrain, or `alpine`).
    pub style: procedural::Style,
    /// Height of the tallest possible peak in metres.
    pub max_height: f64,
    /// Wavelength of the largest features in metres (larger: smoother terrain).
    pub feature_size: f64,
    /// Where sample (0, 0) lies on the earth; none: a flat world (`docs/coordinates.md`).
    pub anchor: Option<Anchor>,
}

impl ProceduralConfig {
    /// The generator's parameters.
    pub fn params(&self) -> procedural::ProceduralParams {
        procedural::ProceduralParams {
            size: self.size,
            seed: self.seed,
            spacing: self.spacing,
            max_height: self.max_height,
            feature_size: self.feature_size,
            style: self.style,
        }
    }
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
    /// Where sample (0, 0) lies on the earth; none: a flat world (`docs/coordinates.md`).
    #[serde(default)]
    pub anchor: Option<Anchor>,
}

#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TilesConfig {
    /// A `vkterrain preprocess` output directory (relative to the config file).
    pub path: PathBuf,
    /// The level to load whole when the clipmap is off; none: the finest level that fits.
    #[serde(default)]
    pub lod: Option<u32>,
    /// For a data set without georeferencing (a procedural or PNG pyramid): where sample
    /// (0, 0) lies on the earth. A georeferenced data set places itself; an anchor is then an
    /// error.
    #[serde(default)]
    pub anchor: Option<Anchor>,
}

/// `[dataset] anchor = { lat_deg = .., lon_deg = .. }`: the WGS84 position of sample (0, 0) of a
/// data set without georeferencing, at height 0 on the ellipsoid. The world frame is then the
/// east-north-up frame there, and the earth's curvature applies.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Anchor {
    pub lat_deg: f64,
    pub lon_deg: f64,
}

impl Anchor {
    /// Latitude within [-90, 90] (poles excluded: no east there), longitude within [-180, 180].
    pub fn check(&self) -> Result<()> {
        let (lat, lon) = (self.lat_deg, self.lon_deg);
        if !(lat.is_finite() && lat.abs() < 90.0 && lon.is_finite() && lon.abs() <= 180.0) {
            return Err(Error::invalid(
                "dataset.anchor",
                format!(
                    "latitude {lat} deg / longitude {lon} deg: need -90 < lat < 90, -180 <= lon <= 180"
                ),
            ));
        }
        Ok(())
    }
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
            style: p.style,
            max_height: p.max_height,
            feature_size: p.feature_size,
            anchor: None,
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
            DatasetConfig::Xyz(_) => "xyz",
        }
    }

    /// The configured `anchor` (data sets without georeferencing).
    pub fn anchor(&self) -> Option<Anchor> {
        match self {
            DatasetConfig::Procedural(p) => p.anchor,
            DatasetConfig::Png16(p) => p.anchor,
            DatasetConfig::Tiles(t) => t.anchor,
            DatasetConfig::Xyz(_) => None,
        }
    }

    /// Checks what serde cannot.
    pub fn validate(&self) -> Result<()> {
        if let Some(a) = self.anchor() {
            a.check()?;
        }
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
                positive("dataset.spacing", p.spacing)?;
                positive("dataset.max_height", p.max_height)?;
                positive("dataset.feature_size", p.feature_size)
            }
            DatasetConfig::Png16(p) => {
                positive("dataset.spacing", p.spacing)?;
                positive("dataset.vertical_scale", p.vertical_scale)
            }
            DatasetConfig::Tiles(_) => Ok(()),
            DatasetConfig::Xyz(x) => x.check(),
        }
    }

    /// Whether the data set can only be read node by node (through the clipmap).
    pub fn streams_only(&self) -> bool {
        matches!(self, DatasetConfig::Xyz(_))
    }

    /// The node store behind a pyramid data set (`tiles`: the directory, `xyz`: live tiles),
    /// read node by node by the clipmap; relative paths are resolved with `resolve`.
    pub fn open_store(&self, resolve: impl Fn(&Path) -> PathBuf) -> Result<Arc<dyn NodeStore>> {
        match self {
            DatasetConfig::Tiles(t) => Ok(Arc::new(DiskStore::open(&resolve(&t.path))?)),
            DatasetConfig::Xyz(x) => {
                let mut x = x.clone();
                x.cache_dir = x.cache_dir.as_deref().map(&resolve);
                if !(x.source.starts_with("http://") || x.source.starts_with("https://")) {
                    x.source = resolve(Path::new(&x.source)).display().to_string();
                }
                Ok(Arc::new(XyzPyramid::open(&x)?))
            }
            other => Err(Error::invalid(
                "dataset.kind",
                format!(
                    "{:?} is not a tile pyramid: the clipmap needs kind = \"tiles\" (a vkterrain preprocess data set) or \"xyz\"",
                    other.kind_name()
                ),
            )),
        }
    }

    /// Loads the whole height grid; relative paths are resolved with `resolve`. A non-square
    /// grid is resampled to square metres (the flat world; [`DatasetConfig::load_as`]).
    pub fn load(&self, resolve: impl Fn(&Path) -> PathBuf) -> Result<Heightmap> {
        self.load_as(resolve, tiles::LoadGrid::SquareMetres)
    }

    /// [`DatasetConfig::load`] with a non-square (geographic) grid loaded as `grid` says.
    pub fn load_as(
        &self,
        resolve: impl Fn(&Path) -> PathBuf,
        grid: tiles::LoadGrid,
    ) -> Result<Heightmap> {
        match self {
            DatasetConfig::Procedural(p) => procedural::generate(&p.params()),
            DatasetConfig::Png16(p) => load_png16(
                &resolve(&p.path),
                p.spacing,
                p.vertical_scale,
                p.albedo.as_deref().map(&resolve).as_deref(),
            ),
            DatasetConfig::Tiles(t) => {
                tiles::load_as(&resolve(&t.path), t.lod, tiles::DEFAULT_MAX_SAMPLES, grid)
            }
            DatasetConfig::Xyz(_) => Err(Error::invalid(
                "dataset.kind",
                "\"xyz\" tiles stream through the clipmap: set [clipmap] enabled = true (or build a data set with `vkterrain preprocess --xyz`)",
            )),
        }
    }
}

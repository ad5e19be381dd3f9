//! Without the `gdal` feature: the same interface as `gdal_in`, every file input a one-line
//! error (build with default features, which need Debian's `libgdal-dev`, to read DEM files).

use std::path::{Path, PathBuf};

use super::source::Raster;
use crate::error::{Error, Result};

/// How to read the inputs (see the GDAL build).
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    pub spacing: Option<f64>,
    pub crs: Option<String>,
    pub memory_budget: Option<u64>,
}

pub fn init() {}

pub fn read(paths: &[PathBuf], _opts: &ReadOptions) -> Result<Raster> {
    let what = paths
        .first()
        .map(|p| p.display().to_string())
        .unwrap_or_else(|| "preprocess".into());
    Err(Error::invalid(
        what,
        "this vkterrain was built without GDAL (--no-default-features): it cannot read DEM files",
    ))
}

pub fn image_transform(_path: &Path) -> Option<[f64; 6]> {
    None
}

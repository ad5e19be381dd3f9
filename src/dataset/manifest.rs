//! `manifest.json`: the versioned description of a tiled data set (see
//! `docs/dataset-format.md`). Written last, so a directory without it is not a data set.

use serde::{Deserialize, Serialize};

use super::source::Georef;

pub const FORMAT: &str = "vkterrain-chunked-clipmap";
pub const VERSION: u32 = 1;
pub const FILE_NAME: &str = "manifest.json";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub version: u32,
    /// Source description.
    pub name: String,
    /// Level-0 samples.
    pub width: u64,
    pub height: u64,
    /// Metres between level-0 samples, `[x east, y north]`.
    pub spacing: [f64; 2],
    /// Metres from the first to the last sample, `[x, y]`.
    pub extent: [f64; 2],
    pub georef: Option<Georef>,
    pub center_size: u32,
    pub border_size: u32,
    pub levels: Vec<LevelInfo>,
    pub layers: Layers,
    /// Minimum and maximum height in metres over all level-0 samples.
    pub height_range: [f32; 2],
    pub voids_filled: u64,
    /// `real`, `procedural` or `amplified` (real DEM plus procedural detail below its
    /// resolution).
    pub content: String,
    pub provenance: Vec<String>,
    pub created_by: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevelInfo {
    pub lod: u32,
    /// Valid samples at this level (`ceil(width / 2^lod)`).
    pub width: u64,
    pub height: u64,
    pub nodes_x: u32,
    pub nodes_y: u32,
    /// File name relative to the data set directory.
    pub file: String,
    pub record_size: u64,
    pub bytes: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Layers {
    /// Always `f32le`: metres, exact for every integer source and for all box averages.
    pub height: String,
    /// Per-texel `u8`, 1 = void in the source and filled.
    pub void_mask: bool,
    /// `rgba8_srgb` when imagery was given.
    pub albedo: Option<String>,
}

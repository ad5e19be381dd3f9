//! `manifest.json`: the versioned description of a tiled data set (see
//! `docs/dataset-format.md`). Written last, so a directory without it is not a data set.
//! [`Manifest::parse`] checks every field against the layout it implies before anything is
//! read or allocated from it.

use serde::{Deserialize, Serialize};

use super::crs::Georef;
use super::pyramid::{LEVEL_HEADER, LayerSet, Layout, MAX_SIDE_SAMPLES};
use super::stats::TileStats;
use crate::error::{Error, Result};

pub const FORMAT: &str = "vkterrain-chunked-clipmap";
/// 2: CRS as WKT2 + authority, sample-to-CRS affine map, vertical datum, nodata, stored tile
/// statistics. Version 1 data sets are refused with the command that rebuilds them.
pub const VERSION: u32 = 2;
pub const FILE_NAME: &str = "manifest.json";
/// Largest manifest read (a real one is a few kB).
pub const MAX_BYTES: u64 = 4 << 20;
/// Plausible ground spacing of level-0 samples, metres.
pub const SPACING_RANGE_M: (f64, f64) = (1e-3, 1e6);

/// Vertical datums vkterrain names (`vertical_datum`); anything else is kept as the CRS says.
pub mod datum {
    /// Orthometric heights above the EGM96 geoid (SRTM).
    pub const EGM96: &str = "egm96";
    pub const EGM2008: &str = "egm2008";
    /// Heights above the WGS84 ellipsoid.
    pub const ELLIPSOID: &str = "ellipsoid";
    /// Heights above "sea level" of an unstated datum (e.g. web terrain tiles).
    pub const UNKNOWN: &str = "unknown";
    /// Not on the earth: procedural terrain, PNG height maps without georeferencing.
    pub const LOCAL: &str = "local";
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub version: u32,
    /// Source description.
    pub name: String,
    /// Level-0 samples.
    pub width: u64,
    pub height: u64,
    /// Local metres between level-0 samples `[x east, y north]` (the flat approximation the
    /// renderer uses until it renders native grids; `docs/dataset-format.md` says how it is
    /// derived from the CRS).
    pub spacing: [f64; 2],
    /// `spacing` times `(samples - 1)`: metres from the first to the last sample.
    pub extent: [f64; 2],
    /// The native grid: CRS and sample-to-CRS map (none for procedural and bare PNG data).
    pub georef: Option<Georef>,
    /// Datum of the heights: see [`datum`].
    pub vertical_datum: String,
    /// Source value that marked voids (e.g. -32768), if the source declared one.
    pub nodata: Option<f64>,
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
    /// What looked wrong in the source (printed by preprocess too).
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Stored UDLOD tile statistics, one file per tile size.
    #[serde(default)]
    pub tile_stats: Vec<StatsInfo>,
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
    /// File name relative to the data set directory (always `L{lod}.bin`).
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

/// One stored statistics file (`dataset::stats`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StatsInfo {
    /// Quads per tile side (UDLOD's `grid_size`).
    pub grid_size: u32,
    /// Always `stats-g{grid_size}.bin`.
    pub file: String,
    pub bytes: u64,
}

/// File name of the statistics for `grid_size`.
pub fn stats_file(grid_size: u32) -> String {
    format!("stats-g{grid_size}.bin")
}

/// File name of level `lod`.
pub fn level_file(lod: u32) -> String {
    format!("L{lod}.bin")
}

impl Manifest {
    /// Parses and checks a manifest; `what` names it in errors. An older version is refused
    /// with the command that rebuilds the data set.
    pub fn parse(text: &str, what: &str) -> Result<Self> {
        let bad = |m: String| Error::invalid(what, m);
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| bad(format!("bad manifest: {e}")))?;
        let format = value.get("format").and_then(|v| v.as_str()).unwrap_or("");
        let version = value.get("version").and_then(|v| v.as_u64());
        if format != FORMAT {
            return Err(bad(format!(
                "format {format:?} is not {FORMAT:?}: not a vkterrain data set"
            )));
        }
        match version {
            Some(v) if v == VERSION as u64 => {}
            Some(v) if v < VERSION as u64 => {
                return Err(bad(format!(
                    "data set format version {v} is older than this vkterrain's {VERSION}: rebuild it with `vkterrain preprocess` (see its provenance for the inputs)"
                )));
            }
            other => {
                return Err(bad(format!(
                    "data set format version {other:?} is not supported (this vkterrain reads version {VERSION})"
                )));
            }
        }
        let m: Manifest =
            serde_json::from_value(value).map_err(|e| bad(format!("bad manifest: {e}")))?;
        m.check(what)?;
        Ok(m)
    }

    /// The layout and layers the manifest implies, after [`Manifest::check`].
    pub fn layout(&self) -> Result<(Layout, LayerSet)> {
        Ok((
            Layout::new(self.width, self.height, self.center_size, self.border_size)?,
            LayerSet {
                mask: self.layers.void_mask,
                albedo: self.layers.albedo.is_some(),
            },
        ))
    }

    /// Every field against the layout it implies: sizes, spacing, georeferencing, level and
    /// statistics entries (file names included: nothing outside the data set).
    pub fn check(&self, what: &str) -> Result<()> {
        self.check_grid(what)?;
        self.check_metadata(what)?;
        self.check_levels(what)?;
        self.check_stats(what)
    }

    /// Level 0's size, spacing and extent.
    fn check_grid(&self, what: &str) -> Result<()> {
        let bad = |m: String| Err(Error::invalid(what, m));
        let (w, h) = (self.width, self.height);
        if !(2..=MAX_SIDE_SAMPLES).contains(&w) || !(2..=MAX_SIDE_SAMPLES).contains(&h) {
            return bad(format!(
                "level 0 of {w}x{h} samples is outside 2..={MAX_SIDE_SAMPLES} per side"
            ));
        }
        let (lo, hi) = SPACING_RANGE_M;
        for s in self.spacing {
            if !(s.is_finite() && (lo..=hi).contains(&s)) {
                return bad(format!(
                    "sample spacing {:?} m is not within {lo}..{hi} m",
                    self.spacing
                ));
            }
        }
        for (k, (e, s)) in self.extent.iter().zip(self.spacing).enumerate() {
            let n = if k == 0 { w } else { h };
            let want = (n - 1) as f64 * s;
            if !(e.is_finite() && (e - want).abs() <= 1e-6 * want.max(1.0)) {
                return bad(format!(
                    "extent {:?} m disagrees with {w}x{h} samples at {:?} m",
                    self.extent, self.spacing
                ));
            }
        }
        Ok(())
    }

    /// Georeferencing, vertical datum, no-data value, content, height range and layers.
    fn check_metadata(&self, what: &str) -> Result<()> {
        let bad = |m: String| Err(Error::invalid(what, m));
        let (w, h) = (self.width, self.height);
        if let Some(g) = &self.georef {
            g.check(what, w, h)?;
        }
        if self.vertical_datum.is_empty() || self.vertical_datum.len() > 200 {
            return bad("vertical_datum is empty or too long".into());
        }
        if self.nodata.is_some_and(|v| v.is_infinite()) {
            return bad(format!("nodata {:?} is infinite", self.nodata));
        }
        if !matches!(self.content.as_str(), "real" | "procedural" | "amplified") {
            return bad(format!("content {:?} is unknown", self.content));
        }
        let [hlo, hhi] = self.height_range;
        if !(hlo.is_finite() && hhi.is_finite() && hlo <= hhi) {
            return bad(format!(
                "height range {:?} is not an interval",
                self.height_range
            ));
        }
        if self.layers.height != "f32le"
            || self
                .layers
                .albedo
                .as_deref()
                .is_some_and(|a| a != "rgba8_srgb")
        {
            return bad(format!("layers {:?} are not supported", self.layers));
        }
        Ok(())
    }

    /// Each level's entry (file, sizes, nodes, record size) against the layout.
    fn check_levels(&self, what: &str) -> Result<()> {
        let bad = |m: String| Err(Error::invalid(what, m));
        let (layout, layers) = self.layout()?;
        if layout.levels() as usize != self.levels.len() {
            return bad(format!(
                "{} levels listed, the layout has {}",
                self.levels.len(),
                layout.levels()
            ));
        }
        for (i, l) in self.levels.iter().enumerate() {
            let lod = i as u32;
            let (lw, lh) = layout.level_size(lod);
            let (nx, ny) = layout.nodes(lod);
            let size = layout.record_size(layers);
            let want = LevelInfo {
                lod,
                width: lw,
                height: lh,
                nodes_x: nx,
                nodes_y: ny,
                file: level_file(lod),
                record_size: size,
                bytes: LEVEL_HEADER + nx as u64 * ny as u64 * size,
            };
            if l.file != want.file {
                return bad(format!(
                    "level {lod} file {:?} is not {:?}: manifest entries must name files inside the data set",
                    l.file, want.file
                ));
            }
            if *l != want {
                return bad(format!(
                    "level {lod} entry disagrees with the layout ({} samples, {}x{} nodes of {} bytes expected)",
                    format_args!("{lw}x{lh}"),
                    nx,
                    ny,
                    size
                ));
            }
        }
        Ok(())
    }

    /// The statistics entries: at most 64, each file inside the data set and of a stored size.
    fn check_stats(&self, what: &str) -> Result<()> {
        let bad = |m: String| Err(Error::invalid(what, m));
        let (w, h) = (self.width, self.height);
        if self.tile_stats.len() > 64 {
            return bad(format!("{} statistics entries", self.tile_stats.len()));
        }
        for s in &self.tile_stats {
            if s.file != stats_file(s.grid_size) {
                return bad(format!(
                    "statistics file {:?} is not {:?}: manifest entries must name files inside the data set",
                    s.file,
                    stats_file(s.grid_size)
                ));
            }
            // With level 0's tiles or without (`preprocess::FINEST_STORED_FROM_GRID`); the
            // file's header says which, and its reader checks its length against that.
            let with = TileStats::stored_size(w as u32, h as u32, s.grid_size, true)?;
            let without = TileStats::stored_size(w as u32, h as u32, s.grid_size, false)?;
            if s.bytes != with && s.bytes != without {
                return bad(format!(
                    "statistics for grid size {} list {} bytes, expected {with} (or {without} without level 0's tiles)",
                    s.grid_size, s.bytes
                ));
            }
        }
        Ok(())
    }
}

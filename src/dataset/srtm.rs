//! SRTM `.hgt` / `.hgt.zip` tiles and their mosaics.
//!
//! A tile is a square of big-endian int16 heights in metres, row 0 = north, void = -32768;
//! 3601x3601 (SRTM1, 1") or 1201x1201 (SRTM3, 3"), the file size decides. The file name is the
//! south-west corner (`N41E001`); the tile covers one degree and neighbouring tiles share their
//! edge row/column.

use std::io::Read;
use std::path::{Path, PathBuf};

use super::source::{Georef, Raster, geographic_spacing};
use crate::error::{Error, Result};

pub const VOID: i16 = -32768;

/// One decoded tile.
#[derive(Clone, Debug)]
pub struct Tile {
    pub path: PathBuf,
    /// South-west corner, whole degrees.
    pub lat: i32,
    pub lon: i32,
    /// Samples per side (1201 or 3601).
    pub side: u32,
    /// Row-major, row 0 = **north** as in the file.
    pub samples: Vec<i16>,
}

fn bad(path: &Path, msg: impl Into<String>) -> Error {
    Error::invalid(path.display().to_string(), msg)
}

/// Parses `N41E001` (any case) from a file name such as `N41E001.hgt.zip`.
pub fn parse_name(path: &Path) -> Result<(i32, i32)> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default()
        .to_ascii_uppercase();
    let stem = name.split('.').next().unwrap_or_default();
    let b = stem.as_bytes();
    let ok = b.len() == 7
        && matches!(b[0], b'N' | b'S')
        && matches!(b[3], b'E' | b'W')
        && b[1..3].iter().chain(&b[4..7]).all(u8::is_ascii_digit);
    if !ok {
        return Err(bad(
            path,
            "SRTM file name must start with the south-west corner, e.g. N41E001.hgt",
        ));
    }
    let lat: i32 = stem[1..3].parse().unwrap_or(0);
    let lon: i32 = stem[4..7].parse().unwrap_or(0);
    let lat = if b[0] == b'S' { -lat } else { lat };
    let lon = if b[3] == b'W' { -lon } else { lon };
    if !(-90..90).contains(&lat) || !(-180..180).contains(&lon) {
        return Err(bad(path, format!("corner {lat},{lon} is not on Earth")));
    }
    Ok((lat, lon))
}

/// Reads the raw `.hgt` bytes, unzipping `.zip` files (the single `.hgt` entry).
fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let lower = path.to_string_lossy().to_ascii_lowercase();
    if lower.ends_with(".zip") {
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let mut zip = zip::ZipArchive::new(std::io::BufReader::new(file))
            .map_err(|e| bad(path, format!("not a readable zip archive ({e})")))?;
        let index = (0..zip.len())
            .find(|&i| {
                zip.name_for_index(i)
                    .is_some_and(|n| n.to_ascii_lowercase().ends_with(".hgt"))
            })
            .ok_or_else(|| bad(path, "zip archive holds no .hgt file"))?;
        let mut entry = zip
            .by_index(index)
            .map_err(|e| bad(path, format!("zip entry unreadable ({e})")))?;
        let mut bytes = Vec::with_capacity(entry.size() as usize);
        entry
            .read_to_end(&mut bytes)
            .map_err(|e| bad(path, format!("zip entry truncated or corrupt ({e})")))?;
        Ok(bytes)
    } else {
        std::fs::read(path).map_err(|e| Error::io(path, e))
    }
}

/// Reads and checks one tile.
pub fn read_tile(path: &Path) -> Result<Tile> {
    let (lat, lon) = parse_name(path)?;
    let bytes = read_bytes(path)?;
    let side = match bytes.len() {
        n if n == 3601 * 3601 * 2 => 3601,
        n if n == 1201 * 1201 * 2 => 1201,
        n => {
            return Err(bad(
                path,
                format!(
                    "{n} bytes is not an SRTM tile (SRTM1 3601x3601 = {} bytes, SRTM3 1201x1201 = {} bytes): truncated or wrong size",
                    3601 * 3601 * 2,
                    1201 * 1201 * 2
                ),
            ));
        }
    };
    let samples = bytes
        .chunks_exact(2)
        .map(|c| i16::from_be_bytes([c[0], c[1]]))
        .collect();
    Ok(Tile {
        path: path.to_path_buf(),
        lat,
        lon,
        side,
        samples,
    })
}

/// Mosaics adjoining tiles into one raster (row 0 = south). The tiles must all have the same
/// resolution and fill a rectangle of whole degrees exactly: gaps, duplicates and mixed
/// resolutions are errors. Shared edge samples come from whichever tile has a valid value.
pub fn mosaic(paths: &[PathBuf]) -> Result<Raster> {
    let first = paths
        .first()
        .ok_or_else(|| Error::invalid("SRTM mosaic", "no input tiles"))?;
    // Check names and sizes cheaply before decoding everything.
    let mut tiles: Vec<Tile> = Vec::with_capacity(paths.len());
    for p in paths {
        let (lat, lon) = parse_name(p)?;
        if let Some(t) = tiles.iter().find(|t| (t.lat, t.lon) == (lat, lon)) {
            return Err(bad(
                p,
                format!(
                    "inconsistent mosaic: overlaps {} (same 1-degree cell)",
                    t.path.display()
                ),
            ));
        }
        let t = read_tile(p)?;
        if let Some(t0) = tiles.first()
            && t0.side != t.side
        {
            return Err(bad(
                p,
                format!(
                    "inconsistent mosaic: {} samples per side but {} has {} (different resolutions)",
                    t.side,
                    t0.path.display(),
                    t0.side
                ),
            ));
        }
        tiles.push(t);
    }
    let lat0 = tiles.iter().map(|t| t.lat).min().unwrap_or(0);
    let lat1 = tiles.iter().map(|t| t.lat).max().unwrap_or(0);
    let lon0 = tiles.iter().map(|t| t.lon).min().unwrap_or(0);
    let lon1 = tiles.iter().map(|t| t.lon).max().unwrap_or(0);
    let (ny, nx) = ((lat1 - lat0 + 1) as u32, (lon1 - lon0 + 1) as u32);
    if (ny * nx) as usize != tiles.len() {
        let missing = (lat0..=lat1)
            .flat_map(|la| (lon0..=lon1).map(move |lo| (la, lo)))
            .find(|&(la, lo)| !tiles.iter().any(|t| (t.lat, t.lon) == (la, lo)))
            .unwrap_or((lat0, lon0));
        return Err(bad(
            first,
            format!(
                "inconsistent mosaic: gap, no tile for {}{:02}{}{:03} inside the {}x{} degree rectangle",
                if missing.0 < 0 { 'S' } else { 'N' },
                missing.0.abs(),
                if missing.1 < 0 { 'W' } else { 'E' },
                missing.1.abs(),
                nx,
                ny
            ),
        ));
    }
    let side = tiles[0].side;
    let step = side - 1;
    let (w, h) = (nx * step + 1, ny * step + 1);
    let mut heights = vec![f32::NAN; w as usize * h as usize];
    let mut provenance = Vec::new();
    let mut mismatches = 0u64;
    for t in &tiles {
        let (ox, oy) = ((t.lon - lon0) as u32 * step, (t.lat - lat0) as u32 * step);
        for r in 0..side {
            let row = oy + (side - 1 - r); // file row 0 is north
            let dst = row as usize * w as usize + ox as usize;
            let src = &t.samples[(r * side) as usize..((r + 1) * side) as usize];
            for (c, &s) in src.iter().enumerate() {
                if s == VOID {
                    continue;
                }
                let d = &mut heights[dst + c];
                if d.is_nan() {
                    *d = s as f32;
                } else if *d != s as f32 {
                    mismatches += 1;
                }
            }
        }
        let voids = t.samples.iter().filter(|&&s| s == VOID).count();
        provenance.push(format!(
            "SRTM{} tile {} ({}x{} samples, {} void)",
            if side == 3601 { 1 } else { 3 },
            t.path.display(),
            side,
            side,
            voids
        ));
    }
    if mismatches > 0 {
        provenance.push(format!(
            "{mismatches} shared edge samples disagreed between tiles; the first tile's value was kept"
        ));
    }
    let step_deg = 1.0 / step as f64;
    let centre_lat = lat0 as f64 + ny as f64 / 2.0;
    let name = if tiles.len() == 1 {
        first.display().to_string()
    } else {
        format!("{} (+{} SRTM tiles)", first.display(), tiles.len() - 1)
    };
    Ok(Raster {
        name,
        width: w,
        height: h,
        spacing: geographic_spacing([step_deg, step_deg], centre_lat),
        heights,
        georef: Some(Georef {
            crs: "EPSG:4326".into(),
            units: "degrees".into(),
            origin: [lon0 as f64, lat0 as f64],
            step: [step_deg, step_deg],
        }),
        provenance,
    })
}

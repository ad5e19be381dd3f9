//! Terrain data as the renderer consumes it: a height grid in metres (+ optional albedo).
//!
//! Convention (see `docs/coordinates.md`): sample `(col, row)` lies at world
//! `x = col * spacing`, `y = row * spacing` (metres, z up); row 0 is the **south** edge, so
//! images whose first row is north are flipped when loaded. Heights are metres.

pub mod crs;
#[cfg(feature = "gdal")]
pub mod gdal_in;
#[cfg(not(feature = "gdal"))]
#[path = "gdal_stub.rs"]
pub mod gdal_in;
pub mod geoid;
pub mod interp;
pub mod level0;
pub mod manifest;
pub mod output;
pub mod preprocess;
pub mod procedural;
pub mod pyramid;
pub mod settings;
pub mod source;
pub mod stats;
pub mod tiles;
pub mod voids;
pub mod world;
pub mod xyz;

use crate::error::{Error, Result};
use glam::DVec2;
pub use interp::normal_snorm8;
use interp::{GridCell, NormalAxes};
pub use level0::{DiskStore, Level0, NodeStore, PyramidReader, Terrain};

/// A regular height grid in metres, with optional albedo of the same extent.
#[derive(Clone, Debug)]
pub struct Heightmap {
    /// Human-readable name of where the data came from (shown in summaries).
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Distance between neighbouring samples in metres (x and y).
    pub spacing: f64,
    /// `width * height` heights, row-major, row 0 = south.
    pub heights: Vec<f32>,
    /// Optional RGBA8 (sRGB) albedo covering the same extent, row 0 = south.
    pub albedo: Option<Albedo>,
    /// Metres between neighbouring samples along x and y (the normals' slopes): `[spacing,
    /// spacing]` except on a native non-square grid (`tiles::LoadGrid::Native`), where
    /// `spacing` is the smallest of them (LOD distances err on the fine side).
    pub axis_spacing: [f64; 2],
    /// Native level-0 samples per sample of this grid (x, y): `[1, 1]` unless it was loaded
    /// from a coarser pyramid level or resampled east-west (`tiles::load`). The geolocation
    /// lattice places sample `(c, r)` at the native sample `(c * x, r * y)`.
    pub source_step: [f64; 2],
}

/// An sRGB RGBA8 image aligned with the height grid by extent.
#[derive(Clone, Debug)]
pub struct Albedo {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
}

/// Largest side accepted for a height grid held in one texture (Vulkan guarantees 4096; the
/// renderer checks the device limit too).
pub const MAX_SIDE: u32 = 16384;

impl Heightmap {
    /// Validates and builds a height grid.
    pub fn new(
        name: impl Into<String>,
        width: u32,
        height: u32,
        spacing: f64,
        heights: Vec<f32>,
    ) -> Result<Self> {
        let name = name.into();
        if width < 2 || height < 2 {
            return Err(Error::invalid(
                &name,
                format!("height grid {width}x{height} is smaller than 2x2"),
            ));
        }
        if width > MAX_SIDE || height > MAX_SIDE {
            return Err(Error::invalid(
                &name,
                format!("height grid {width}x{height} exceeds {MAX_SIDE} per side"),
            ));
        }
        if !(spacing.is_finite() && spacing > 0.0) {
            return Err(Error::invalid(
                &name,
                format!("sample spacing {spacing} m is not a positive number"),
            ));
        }
        if heights.len() != (width as usize) * (height as usize) {
            return Err(Error::invalid(
                &name,
                format!("{} heights for a {width}x{height} grid", heights.len()),
            ));
        }
        if let Some(i) = heights.iter().position(|h| !h.is_finite()) {
            return Err(Error::invalid(
                &name,
                format!("height at sample {} is {}", i, heights[i]),
            ));
        }
        Ok(Heightmap {
            name,
            width,
            height,
            spacing,
            heights,
            albedo: None,
            axis_spacing: [spacing, spacing],
            source_step: [1.0, 1.0],
        })
    }

    /// Height of sample `(col, row)` in metres.
    pub fn sample(&self, col: u32, row: u32) -> f32 {
        self.heights[row as usize * self.width as usize + col as usize]
    }

    /// Bilinear height at a world position (clamped to the grid), the same interpolation the
    /// GPU applies between samples.
    pub fn height_at(&self, x: f64, y: f64) -> f64 {
        GridCell::at(x / self.spacing, y / self.spacing, self.width, self.height)
            .bilinear(|c, r| self.sample(c, r) as f64)
    }

    /// Height of the exact surface at world `(x, y)`: the full-resolution triangle mesh the
    /// brute-force method draws (every sample a vertex, quads split along the diagonal from
    /// `(c + 1, r)` to `(c, r + 1)`, as `lod::brute::grid_indices`). Clamped to the data.
    pub fn mesh_height_at(&self, x: f64, y: f64) -> f64 {
        let gx = (x / self.spacing).clamp(0.0, (self.width - 1) as f64);
        let gy = (y / self.spacing).clamp(0.0, (self.height - 1) as f64);
        // The last row and column belong to the quad before them (fraction 1).
        let (c0, r0) = (
            (gx.floor() as u32).min(self.width.saturating_sub(2)),
            (gy.floor() as u32).min(self.height.saturating_sub(2)),
        );
        let (c1, r1) = ((c0 + 1).min(self.width - 1), (r0 + 1).min(self.height - 1));
        let h = |c, r| self.sample(c, r) as f64;
        interp::triangulated(
            [h(c0, r0), h(c1, r0), h(c0, r1), h(c1, r1)],
            gx - c0 as f64,
            gy - r0 as f64,
        )
    }

    /// World extent in metres: `(x_max, y_max)`; the grid starts at the origin.
    pub fn extent(&self) -> (f64, f64) {
        (
            (self.width - 1) as f64 * self.spacing,
            (self.height - 1) as f64 * self.spacing,
        )
    }

    /// Minimum and maximum height.
    pub fn height_range(&self) -> (f32, f32) {
        self.heights
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            })
    }

    /// Unit surface normal at each sample from central differences (one-sided at the edges),
    /// packed as RGBA8 snorm (x, y, z, 0) for the normal texture: in the grid's frame, or with
    /// the geolocation `lattice` in world axes (the surface through the samples where the
    /// lattice draws them).
    pub fn normals_snorm8(&self, lattice: Option<&crate::geo::Lattice>) -> Vec<u8> {
        let heights = |c: usize, r: usize| self.sample(c as u32, r as u32) as f64;
        let (w, h) = (self.width as usize, self.height as usize);
        match lattice {
            None => interp::normals_snorm8(w, h, &NormalAxes::Grid(self.axis_spacing), heights),
            Some(l) => {
                let position = |c: usize, r: usize, height: f64| {
                    l.position(DVec2::new(c as f64, r as f64), height)
                };
                interp::normals_snorm8(w, h, &NormalAxes::World(&position), heights)
            }
        }
    }

    /// The albedo to draw: the data's own if it has one, else a colour ramp by height and
    /// slope (grass, rock, snow), so untextured data still reads well.
    pub fn albedo_or_ramp(&self) -> Albedo {
        if let Some(a) = &self.albedo {
            return a.clone();
        }
        let (lo, hi) = self.height_range();
        let span = (hi - lo).max(1.0);
        let normals = self.normals_snorm8(None);
        let mut rgba = Vec::with_capacity(self.heights.len() * 4);
        for (i, &h) in self.heights.iter().enumerate() {
            rgba.extend(ramp_rgba(h, lo, span, normals[i * 4 + 2]));
        }
        Albedo {
            width: self.width,
            height: self.height,
            rgba,
        }
    }
}

/// The colour ramp of untextured data (grass, rock, snow) for height `h` in a data set
/// spanning `lo .. lo + span` metres, given the packed normal's z byte (slope).
pub fn ramp_rgba(h: f32, lo: f32, span: f32, normal_z: u8) -> [u8; 4] {
    let t = (h - lo) / span;
    let nz = (normal_z as i8) as f32 / 127.0;
    let grass = [0.32f32, 0.45, 0.22];
    let rock = [0.45f32, 0.41, 0.37];
    let snow = [0.93f32, 0.94, 0.96];
    let steep = ((0.9 - nz) / 0.25).clamp(0.0, 1.0);
    let mut c = [0.0f32; 3];
    for k in 0..3 {
        c[k] = grass[k] + (rock[k] - grass[k]) * steep.max(((t - 0.55) / 0.2).clamp(0.0, 1.0));
        let s = ((t - 0.8) / 0.1).clamp(0.0, 1.0) * (1.0 - steep);
        c[k] += (snow[k] - c[k]) * s;
    }
    let q = |v: f32| (v * 255.0).round() as u8;
    [q(c[0]), q(c[1]), q(c[2]), 255]
}

/// A 16-bit greyscale PNG height map (`value * vertical_scale` metres) with optional albedo
/// image covering the same extent. PNG rows run north to south; they are flipped so row 0 is
/// south.
pub fn load_png16(
    path: &std::path::Path,
    spacing: f64,
    vertical_scale: f64,
    albedo: Option<&std::path::Path>,
) -> Result<Heightmap> {
    let decode = |p: &std::path::Path| {
        image::ImageReader::open(p)
            .map_err(|e| Error::io(p, e))?
            .with_guessed_format()
            .map_err(|e| Error::io(p, e))?
            .decode()
            .map_err(|e| Error::invalid(p.display().to_string(), e.to_string()))
    };
    let img = decode(path)?;
    if !matches!(img.color(), image::ColorType::L16 | image::ColorType::La16) {
        return Err(Error::invalid(
            path.display().to_string(),
            format!("expected a 16-bit greyscale PNG, found {:?}", img.color()),
        ));
    }
    let grey = img.to_luma16();
    let (w, h) = grey.dimensions();
    let mut heights = Vec::with_capacity((w * h) as usize);
    for row in (0..h).rev() {
        for col in 0..w {
            heights.push((grey.get_pixel(col, row)[0] as f64 * vertical_scale) as f32);
        }
    }
    let mut map = Heightmap::new(path.display().to_string(), w, h, spacing, heights)?;
    if let Some(ap) = albedo {
        let rgba = decode(ap)?.to_rgba8();
        let (aw, ah) = rgba.dimensions();
        let flipped: Vec<u8> = (0..ah)
            .rev()
            .flat_map(|r| {
                rgba.as_raw()[(r * aw * 4) as usize..((r + 1) * aw * 4) as usize].to_vec()
            })
            .collect();
        map.albedo = Some(Albedo {
            width: aw,
            height: ah,
            rgba: flipped,
        });
    }
    Ok(map)
}

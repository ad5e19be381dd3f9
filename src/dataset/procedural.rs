//! Deterministic procedural terrain: the embedded default data set.
//!
//! Gradient-free value noise (hash-based, so any sample can be computed alone, which later lets
//! a generator work node by node) summed as fBm, with a ridged term for mountain crests and a
//! power curve that flattens valleys as erosion would. Same seed, same size: same heights, bit
//! for bit, on every machine (only integer hashing and f64 arithmetic).

use super::Heightmap;
use crate::error::Result;

/// Parameters of the generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProceduralParams {
    pub size: u32,
    pub seed: u64,
    /// Sample spacing in metres.
    pub spacing: f64,
    /// Height of the tallest possible peak in metres.
    pub max_height: f64,
    /// Wavelength of the largest features in metres.
    pub feature_size: f64,
    /// The character of the terrain.
    pub style: Style,
}

/// Terrain characters of the generator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Style {
    /// Rolling fBm hills with ridged mountains in a few masked regions (the tests' terrain).
    #[default]
    Classic,
    /// Ridged multifractal mountains over warped, rotated octaves: ridges, valleys and crests
    /// everywhere, no lattice-aligned features (the main job's terrain).
    Alpine,
}

impl Default for ProceduralParams {
    fn default() -> Self {
        ProceduralParams {
            size: 1025,
            seed: 1,
            spacing: 30.0,
            max_height: 2400.0,
            feature_size: 12_000.0,
            style: Style::Classic,
        }
    }
}

fn hash(seed: u64, x: i64, y: i64) -> f64 {
    // SplitMix64 over the packed lattice coordinates.
    let mut z = seed
        .wrapping_add((x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
        .wrapping_add((y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

fn smooth(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// Value noise in [0, 1] at lattice coordinates `(x, y)`.
fn value_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (smooth(x - x0), smooth(y - y0));
    let (ix, iy) = (x0 as i64, y0 as i64);
    let a = hash(seed, ix, iy);
    let b = hash(seed, ix + 1, iy);
    let c = hash(seed, ix, iy + 1);
    let d = hash(seed, ix + 1, iy + 1);
    let south = a + (b - a) * fx;
    let north = c + (d - c) * fx;
    south + (north - south) * fy
}

/// Height in metres at world position `(x, y)`.
pub fn height(params: &ProceduralParams, x: f64, y: f64) -> f64 {
    match params.style {
        Style::Classic => classic(params, x, y),
        Style::Alpine => alpine(params, x, y),
    }
}

/// A 3-4-5 rotation (about 36.87 degrees) and a shift between octaves, so no two octaves share
/// lattice axes or origins.
fn next_octave(u: f64, v: f64) -> (f64, f64) {
    (
        2.0 * (0.8 * u - 0.6 * v) + 17.31,
        2.0 * (0.6 * u + 0.8 * v) - 9.17,
    )
}

/// fBm in [0, 1] over `octaves` rotated octaves.
fn rotated_fbm(seed: u64, mut u: f64, mut v: f64, octaves: u64) -> f64 {
    let (mut sum, mut amplitude, mut norm) = (0.0, 0.5, 0.0);
    for octave in 0..octaves {
        sum += amplitude * value_noise(seed.wrapping_add(octave), u, v);
        norm += amplitude;
        amplitude *= 0.5;
        (u, v) = next_octave(u, v);
    }
    sum / norm
}

/// Ridged multifractal (each octave's detail weighted by the ridge below it, so crests are
/// rough and valleys smooth) over a domain warped by low-frequency fBm, on broad hills.
fn alpine(params: &ProceduralParams, x: f64, y: f64) -> f64 {
    let f = 1.0 / params.feature_size;
    let seed = params.seed.wrapping_mul(0x51ED);
    let warp = 0.35 * params.feature_size;
    let x = x + warp * (rotated_fbm(seed ^ 0x1111, x * f * 0.5, y * f * 0.5, 4) - 0.5);
    let y = y + warp * (rotated_fbm(seed ^ 0x2222, x * f * 0.5 + 5.2, y * f * 0.5, 4) - 0.5);
    // Even the first octave off the lattice axes (the rotation of `next_octave`, unscaled).
    let (mut u, mut v) = ((0.8 * x - 0.6 * y) * f, (0.6 * x + 0.8 * y) * f);
    let (mut sum, mut amplitude, mut weight, mut norm) = (0.0, 0.5, 1.0, 0.0);
    // Band-limited to the samples: octaves down to a wavelength of 2.5 samples. Finer ones
    // would only alias into sample-to-sample noise that no renderer can show.
    let octaves = (params.feature_size / (2.5 * params.spacing))
        .log2()
        .floor()
        .clamp(1.0, 11.0) as u64;
    for octave in 0..octaves {
        let n = value_noise(seed.wrapping_add(100 + octave), u, v);
        let ridge = (1.0 - (2.0 * n - 1.0).abs()).powi(2);
        sum += amplitude * ridge * weight;
        norm += amplitude;
        weight = (2.0 * ridge).clamp(0.0, 1.0);
        amplitude *= 0.5;
        (u, v) = next_octave(u, v);
    }
    let hills = rotated_fbm(seed ^ 0x3333, x * f * 0.35, y * f * 0.35, 5);
    let shaped = (0.3 * hills + 0.9 * sum / norm).clamp(0.0, 1.0);
    params.max_height * shaped.powf(1.4)
}

/// Rolling fBm hills with ridged mountains where a low-frequency mask is high.
fn classic(params: &ProceduralParams, x: f64, y: f64) -> f64 {
    let mut fbm = 0.0;
    let mut ridge = 0.0;
    let mut amplitude = 0.5;
    let mut frequency = 1.0 / params.feature_size;
    for octave in 0..10u64 {
        let s = params.seed.wrapping_mul(31).wrapping_add(octave);
        let n = value_noise(s, x * frequency, y * frequency);
        fbm += amplitude * n;
        ridge += amplitude * (1.0 - (2.0 * n - 1.0).abs()).powi(2);
        amplitude *= 0.5;
        frequency *= 2.03;
    }
    // Mountains where the low-frequency mask is high, rolling hills elsewhere.
    let mask = smooth(value_noise(
        params.seed ^ 0xA5A5,
        x / (params.feature_size * 2.5),
        y / (params.feature_size * 2.5),
    ));
    let shaped = (0.55 * fbm + 0.45 * ridge * mask).clamp(0.0, 1.0);
    params.max_height * shaped.powf(1.6)
}

/// The data set's description: size, seed and spacing, and whatever differs from the defaults.
fn describe(params: &ProceduralParams) -> String {
    let d = ProceduralParams::default();
    let mut text = format!(
        "procedural size={} seed={} spacing={} m",
        params.size, params.seed, params.spacing
    );
    if params.style != d.style {
        text += &format!(" style={:?}", params.style).to_lowercase();
    }
    if params.max_height != d.max_height {
        text += &format!(" max_height={} m", params.max_height);
    }
    if params.feature_size != d.feature_size {
        text += &format!(" feature_size={} m", params.feature_size);
    }
    text
}

/// Generates the whole grid.
pub fn generate(params: &ProceduralParams) -> Result<Heightmap> {
    let n = params.size as usize;
    let mut heights = Vec::with_capacity(n * n);
    for row in 0..params.size {
        for col in 0..params.size {
            let (x, y) = (col as f64 * params.spacing, row as f64 * params.spacing);
            heights.push(height(params, x, y) as f32);
        }
    }
    Heightmap::new(
        describe(params),
        params.size,
        params.size,
        params.spacing,
        heights,
    )
}

/// Analytic test surfaces with known geometry (for image tests against exact values).
pub mod analytic {
    use super::super::Heightmap;
    use crate::error::Result;

    /// A plane `z = z0 + gx * x + gy * y`.
    pub fn plane(size: u32, spacing: f64, z0: f64, gx: f64, gy: f64) -> Result<Heightmap> {
        let mut h = Vec::with_capacity((size * size) as usize);
        for r in 0..size {
            for c in 0..size {
                h.push((z0 + gx * c as f64 * spacing + gy * r as f64 * spacing) as f32);
            }
        }
        Heightmap::new("analytic plane", size, size, spacing, h)
    }

    /// A cone of `peak` metres at the grid centre, falling linearly to 0 at `radius`.
    pub fn cone(size: u32, spacing: f64, peak: f64, radius: f64) -> Result<Heightmap> {
        let centre = (size - 1) as f64 * spacing / 2.0;
        let mut h = Vec::with_capacity((size * size) as usize);
        for r in 0..size {
            for c in 0..size {
                let d = ((c as f64 * spacing - centre).powi(2)
                    + (r as f64 * spacing - centre).powi(2))
                .sqrt();
                h.push((peak * (1.0 - d / radius)).max(0.0) as f32);
            }
        }
        Heightmap::new("analytic cone", size, size, spacing, h)
    }
}

/// Zero-mean fBm detail of roughly `amplitude` metres with the largest wavelength
/// `wavelength` metres (4 octaves), used to amplify a real DEM below its resolution.
pub fn detail(seed: u64, x: f64, y: f64, wavelength: f64, amplitude: f64) -> f64 {
    let mut sum = 0.0;
    let mut a = amplitude;
    let mut f = 1.0 / wavelength;
    for octave in 0..4u64 {
        let s = seed.wrapping_mul(0x9E37).wrapping_add(1000 + octave);
        sum += a * (2.0 * value_noise(s, x * f, y * f) - 1.0);
        a *= 0.5;
        f *= 2.0;
    }
    sum
}

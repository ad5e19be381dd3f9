//! FLIP (Andersson et al., "FLIP: A Difference Evaluator for Alternating Images", HPG 2020):
//! the perceptual difference between a rendered frame and the reference, through NVIDIA's
//! reference implementation (the `nv-flip` crate builds its C++ with `cc`; wgpu's test suite
//! compares images with it too). It runs on the CPU: the evaluator computes it for sampled
//! frames on a rayon pool while the GPU renders (`docs/eval.md`).

use serde::Serialize;

/// Pixels per degree of visual angle the comparison assumes: FLIP's default (a 0.7 m viewing
/// distance from a 24" 4K monitor).
pub const PIXELS_PER_DEGREE: f32 = nv_flip::DEFAULT_PIXELS_PER_DEGREE;

/// FLIP of one frame: mean, median, 99th percentile (nearest rank) and maximum of the
/// per-pixel error map (0 = identical, 1 = most different).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FlipStats {
    pub mean: f64,
    pub median: f64,
    pub p99: f64,
    pub max: f64,
}

/// The per-pixel FLIP error map of `test` against `reference` (RGBA8 sRGB, rows from the top,
/// `width * height` pixels each; alpha ignored).
pub fn error_map(reference: &[u8], test: &[u8], width: u32, height: u32) -> Vec<f32> {
    let rgb = |rgba: &[u8]| -> Vec<u8> {
        rgba.chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect()
    };
    let r = nv_flip::FlipImageRgb8::with_data(width, height, &rgb(reference));
    let t = nv_flip::FlipImageRgb8::with_data(width, height, &rgb(test));
    nv_flip::flip(r, t, PIXELS_PER_DEGREE).to_vec()
}

impl FlipStats {
    /// Summary of an error map (all zero when empty).
    pub fn of(map: &[f32]) -> FlipStats {
        if map.is_empty() {
            return FlipStats::default();
        }
        let mut v: Vec<f64> = map.iter().map(|&e| e as f64).collect();
        v.sort_by(f64::total_cmp);
        let rank = |q: f64| crate::render::stats::nearest_rank(&v, q);
        FlipStats {
            mean: v.iter().sum::<f64>() / v.len() as f64,
            median: rank(0.5),
            p99: rank(0.99),
            max: v[v.len() - 1],
        }
    }
}

/// The error map coloured with FLIP's magma look-up table, RGBA8.
pub fn magma_rgba(map: &[f32], width: u32, height: u32) -> Vec<u8> {
    let image = nv_flip::FlipImageFloat::with_data(width, height, map);
    image
        .apply_color_lut(&nv_flip::magma_lut())
        .to_vec()
        .chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pattern(w: u32, h: u32, shift: u32) -> Vec<u8> {
        let mut img = vec![0u8; (w * h * 4) as usize];
        for y in 0..h {
            for x in 0..w {
                let i = ((y * w + x) * 4) as usize;
                let v = if ((x + shift) / 4 + y / 4) % 2 == 0 {
                    220
                } else {
                    30
                };
                img[i..i + 4].copy_from_slice(&[v, v / 2, 255 - v, 255]);
            }
        }
        img
    }

    #[test]
    fn flip_of_identical_images_is_zero_and_of_a_shifted_image_is_not() {
        let (w, h) = (64, 48);
        let a = pattern(w, h, 0);
        let same = FlipStats::of(&error_map(&a, &a, w, h));
        assert_eq!(same, FlipStats::default(), "identical images");
        // Negative control: the same checkerboard shifted by two pixels.
        let b = pattern(w, h, 2);
        let shifted = FlipStats::of(&error_map(&a, &b, w, h));
        assert!(
            shifted.mean > 0.05 && shifted.max > 0.5,
            "shifted image: {shifted:?}"
        );
        assert!(shifted.median <= shifted.p99 && shifted.p99 <= shifted.max);
        let colours = magma_rgba(&error_map(&a, &b, w, h), w, h);
        assert_eq!(colours.len(), (w * h * 4) as usize);
    }
}

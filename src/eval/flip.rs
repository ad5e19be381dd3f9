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
/// `width * height` pixels each; alpha ignored), in one call over the whole image.
pub fn error_map(reference: &[u8], test: &[u8], width: u32, height: u32) -> Vec<f32> {
    flip_rows(reference, test, width as usize, 0, height as usize)
}

/// [`error_map`] of the rows where the images differ, in horizontal strips on the rayon pool
/// (about one per thread, none longer than needed for that or 8 halos), each with
/// [`halo_rows`] rows of context above and below ([`error_map_of_changed_rows`]): the same
/// values bit for bit in a
/// fraction of the time where threads are idle or the images share whole bands of rows (the sky
/// above a horizon; terrain that a method draws exactly like the reference).
pub fn error_map_parallel(reference: &[u8], test: &[u8], width: u32, height: u32) -> Vec<f32> {
    let halo = halo_rows(PIXELS_PER_DEGREE);
    error_map_of_changed_rows(
        reference,
        test,
        width,
        height,
        rayon::current_num_threads(),
        halo,
    )
}

/// Rows of context a strip needs on each side for FLIP at `ppd`: the larger of FLIP's two
/// filter radii (the spatial filters', from the largest scale parameter 0.04 of its contrast
/// sensitivity Gaussians, and the feature filter's, 3 standard deviations of `0.5 * 0.082 *
/// ppd`: `sharedflip.h` and `image.h` of the reference implementation), plus one. FLIP filters
/// separably (rows, then columns, clamping at the image's edges) and is otherwise per pixel,
/// so a pixel's value depends on no row farther away than that radius.
pub fn halo_rows(ppd: f32) -> usize {
    let ppd = ppd as f64;
    let spatial = (3.0 * (0.04 / (2.0 * std::f64::consts::PI.powi(2))).sqrt() * ppd).ceil();
    let feature = (3.0 * 0.5 * 0.082 * ppd).ceil();
    spatial.max(feature) as usize + 1
}

/// [`error_map`] computed only on the rows within `halo` of a row where the two images differ,
/// in strips of at most `max(changed rows / threads, 8 halo)` rows (so about `threads` of them
/// where much changed), each with `halo` rows of context; every
/// other row is 0, which FLIP gives wherever both images are equal within its filters' reach
/// (equal filtered colours and features: a colour difference of 0 raised to any power).
pub fn error_map_of_changed_rows(
    reference: &[u8],
    test: &[u8],
    width: u32,
    height: u32,
    threads: usize,
    halo: usize,
) -> Vec<f32> {
    let (w, h) = (width as usize, height as usize);
    let ranges = changed_row_ranges(reference, test, w, h, halo);
    let total: usize = ranges.iter().map(|(a, b)| b - a).sum();
    let rows = total.div_ceil(threads.max(1)).max(8 * halo).max(1);
    let pieces: Vec<_> = ranges
        .iter()
        .flat_map(|&(a, b)| (a..b).step_by(rows).map(move |y| (y, (y + rows).min(b))))
        .collect();
    flip_pieces(reference, test, w, h, &pieces, halo)
}

/// The ranges of rows whose FLIP value may differ from 0: rows within `halo` of a row where the
/// images differ (RGBA compared; alpha-only differences are computed too, which costs time, not
/// exactness), merged where they touch.
fn changed_row_ranges(
    reference: &[u8],
    test: &[u8],
    w: usize,
    h: usize,
    halo: usize,
) -> Vec<(usize, usize)> {
    let row = |y: usize| y * w * 4..(y + 1) * w * 4;
    let mut ranges: Vec<(usize, usize)> = Vec::new();
    for y in (0..h).filter(|&y| reference[row(y)] != test[row(y)]) {
        let (a, b) = (y.saturating_sub(halo), (y + halo + 1).min(h));
        match ranges.last_mut() {
            Some(last) if last.1 >= a => last.1 = b,
            _ => ranges.push((a, b)),
        }
    }
    ranges
}

/// FLIP of each piece `(y0, y1)` of rows in parallel, each from rows `y0 - halo .. y1 + halo`
/// (clipped to the image) as an image of its own, kept rows only; rows of no piece are 0.
fn flip_pieces(
    reference: &[u8],
    test: &[u8],
    w: usize,
    h: usize,
    pieces: &[(usize, usize)],
    halo: usize,
) -> Vec<f32> {
    use rayon::prelude::*;
    let parts: Vec<Vec<f32>> = pieces
        .par_iter()
        .map(|&(y0, y1)| {
            let (a, b) = (y0.saturating_sub(halo), (y1 + halo).min(h));
            let map = flip_rows(reference, test, w, a, b);
            map[(y0 - a) * w..(y1 - a) * w].to_vec()
        })
        .collect();
    let mut out = vec![0.0f32; w * h];
    for (&(y0, y1), part) in pieces.iter().zip(parts) {
        out[y0 * w..y1 * w].copy_from_slice(&part);
    }
    out
}

/// FLIP of rows `a..b` of both images as an image of their own.
fn flip_rows(reference: &[u8], test: &[u8], w: usize, a: usize, b: usize) -> Vec<f32> {
    let rgb = |rgba: &[u8]| -> Vec<u8> {
        rgba[a * w * 4..b * w * 4]
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect()
    };
    let (w, h) = (w as u32, (b - a) as u32);
    let r = nv_flip::FlipImageRgb8::with_data(w, h, &rgb(reference));
    let t = nv_flip::FlipImageRgb8::with_data(w, h, &rgb(test));
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

    /// A frame-like image: smooth gradients, a sharp horizon and per-pixel noise.
    fn scene(w: u32, h: u32, seed: u32) -> Vec<u8> {
        let mut img = vec![0u8; (w * h * 4) as usize];
        let mut state = seed.wrapping_mul(2_654_435_761).max(1);
        for y in 0..h {
            for x in 0..w {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                let noise = (state % 23) as u8;
                let i = ((y * w + x) * 4) as usize;
                let sky = y < h / 3 + (x / 7) % 5;
                let v = if sky {
                    200
                } else {
                    (40 + (x * 3 + y * 2) % 150) as u8
                };
                img[i..i + 4].copy_from_slice(&[v + noise / 2, v / 2 + noise, 250 - v, 255]);
            }
        }
        img
    }

    /// [`error_map`] over exactly `strips` horizontal strips in parallel (the mechanism of
    /// [`error_map_of_changed_rows`] at any number of seams), each extended by `halo` rows of
    /// context (clipped at the image's top and bottom, where FLIP's own edge clamping then applies
    /// as over the whole image); only the strip's own rows are kept.
    fn error_map_in_strips(
        reference: &[u8],
        test: &[u8],
        width: u32,
        height: u32,
        strips: usize,
        halo: usize,
    ) -> Vec<f32> {
        let h = height as usize;
        let rows = h.div_ceil(strips.max(1)).max(1);
        let pieces: Vec<_> = (0..h)
            .step_by(rows)
            .map(|y| (y, (y + rows).min(h)))
            .collect();
        flip_pieces(reference, test, width as usize, h, &pieces, halo)
    }

    #[test]
    fn flip_in_strips_equals_flip_of_the_whole_image_bit_for_bit() {
        let (w, h) = (96, 173);
        let (a, b) = (scene(w, h, 1), scene(w, h, 2));
        let whole = flip_rows(&a, &b, w as usize, 0, h as usize);
        let halo = halo_rows(PIXELS_PER_DEGREE);
        assert_eq!(
            halo, 11,
            "FLIP's radii at its default 67 pixels per degree: 10 and 9"
        );
        for strips in [2, 3, 7] {
            let split = error_map_in_strips(&a, &b, w, h, strips, halo);
            assert_eq!(split.len(), whole.len());
            let differ = split
                .iter()
                .zip(&whole)
                .filter(|(s, o)| s.to_bits() != o.to_bits())
                .count();
            assert_eq!(differ, 0, "{strips} strips: {differ} pixels differ");
        }
        assert_eq!(error_map_parallel(&a, &b, w, h), error_map(&a, &b, w, h));
        // Negative control: strips without enough context differ near their seams.
        let short = error_map_in_strips(&a, &b, w, h, 3, 4);
        let differ = short.iter().zip(&whole).filter(|(s, o)| s != o).count();
        assert!(differ > 0, "a 4-row halo must change pixels near the seams");
    }

    #[test]
    fn flip_of_the_changed_rows_only_equals_flip_of_the_whole_image_bit_for_bit() {
        let (w, h) = (96, 260);
        let a = scene(w, h, 1);
        // Equal but for two bands of rows (a sky and a near field drawn alike around them).
        let other = scene(w, h, 2);
        let mut b = a.clone();
        let band = |y0: usize, y1: usize| y0 * w as usize * 4..y1 * w as usize * 4;
        for (y0, y1) in [(70, 95), (200, 204)] {
            b[band(y0, y1)].copy_from_slice(&other[band(y0, y1)]);
        }
        let whole = flip_rows(&a, &b, w as usize, 0, h as usize);
        let halo = halo_rows(PIXELS_PER_DEGREE);
        let ranges = changed_row_ranges(&a, &b, w as usize, h as usize, halo);
        assert_eq!(
            ranges,
            vec![(59, 106), (189, 215)],
            "rows FLIP is computed on"
        );
        let zero = whole.iter().filter(|&&e| e == 0.0).count();
        assert!(
            zero > (w * h / 2) as usize,
            "FLIP is 0 where the images agree: {zero}"
        );
        for threads in [1, 3, 16] {
            let changed = error_map_of_changed_rows(&a, &b, w, h, threads, halo);
            let differ = changed
                .iter()
                .zip(&whole)
                .filter(|(s, o)| s.to_bits() != o.to_bits())
                .count();
            assert_eq!(differ, 0, "{threads} threads: {differ} pixels differ");
        }
        // Negative control: a 4-row margin leaves out rows FLIP's filters reach.
        let short = error_map_of_changed_rows(&a, &b, w, h, 3, 4);
        let differ = short.iter().zip(&whole).filter(|(s, o)| s != o).count();
        assert!(differ > 0, "a 4-row margin must miss non-zero rows");
    }
}

//! Void filling by push-pull: average the valid samples into ever coarser grids (push), then
//! fill each void from the bilinearly interpolated next coarser grid (pull), coarse to fine.
//! Every filled value is a convex combination of valid samples, so fills never overshoot the
//! surrounding terrain (no spikes), and a hole of any size is filled smoothly.

use super::interp::GridCell;
use crate::error::{Error, Result};

/// Fills every `NaN` in `heights` (row-major `w x h`). Returns the mask (1 = filled) and the
/// number of filled samples. An entirely void raster is an error naming `name`.
pub fn fill(name: &str, heights: &mut [f32], w: u32, h: u32) -> Result<(Vec<u8>, u64)> {
    let mask: Vec<u8> = heights.iter().map(|v| v.is_nan() as u8).collect();
    let filled = mask.iter().filter(|&&m| m != 0).count() as u64;
    if filled == 0 {
        return Ok((mask, 0));
    }
    if filled as usize == heights.len() {
        return Err(Error::invalid(
            name,
            "entirely void: no valid elevation sample to fill from",
        ));
    }
    // Push: level k+1 = mean of the valid samples among each 2x2 block of level k.
    let mut levels: Vec<(usize, usize, Vec<f32>)> = Vec::new();
    let (mut cw, mut ch) = (w as usize, h as usize);
    while cw > 1 || ch > 1 {
        let prev: &[f32] = match levels.last() {
            Some(l) => &l.2,
            None => heights,
        };
        let (nw, nh) = (cw.div_ceil(2), ch.div_ceil(2));
        let mut next = vec![f32::NAN; nw * nh];
        for y in 0..nh {
            for x in 0..nw {
                let (mut sum, mut n) = (0f64, 0u32);
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (sx, sy) = (2 * x + dx, 2 * y + dy);
                    if sx < cw && sy < ch {
                        let v = prev[sy * cw + sx];
                        if !v.is_nan() {
                            sum += v as f64;
                            n += 1;
                        }
                    }
                }
                if n > 0 {
                    next[y * nw + x] = (sum / n as f64) as f32;
                }
            }
        }
        levels.push((nw, nh, next));
        (cw, ch) = (nw, nh);
    }
    // Pull: from the coarsest (1x1, valid since some sample is) down to the source.
    for k in (0..levels.len()).rev() {
        let (lo, hi) = levels.split_at_mut(k);
        let (cw, ch, cvals) = (&hi[0].0, &hi[0].1, &hi[0].2);
        let (fw, fh, fine): (usize, usize, &mut [f32]) = if k == 0 {
            (w as usize, h as usize, &mut *heights)
        } else {
            let l = &mut lo[k - 1];
            (l.0, l.1, &mut l.2[..])
        };
        let sample = |x: f64, y: f64| -> f32 {
            GridCell::at(x, y, *cw as u32, *ch as u32)
                .bilinear(|xx, yy| cvals[yy as usize * cw + xx as usize] as f64) as f32
        };
        let mut holes = Vec::new();
        for y in 0..fh {
            for x in 0..fw {
                let i = y * fw + x;
                if fine[i].is_nan() {
                    fine[i] = sample((x as f64 - 0.5) / 2.0, (y as f64 - 0.5) / 2.0);
                    holes.push((x, y));
                }
            }
        }
        relax(fine, fw, fh, &holes);
    }
    Ok((mask, filled))
}

/// Gauss-Seidel sweeps of the Laplace equation over the filled samples only (valid samples
/// are fixed): the pulled values are a good start, so a few sweeps per level suffice for the
/// multigrid-like descent to approach the harmonic fill, which never leaves the range of the
/// void's rim (no spikes or pits).
fn relax(v: &mut [f32], w: usize, h: usize, holes: &[(usize, usize)]) {
    const SWEEPS: usize = 12;
    for _ in 0..SWEEPS {
        for &(x, y) in holes {
            let mut sum = 0f64;
            let mut n = 0u32;
            if x > 0 {
                sum += v[y * w + x - 1] as f64;
                n += 1;
            }
            if x + 1 < w {
                sum += v[y * w + x + 1] as f64;
                n += 1;
            }
            if y > 0 {
                sum += v[(y - 1) * w + x] as f64;
                n += 1;
            }
            if y + 1 < h {
                sum += v[(y + 1) * w + x] as f64;
                n += 1;
            }
            if n > 0 {
                v[y * w + x] = (sum / n as f64) as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fills_holes_within_range() {
        let (w, h) = (37u32, 23u32);
        let mut v: Vec<f32> = (0..w * h)
            .map(|i| (i % w) as f32 + (i / w) as f32)
            .collect();
        for y in 5..15 {
            for x in 3..30 {
                v[(y * w + x) as usize] = f32::NAN;
            }
        }
        let (mask, n) = fill("t", &mut v, w, h).unwrap();
        assert_eq!(n, 10 * 27);
        assert_eq!(mask.iter().filter(|&&m| m == 1).count(), 270);
        assert!(v.iter().all(|x| x.is_finite() && *x >= 0.0 && *x <= 58.0));
    }

    #[test]
    fn entirely_void_is_an_error() {
        let mut v = vec![f32::NAN; 16];
        let e = fill("x.hgt", &mut v, 4, 4).unwrap_err().to_string();
        assert!(e.contains("x.hgt") && e.contains("entirely void"), "{e}");
    }
}

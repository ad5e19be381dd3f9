//! Coarse pixels (docs/eval.md, "Coarse pixels"): the pixels whose surface a method drew with a
//! tile coarser than the data's level 0. Where a tile of level 0 is drawn the data's
//! resolution is the limit and the drawn mesh is exact but for the morph, so those pixels say
//! nothing about how a method spends its pixel error target; issue 18's band for the 99.9th
//! percentile applies to the others. Measured on the CPU ([`super::metrics`]) from read-back
//! depth and the method's own tile list ([`crate::lod::LodMethod::drawn_tiles`]).

use std::collections::HashSet;

use serde::Serialize;

use super::metrics::{self, ExactSurface, Histogram, ViewColumns};
use crate::lod::DrawnTiles;

/// Tile levels above this are not looked up (a tile of level 31 spans 2^31 tile sides).
const MAX_LEVEL: u32 = 31;

/// Which tile drew each point of the data: the drawn tiles of one view, looked up from level 0
/// up (memory proportional to the drawn tiles, not to the data).
pub struct TileLevels {
    tiles: HashSet<[u32; 3]>,
    tile_samples: u32,
    top: u32,
}

impl TileLevels {
    pub fn new(drawn: &DrawnTiles) -> Self {
        let tiles: HashSet<[u32; 3]> = drawn
            .tiles
            .iter()
            .copied()
            .filter(|t| t[2] <= MAX_LEVEL)
            .collect();
        let top = tiles.iter().map(|t| t[2]).max().unwrap_or(0);
        TileLevels {
            tiles,
            tile_samples: drawn.tile_samples.max(1),
            top,
        }
    }

    /// The level of the drawn tile over level-0 sample position `sample` (columns, rows);
    /// `None` where no drawn tile covers it (culled, or off the data).
    pub fn level_at(&self, sample: [f64; 2]) -> Option<u32> {
        if !(sample[0] >= 0.0 && sample[1] >= 0.0) {
            return None;
        }
        let cell = sample.map(|s| (s / self.tile_samples as f64).floor());
        if !(cell[0] < u32::MAX as f64 && cell[1] < u32::MAX as f64) {
            return None;
        }
        let [x, y] = cell.map(|c| c as u32);
        (0..=self.top).find(|&lod| self.tiles.contains(&[x >> lod, y >> lod, lod]))
    }
}

/// The screen-space errors of one or more frames' coarse pixels, how many pixels were
/// measured in all, and the largest error over level-0 tiles.
#[derive(Clone, Debug, Default)]
pub struct CoarseErrors {
    pub pixels: Histogram,
    /// Every measured pixel: coarse, level 0, or over no drawn tile.
    pub measured: u64,
    /// The largest screen-space error of a pixel over a level-0 tile (px): the morph's alone.
    pub level0_max_px: f64,
}

/// The coarse pixels' 99.9th percentile (0 without any), their share of the measured pixels,
/// and the largest error over level-0 tiles.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct CoarseSummary {
    pub p999_px: f64,
    pub share: f64,
    pub level0_max_px: f64,
}

impl CoarseErrors {
    pub fn merge(&mut self, other: &CoarseErrors) {
        self.pixels.merge(&other.pixels);
        self.measured += other.measured;
        self.level0_max_px = self.level0_max_px.max(other.level0_max_px);
    }

    /// `None` without a measured pixel.
    pub fn summary(&self) -> Option<CoarseSummary> {
        let n = self.pixels.count();
        (self.measured > 0).then(|| CoarseSummary {
            p999_px: if n > 0 {
                self.pixels.quantile(0.999)
            } else {
                0.0
            },
            share: n as f64 / self.measured as f64,
            level0_max_px: self.level0_max_px,
        })
    }
}

/// The coarse pixels of a frame of `views` (one [`TileLevels`] each) with read-back `depth`.
pub fn measure<S: ExactSurface + ?Sized>(
    data: &S,
    views: &[ViewColumns],
    levels: &[TileLevels],
    (width, height): (u32, u32),
    depth: &[f32],
) -> CoarseErrors {
    let errors = metrics::pixel_errors_views(views, width, height, depth, data);
    let mut out = CoarseErrors {
        measured: errors.len() as u64,
        ..CoarseErrors::default()
    };
    for e in &errors {
        let v = views.iter().rposition(|v| e.x >= v.first).unwrap_or(0);
        match levels.get(v).and_then(|l| l.level_at(e.sample)) {
            Some(0) => out.level0_max_px = out.level0_max_px.max(e.pixels),
            Some(_) => out.pixels.add(e.pixels),
            None => {}
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn levels(tiles: &[[u32; 3]]) -> TileLevels {
        TileLevels::new(&DrawnTiles {
            tiles: tiles.to_vec(),
            tile_samples: 4,
        })
    }

    #[test]
    fn a_point_takes_the_level_of_the_tile_over_it() {
        // Level 1 tile (0, 0) covers samples 0..8; level 0 tiles (2, 0) and (3, 0) cover
        // 8..16 along x on the first row of tiles; level 2 tile (0, 1) covers rows 16..32.
        let l = levels(&[[0, 0, 1], [2, 0, 0], [3, 0, 0], [0, 1, 2]]);
        for (sample, want) in [
            ([0.0, 0.0], Some(1)),
            ([7.9, 7.9], Some(1)),
            ([8.0, 0.5], Some(0)),
            ([15.5, 3.9], Some(0)),
            ([12.0, 4.5], None),
            ([5.0, 20.0], Some(2)),
            ([15.9, 31.9], Some(2)),
            ([31.9, 31.9], None),
            ([32.0, 5.0], None),
            ([-0.1, 1.0], None),
            ([f64::NAN, 1.0], None),
            ([1e30, 1.0], None),
        ] {
            assert_eq!(l.level_at(sample), want, "{sample:?}");
        }
        // A list without tiles covers nothing; absurd levels are ignored, not shifted.
        assert_eq!(levels(&[]).level_at([1.0, 1.0]), None);
        assert_eq!(levels(&[[0, 0, 40]]).level_at([1.0, 1.0]), None);
    }

    #[test]
    fn the_summary_counts_coarse_pixels_against_all() {
        let mut e = CoarseErrors::default();
        assert_eq!(e.summary(), None);
        for v in [0.1, 0.2, 0.3, 0.4] {
            e.pixels.add(v);
        }
        e.measured = 10;
        let s = e.summary().unwrap();
        assert_eq!((s.share, s.level0_max_px), (0.4, 0.0));
        assert!((s.p999_px - 0.4).abs() < 1e-12, "{s:?}");
        let mut pooled = CoarseErrors::default();
        pooled.merge(&e);
        pooled.merge(&CoarseErrors {
            measured: 10,
            level0_max_px: 0.03,
            ..CoarseErrors::default()
        });
        let s = pooled.summary().unwrap();
        assert_eq!((s.share, s.level0_max_px), (0.2, 0.03));
        let level0_only = CoarseErrors {
            measured: 5,
            ..CoarseErrors::default()
        };
        assert_eq!(level0_only.summary().unwrap().p999_px, 0.0);
    }
}

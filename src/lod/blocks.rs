//! Height bounds per square block of samples, for the methods that cull fixed blocks of the
//! data (tessellation's patch quads, GeoMipMapping's blocks). Read row by row through
//! [`Level0`], so it works on a height map in memory and on a tile pyramid alike (one pass
//! over level 0 at start-up; memory is one row plus the bounds).

use crate::dataset::Level0;
use crate::error::Result;

/// Lowest and highest height of every `quads` x `quads` block of sample quads, row-major
/// (block `(i, j)` covers samples `i*quads ..= (i+1)*quads` in x, clamped to the data, and the
/// same in y: neighbouring blocks share their edge samples).
#[derive(Clone, Debug, PartialEq)]
pub struct BlockBounds {
    pub quads: u32,
    /// Blocks per side: `ceil((samples - 1) / quads)` (at least 1).
    pub cols: u32,
    pub rows: u32,
    /// `[min, max]` per block, row-major, south first.
    pub bounds: Vec<[f32; 2]>,
}

impl BlockBounds {
    pub fn new(data: &dyn Level0, quads: u32) -> Result<Self> {
        let (w, h) = (data.width(), data.height());
        let blocks = |n: u32| (n.saturating_sub(1)).div_ceil(quads).max(1);
        let (cols, rows) = (blocks(w), blocks(h));
        let mut bounds = vec![[f32::INFINITY, f32::NEG_INFINITY]; (cols * rows) as usize];
        let mut row = Vec::with_capacity(w as usize);
        for r in 0..h {
            data.row(r, 0, w - 1, &mut row)?;
            // Block rows holding sample row r: r / quads, and the one below on a shared edge.
            let j_hi = (r / quads).min(rows - 1);
            let j_lo = if r % quads == 0 && r > 0 {
                r / quads - 1
            } else {
                j_hi
            };
            for (c, &v) in row.iter().enumerate() {
                let c = c as u32;
                let i_hi = (c / quads).min(cols - 1);
                let i_lo = if c % quads == 0 && c > 0 {
                    c / quads - 1
                } else {
                    i_hi
                };
                for j in j_lo..=j_hi {
                    for i in i_lo..=i_hi {
                        let b = &mut bounds[(j * cols + i) as usize];
                        b[0] = b[0].min(v);
                        b[1] = b[1].max(v);
                    }
                }
            }
        }
        Ok(BlockBounds {
            quads,
            cols,
            rows,
            bounds,
        })
    }

    /// `[min, max]` of block `(i, j)`.
    pub fn get(&self, i: u32, j: u32) -> [f32; 2] {
        self.bounds[(j * self.cols + i) as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::Heightmap;

    #[test]
    fn bounds_cover_every_sample_of_a_block_including_shared_edges() {
        let (w, h) = (11u32, 7u32);
        let heights: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 101) as f32).collect();
        let data = Heightmap::new("t", w, h, 1.0, heights.clone()).unwrap();
        let b = BlockBounds::new(&data, 4).unwrap();
        assert_eq!((b.cols, b.rows), (3, 2));
        for j in 0..b.rows {
            for i in 0..b.cols {
                let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                for y in (j * 4)..=((j + 1) * 4).min(h - 1) {
                    for x in (i * 4)..=((i + 1) * 4).min(w - 1) {
                        let v = heights[(y * w + x) as usize];
                        lo = lo.min(v);
                        hi = hi.max(v);
                    }
                }
                assert_eq!(b.get(i, j), [lo, hi], "block {i},{j}");
            }
        }
    }
}

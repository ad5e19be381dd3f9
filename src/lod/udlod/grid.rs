//! A tile's triangles per collapse mask: which quadrants of a tile are drawn as their parent
//! grid's quads (docs/udlod.md, "Collapsed quadrants").
//!
//! A tile of `grid` quads per side has four quadrants of `grid / 2` (bit `qx + 2 qy` of a
//! mask, quadrant origin `(qx, qy) * grid / 2`). A quadrant whose vertices odd at the tile's
//! level all lie fully on the parent grid (`select::tile_collapse_mask`) draws the parent
//! grid's `grid / 4` quads per side over its even vertices; the others their own. A mask
//! names the tile's draw: the index buffer holds one index list per mask (`IndexLayout`),
//! and with vertex pulling `pulled_local` in `shaders/udlod.wgsl` walks the same triangles
//! in the same order. At grid 2 a quadrant is one quad: such a tile collapses whole (mask 15,
//! the parent's one quad) or not at all.

use crate::gpu_constants::UDLOD_COLLAPSE_MASKS;

/// Every quadrant collapsed.
pub const ALL_QUADRANTS: u32 = UDLOD_COLLAPSE_MASKS - 1;

/// The quadrants (mask bits) holding grid vertex `local` of a tile of `grid` quads per side:
/// one, two on a middle line, four at the centre.
pub fn quadrants_of(grid: u32, local: [u32; 2]) -> u32 {
    let h = grid / 2;
    let xs = (local[0] <= h) as u32 | ((local[0] >= h) as u32) << 1;
    let ys = (local[1] <= h) as u32 | ((local[1] >= h) as u32) << 1;
    let mut bits = 0;
    for qy in 0..2 {
        for qx in 0..2 {
            if xs & (1 << qx) != 0 && ys & (1 << qy) != 0 {
                bits |= 1 << (qx + 2 * qy);
            }
        }
    }
    bits
}

/// The mask a tile is drawn with when `collapsing` quadrants qualify: at grid 2 all or none.
pub fn drawn_mask(grid: u32, collapsing: u32) -> u32 {
    if grid == 2 && collapsing != ALL_QUADRANTS {
        0
    } else {
        collapsing
    }
}

/// Grid vertices (tile-local) of the triangles of a tile drawn with `mask`, three per
/// triangle: per quadrant (in bit order) its quads row by row, each as (0,0) (1,0) (0,1) and
/// (1,0) (1,1) (0,1) (`lod::brute::grid_indices`' order), a collapsed quadrant's quads twice
/// as large.
pub fn mask_vertices(grid: u32, mask: u32) -> Vec<[u32; 2]> {
    let mask = drawn_mask(grid, mask);
    if grid == 2 && mask == ALL_QUADRANTS {
        return quads(1, 2, [0, 0]);
    }
    let h = grid / 2;
    (0..4)
        .flat_map(|q| {
            let origin = [(q & 1) * h, (q >> 1) * h];
            if mask & (1 << q) != 0 {
                quads(h / 2, 2, origin)
            } else {
                quads(h, 1, origin)
            }
        })
        .collect()
}

/// `n` x `n` quads of side `step` from `origin`, two triangles each.
fn quads(n: u32, step: u32, origin: [u32; 2]) -> Vec<[u32; 2]> {
    let mut out = Vec::with_capacity((6 * n * n) as usize);
    for r in 0..n {
        for c in 0..n {
            let at = |dx: u32, dy: u32| [origin[0] + (c + dx) * step, origin[1] + (r + dy) * step];
            out.extend([at(0, 0), at(1, 0), at(0, 1), at(1, 0), at(1, 1), at(0, 1)]);
        }
    }
    out
}

/// Triangles of a tile drawn with `mask`.
pub fn mask_triangles(grid: u32, mask: u32) -> u64 {
    mask_vertices(grid, mask).len() as u64 / 3
}

/// The index buffer of every mask's triangles, one list after another, and where each is.
pub struct IndexLayout {
    pub indices: Vec<u16>,
    /// Per mask: (first index, index count).
    pub ranges: [(u32, u32); UDLOD_COLLAPSE_MASKS as usize],
}

impl IndexLayout {
    /// Indices name grid vertices `row * (grid + 1) + column` (`indexed_local` in
    /// `shaders/udlod.wgsl`).
    pub fn new(grid: u32) -> Self {
        let row = grid + 1;
        assert!(
            row * row <= u16::MAX as u32 + 1,
            "grid too large for 16-bit indices"
        );
        let mut indices = Vec::new();
        let mut ranges = [(0, 0); UDLOD_COLLAPSE_MASKS as usize];
        for (mask, range) in ranges.iter_mut().enumerate() {
            let first = indices.len() as u32;
            indices.extend(
                mask_vertices(grid, mask as u32)
                    .iter()
                    .map(|&[x, y]| (y * row + x) as u16),
            );
            *range = (first, indices.len() as u32 - first);
        }
        IndexLayout { indices, ranges }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_zero_is_the_tile_grid_and_all_quadrants_the_parent_grid_as_sets() {
        use std::collections::HashSet;
        let triangles = |v: Vec<[u32; 2]>| -> HashSet<[[u32; 2]; 3]> {
            v.chunks(3).map(|t| [t[0], t[1], t[2]]).collect()
        };
        for grid in [2, 4, 8, 16] {
            assert_eq!(
                triangles(mask_vertices(grid, 0)),
                triangles(quads(grid, 1, [0, 0])),
                "grid {grid}"
            );
            assert_eq!(
                triangles(mask_vertices(grid, ALL_QUADRANTS)),
                triangles(quads(grid / 2, 2, [0, 0])),
                "grid {grid}"
            );
            assert_eq!(mask_triangles(grid, 0), 2 * grid as u64 * grid as u64);
            assert_eq!(
                mask_triangles(grid, ALL_QUADRANTS),
                2 * (grid as u64 / 2).pow(2)
            );
        }
        // A partial mask at grid 4: each collapsed quadrant 2 triangles instead of 8;
        // at grid 2 a partial mask draws the whole grid.
        assert_eq!(mask_triangles(4, 0b0101), 8 + 2 + 8 + 2);
        assert_eq!(mask_triangles(2, 0b0101), 8);
    }

    #[test]
    fn quadrants_of_middle_lines_and_centre() {
        assert_eq!(quadrants_of(4, [1, 1]), 0b0001);
        assert_eq!(quadrants_of(4, [3, 1]), 0b0010);
        assert_eq!(quadrants_of(4, [2, 1]), 0b0011);
        assert_eq!(quadrants_of(4, [1, 2]), 0b0101);
        assert_eq!(quadrants_of(4, [2, 2]), 0b1111);
        assert_eq!(quadrants_of(4, [3, 4]), 0b1000);
    }

    #[test]
    fn index_ranges_tile_the_buffer() {
        let layout = IndexLayout::new(4);
        let mut next = 0;
        for (mask, &(first, count)) in layout.ranges.iter().enumerate() {
            assert_eq!(first, next);
            assert_eq!(count as u64, 3 * mask_triangles(4, mask as u32));
            next += count;
        }
        assert_eq!(next as usize, layout.indices.len());
    }
}

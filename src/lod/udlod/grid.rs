//! A tile's triangles per draw mask: which quadrants of a tile are drawn as their own grid,
//! as their parent grid's quads (docs/udlod-rounds.md, "Collapsed quadrants") or not at all
//! (outside the frustum: "Quadrants outside the view").
//!
//! A tile of `grid` quads per side has four quadrants of `grid / 2` (quadrant `q = qx + 2 qy`,
//! origin `(qx, qy) * grid / 2`). A quadrant whose vertices odd at the tile's level all lie
//! fully on the parent grid (`morph::tile_collapse_mask`) draws the parent grid's `grid / 4`
//! quads per side over its even vertices; one whose box lies outside the frustum
//! (`select::quadrants_culled`) draws nothing; the others their own. A [`TileMask`] names the
//! tile's draw: the index buffer holds one index list per mask (`IndexLayout`), and with
//! vertex pulling `pulled_local` in `shaders/udlod.wgsl` walks the same triangles in the same
//! order. At grid 2 a quadrant is one quad: such a tile collapses whole (the parent's one quad,
//! then drawn whole even where some quadrants lie outside the view) or not at all.

use crate::gpu_constants::UDLOD_TILE_MASKS;

/// Every quadrant (mask bits `1 << q`).
pub const ALL_QUADRANTS: u32 = 0b1111;

/// How one quadrant of a drawn tile is drawn: digit `q` (base 3) of a [`TileMask`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QuadrantDraw {
    /// Its own grid of `grid / 2` quads per side.
    Own = 0,
    /// The parent grid's `grid / 4` quads per side over its even vertices.
    Collapsed = 1,
    /// Nothing: its box lies outside the frustum.
    Dropped = 2,
}

/// A tile's draw: quadrant `q`'s [`QuadrantDraw`] is digit `q` of the index in base 3
/// (`tile_mask` in `shaders/udlod_tiling.wgsl` builds it, `pulled_local` in
/// `shaders/udlod.wgsl` reads it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct TileMask(u32);

impl TileMask {
    /// Every quadrant its own grid.
    pub const FULL: TileMask = TileMask(0);

    /// The draw of a tile whose quadrants `collapsing` (bits `1 << q`) lie fully on the parent
    /// grid and `dropped` lie outside the frustum: a dropped quadrant is not drawn; at grid 2
    /// a tile collapses whole (and is then drawn whole unless every quadrant is dropped) or
    /// not at all.
    pub fn new(grid: u32, collapsing: u32, dropped: u32) -> Self {
        let (mut collapsing, mut dropped) = (collapsing & ALL_QUADRANTS, dropped & ALL_QUADRANTS);
        if grid == 2 && dropped != ALL_QUADRANTS {
            if collapsing == ALL_QUADRANTS {
                dropped = 0;
            } else {
                collapsing = 0;
            }
        }
        let digits = (0..4).map(|q| {
            if dropped & 1 << q != 0 {
                QuadrantDraw::Dropped
            } else if collapsing & 1 << q != 0 {
                QuadrantDraw::Collapsed
            } else {
                QuadrantDraw::Own
            }
        });
        TileMask(digits.rev().fold(0, |m, d| 3 * m + d as u32))
    }

    /// Mask `index` (below `UDLOD_TILE_MASKS`), as a draw group or index list names it.
    pub fn from_index(index: u32) -> Self {
        assert!(index < UDLOD_TILE_MASKS, "tile mask {index} out of range");
        TileMask(index)
    }

    pub fn index(self) -> u32 {
        self.0
    }

    /// Every mask, in index order.
    pub fn all() -> impl Iterator<Item = TileMask> {
        (0..UDLOD_TILE_MASKS).map(TileMask)
    }

    /// How quadrant `q` (0..4) is drawn.
    pub fn quadrant(self, q: u32) -> QuadrantDraw {
        match self.0 / 3u32.pow(q) % 3 {
            0 => QuadrantDraw::Own,
            1 => QuadrantDraw::Collapsed,
            _ => QuadrantDraw::Dropped,
        }
    }

    /// The quadrants (bits) drawn as `state`.
    pub fn quadrants(self, state: QuadrantDraw) -> u32 {
        (0..4)
            .filter(|&q| self.quadrant(q) == state)
            .fold(0, |b, q| b | 1 << q)
    }

    /// This mask as a tile of `grid` is drawn (at grid 2 a partly collapsed tile draws its
    /// own grid: [`TileMask::new`]).
    pub fn drawn(self, grid: u32) -> Self {
        let q = |s| self.quadrants(s);
        TileMask::new(grid, q(QuadrantDraw::Collapsed), q(QuadrantDraw::Dropped))
    }
}

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

/// Grid vertices (tile-local) of the triangles of a tile drawn with `mask`, three per
/// triangle: per quadrant (in order) its quads row by row, each as (0,0) (1,0) (0,1) and
/// (1,0) (1,1) (0,1) (`lod::brute::grid_indices`' order), a collapsed quadrant's quads twice
/// as large, a dropped quadrant none.
pub fn mask_vertices(grid: u32, mask: TileMask) -> Vec<[u32; 2]> {
    let mask = mask.drawn(grid);
    if grid == 2 && mask.quadrants(QuadrantDraw::Collapsed) == ALL_QUADRANTS {
        return quads(1, 2, [0, 0]);
    }
    let h = grid / 2;
    (0..4)
        .flat_map(|q| {
            let origin = [(q & 1) * h, (q >> 1) * h];
            match mask.quadrant(q) {
                QuadrantDraw::Own => quads(h, 1, origin),
                QuadrantDraw::Collapsed => quads(h / 2, 2, origin),
                QuadrantDraw::Dropped => Vec::new(),
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
pub fn mask_triangles(grid: u32, mask: TileMask) -> u64 {
    mask_vertices(grid, mask).len() as u64 / 3
}

/// The index buffer of every mask's triangles, one list after another, and where each is.
pub struct IndexLayout {
    pub indices: Vec<u16>,
    /// Per mask (by index): (first index, index count).
    pub ranges: [(u32, u32); UDLOD_TILE_MASKS as usize],
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
        let mut ranges = [(0, 0); UDLOD_TILE_MASKS as usize];
        for (mask, range) in TileMask::all().zip(ranges.iter_mut()) {
            let first = indices.len() as u32;
            indices.extend(
                mask_vertices(grid, mask)
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

    fn collapsed(grid: u32, bits: u32) -> TileMask {
        TileMask::new(grid, bits, 0)
    }

    #[test]
    fn full_mask_is_the_tile_grid_and_all_collapsed_the_parent_grid_as_sets() {
        use std::collections::HashSet;
        let triangles = |v: Vec<[u32; 2]>| -> HashSet<[[u32; 2]; 3]> {
            v.chunks(3).map(|t| [t[0], t[1], t[2]]).collect()
        };
        for grid in [2, 4, 8, 16] {
            let all = collapsed(grid, ALL_QUADRANTS);
            assert_eq!(
                triangles(mask_vertices(grid, TileMask::FULL)),
                triangles(quads(grid, 1, [0, 0])),
                "grid {grid}"
            );
            assert_eq!(
                triangles(mask_vertices(grid, all)),
                triangles(quads(grid / 2, 2, [0, 0])),
                "grid {grid}"
            );
            assert_eq!(
                mask_triangles(grid, TileMask::FULL),
                2 * grid as u64 * grid as u64
            );
            assert_eq!(mask_triangles(grid, all), 2 * (grid as u64 / 2).pow(2));
        }
        // A partial mask at grid 4: each collapsed quadrant 2 triangles instead of 8;
        // at grid 2 a partial mask draws the whole grid.
        assert_eq!(mask_triangles(4, collapsed(4, 0b0101)), 8 + 2 + 8 + 2);
        assert_eq!(mask_triangles(2, collapsed(2, 0b0101)), 8);
    }

    #[test]
    fn dropped_quadrants_draw_nothing_and_win_over_collapsing() {
        // Grid 4: quadrant 0 dropped, 1 collapsed, 2 and 3 their own.
        let m = TileMask::new(4, 0b0011, 0b0001);
        assert_eq!(m.quadrant(0), QuadrantDraw::Dropped);
        assert_eq!(m.quadrant(1), QuadrantDraw::Collapsed);
        assert_eq!(m.quadrant(2), QuadrantDraw::Own);
        assert_eq!(mask_triangles(4, m), 2 + 8 + 8);
        assert!(mask_vertices(4, m).iter().all(|v| v[0] >= 2 || v[1] >= 2));
        assert_eq!(mask_triangles(4, TileMask::new(4, 0, ALL_QUADRANTS)), 0);
        // Grid 2: a collapsing tile is drawn whole (its one parent quad) unless all four are
        // dropped; one that does not collapse drops its quadrants' quads.
        assert_eq!(
            TileMask::new(2, ALL_QUADRANTS, 0b0110),
            collapsed(2, ALL_QUADRANTS)
        );
        assert_eq!(mask_triangles(2, TileMask::new(2, 0b0111, 0b0110)), 4);
        assert_eq!(mask_triangles(2, TileMask::new(2, ALL_QUADRANTS, 15)), 0);
    }

    #[test]
    fn masks_round_trip_their_quadrants() {
        assert_eq!(TileMask::all().count(), UDLOD_TILE_MASKS as usize);
        for m in TileMask::all() {
            let q = |s| m.quadrants(s);
            let (c, d) = (q(QuadrantDraw::Collapsed), q(QuadrantDraw::Dropped));
            assert_eq!(c & d, 0);
            assert_eq!(c | d | q(QuadrantDraw::Own), ALL_QUADRANTS);
            assert_eq!(TileMask::new(8, c, d), m, "{m:?}");
            assert_eq!(TileMask::from_index(m.index()), m);
        }
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
        for (mask, &(first, count)) in TileMask::all().zip(&layout.ranges) {
            assert_eq!(first, next);
            assert_eq!(count as u64, 3 * mask_triangles(4, mask));
            next += count;
        }
        assert_eq!(next as usize, layout.indices.len());
    }
}

//! The prepass's coarse levels decided on the host (the seed).
//!
//! The GPU refines the quadtree one level per pass, and each pass is two dispatches and their
//! barriers (`prepare`, `refine`). The coarse levels hold a handful of tiles, so on a device at
//! its floor (the H200's ~1 ms frame) or on llvmpipe (whose small dispatches wait for its
//! worker threads) those passes, not the tiles, set the prepass's time. The host walks them
//! instead with the reference selection's decisions ([`select::tile_splits`],
//! [`select::tile_culled`]) and hands the GPU's first pass the walk's frontier as its
//! parents: every tile the walk kept that does not split (at any level), and the last level
//! walked. The GPU's passes then run only from that level down (docs/udlod-rounds.md, "The seed").
//!
//! The walk applies the passes' capacity rule level by level (a level splits only if all of
//! its splits fit the lists) and stops before a level that would not fit, leaving that level
//! to the GPU's first pass, which refuses it by the same rule: the selection is the one the
//! GPU would have made from the root.

use super::levels::{Levels, Tile};
use super::params::SelectionParams;
use super::select::{self, Visibility};
use crate::gpu_constants::{
    UDLOD_TILE_CULLED, UDLOD_TILE_DECIDED, UDLOD_TILE_INSIDE, UDLOD_TILE_OUTSIDE, UDLOD_TILE_SPLITS,
};

/// The first pass's parents, as the host uploads them.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Seed {
    /// `[x, y, lod, flags]` (`Tile` in `shaders/include/udlod_common.wgsl`, flags
    /// `UDLOD_TILE_*`): the walk's tiles that do not split, then its last level's.
    pub tiles: Vec<[u32; 4]>,
    /// Tiles of `tiles` that want to split (the first pass's split requests).
    pub requests: u32,
    /// Passes the GPU needs after the seed: one, plus one per level below the last level
    /// walked when some of its tiles split.
    pub passes: u32,
}

/// The lists a frame's tiles go into: final-list entries and temporary-list entries
/// (`udlod.sizes.z` and `.w`).
#[derive(Clone, Copy, Debug)]
pub struct ListCapacity {
    pub final_tiles: u32,
    pub temp_tiles: u32,
}

/// Tile `t` with the flags the GPU's `decided` gives it: outside the data, else culled (when
/// culling is on), else splitting, and with culling whether its box lies inside the frustum
/// ([`select::tile_inside`]).
pub fn decided(levels: &Levels, p: &SelectionParams, t: Tile) -> [u32; 4] {
    let mut flags = UDLOD_TILE_DECIDED;
    if !levels.inside(t) {
        return [t.x, t.y, t.lod, flags | UDLOD_TILE_OUTSIDE];
    }
    match p.cull.then(|| select::tile_visibility(levels, p, t)) {
        Some(Visibility::Culled) => return [t.x, t.y, t.lod, flags | UDLOD_TILE_CULLED],
        Some(Visibility::Inside) => flags |= UDLOD_TILE_INSIDE,
        Some(Visibility::Crossing) | None => {}
    }
    if select::tile_splits(levels, p, t) {
        flags |= UDLOD_TILE_SPLITS;
    }
    [t.x, t.y, t.lod, flags]
}

fn splits(tile: &[u32; 4]) -> bool {
    tile[3] & !UDLOD_TILE_INSIDE == UDLOD_TILE_DECIDED | UDLOD_TILE_SPLITS
}

/// The walk from the root: levels are walked while the frontier stays within `most` tiles and
/// the level's splits fit `lists` (`prepare` in `shaders/udlod_tiling.wgsl`: every split
/// reserves 3 more final entries, parents and children share the temporary list).
pub fn seed(levels: &Levels, p: &SelectionParams, lists: ListCapacity, most: u32) -> Seed {
    let root = Tile {
        x: 0,
        y: 0,
        lod: levels.root_lod,
    };
    let mut done: Vec<[u32; 4]> = Vec::new();
    let mut layer = vec![decided(levels, p, root)];
    loop {
        let requests = layer.iter().filter(|t| splits(t)).count() as u64;
        // Every tile not yet split is a reserved leaf (1 + 3 per split so far).
        let parents = (done.len() + layer.len()) as u64;
        let fits = parents + 3 * requests <= lists.final_tiles as u64
            && parents + 4 * requests <= lists.temp_tiles as u64;
        if requests == 0 || !fits || parents + 3 * requests > most as u64 {
            let lod = layer[0][2];
            done.extend_from_slice(&layer);
            return Seed {
                tiles: done,
                requests: requests as u32,
                passes: if requests == 0 { 1 } else { lod + 1 },
            };
        }
        let mut next = Vec::with_capacity(4 * requests as usize);
        for t in layer {
            if !splits(&t) {
                done.push(t);
                continue;
            }
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let child = Tile {
                    x: t[0] * 2 + dx,
                    y: t[1] * 2 + dy,
                    lod: t[2] - 1,
                };
                next.push(decided(levels, p, child));
            }
        }
        layer = next;
    }
}

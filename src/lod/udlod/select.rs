//! UDLOD's tile selection on the CPU: tile distances, culling and reach, the draw masks, and
//! a reference implementation of the GPU's tile selection (tests compare the GPU's final tile
//! list against it), over the per-frame inputs of [`super::params`]. Arithmetic that must
//! agree with `shaders/udlod_tiling.wgsl` is written in f32 in the same order.

use glam::Vec3;

use super::field::SplitField;
use super::grid::TileMask;
use super::levels::{Levels, QUAD, Tile};
use super::morph::{tile_collapse_mask, walk_end};
use super::params::SelectionParams;

/// Distance from the LOD viewer to the nearest point of the tile's rectangle at the reference
/// height, in the LOD metric (grid-frame offsets times [`SelectionParams::stretch`]).
pub fn tile_distance(levels: &Levels, p: &SelectionParams, t: Tile) -> f32 {
    let span = (levels.grid_size << t.lod) as i32;
    let [x, y] = [t.x as i32 * span, t.y as i32 * span];
    rect_distance(p, [x, y], [x + span, y + span])
}

/// Distance from the LOD viewer to the nearest point of the grid rectangle from sample `c0`
/// to sample `c1` at the reference height, in the LOD metric ([`tile_distance`] for any
/// rectangle).
pub fn rect_distance(p: &SelectionParams, c0: [i32; 2], c1: [i32; 2]) -> f32 {
    let lo = p.from_viewer(c0);
    let hi = p.from_viewer(c1);
    let dx = lo[0].max(0.0f32.min(hi[0])) * p.stretch[0];
    let dy = lo[1].max(0.0f32.min(hi[1])) * p.stretch[1];
    Vec3::new(dx, dy, p.viewer[2]).length()
}

/// Does the tile split? Its smallest scaled distance (field minimum x distance) against the
/// level's split distance, i.e. its nearest point against the largest split distance of its
/// corners (`refine` in `udlod_tiling.wgsl`).
pub fn tile_splits(levels: &Levels, p: &SelectionParams, t: Tile) -> bool {
    let field_min = p.field.tile_range(levels, t)[0];
    t.lod > 0 && field_min * tile_distance(levels, p, t) < p.field.split[t.lod as usize]
}

/// Is the tile's box outside the frustum? The box is the rectangle its morphed vertices can
/// reach ([`tile_reach`]), clamped to the data, by the heights of the tile that holds it; on
/// the earth the curved box over it ([`crate::geo::EarthCull::outside`], in f64: it decides as the GPU's
/// f32 `earth_box` except within the GPU's rounding of the boundary; tests/udlod.rs
/// brackets it). `decided` (`reach_box`, `box_outside`) in `shaders/udlod_tiling.wgsl`.
pub fn tile_culled(levels: &Levels, p: &SelectionParams, t: Tile) -> bool {
    tile_visibility(levels, p, t) == Visibility::Culled
}

/// Where a tile's box lies against the frustum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Visibility {
    /// Outside a plane by more than the margin ([`tile_culled`]).
    Culled,
    /// Across a plane.
    Crossing,
    /// Inside every plane ([`tile_inside`]).
    Inside,
}

/// [`tile_culled`] and [`tile_inside`] from one box (`decided` in `udlod_tiling.wgsl` builds
/// it once too).
pub fn tile_visibility(levels: &Levels, p: &SelectionParams, t: Tile) -> Visibility {
    let span = (levels.grid_size << t.lod) as i32;
    rect_visibility(levels, p, tile_reach(levels, p, t), span)
}

/// The quadrants (bits `1 << q`, [`super::grid`]) of final tile `t` whose box lies outside the
/// frustum: drawn as nothing (docs/udlod-rounds.md, "Quadrants outside the view"). Each box is
/// [`tile_culled`]'s for the quadrant's rectangle ([`quadrant_reach`]); none without culling
/// or with `cull_quadrants` off. `quadrant_square` and `reach_culled` in `shaders/udlod_tiling.wgsl`.
pub fn quadrants_culled(levels: &Levels, p: &SelectionParams, t: Tile) -> u32 {
    if !(p.cull && p.cull_quadrants) || tile_inside(levels, p, t) {
        return 0;
    }
    (0..4)
        .filter(|&q| quadrant_culled(levels, p, t, q))
        .fold(0, |bits, q| bits | 1 << q)
}

/// How final tile `t` is drawn: its quadrants on the parent grid ([`tile_collapse_mask`]) and
/// those outside the frustum ([`quadrants_culled`]) as one mask (`tile_mask` in
/// `shaders/udlod_tiling.wgsl`).
pub fn tile_mask(levels: &Levels, p: &SelectionParams, t: Tile) -> TileMask {
    let collapsing = tile_collapse_mask(levels, p, t);
    TileMask::new(levels.grid_size, collapsing, quadrants_culled(levels, p, t))
}

/// Quadrant `q` of final tile `t` tested on its own ([`quadrants_culled`] without the
/// shortcut of [`tile_inside`]).
pub fn quadrant_culled(levels: &Levels, p: &SelectionParams, t: Tile, q: u32) -> bool {
    let half = (levels.grid_size << t.lod) as i32 / 2;
    rect_visibility(levels, p, quadrant_reach(levels, p, t, q), half) == Visibility::Culled
}

/// The box of `reach` (its rectangle x the heights of the tile holding it) against the
/// frustum: culled when outside a plane by more than a margin of 1e-3 of `span` samples (the
/// rectangle's side before its walks; it keeps rounding from culling a touching box), else
/// inside or crossing.
fn rect_visibility(
    levels: &Levels,
    p: &SelectionParams,
    reach: TileReach,
    span: i32,
) -> Visibility {
    let (c0, c1) = (reach.lo, reach.hi);
    let heights = levels.tile_min_max(reach.heights);
    let margin = 1e-3 * (span as f32 * p.spacing);
    let (outside, inside) = match &p.earth {
        Some(earth) => earth.visibility(&p.frustum, c0, c1, heights, margin as f64),
        None => {
            let outside = flat_box_outside(p, c0, c1, heights, margin);
            (outside, !outside && flat_box_inside(p, c0, c1, heights))
        }
    };
    match (outside, inside) {
        (true, _) => Visibility::Culled,
        (false, true) => Visibility::Inside,
        (false, false) => Visibility::Crossing,
    }
}

/// Does tile `t`'s box ([`tile_culled`]'s) lie inside every plane of the frustum? Then no
/// quadrant of it is culled, so [`quadrants_culled`] tests none, as the prepass does
/// (`UDLOD_TILE_INSIDE`, set by `decided` in `shaders/udlod_tiling.wgsl` and
/// [`super::seed::decided`]). Why none is: every morphed vertex of a quadrant lies in the
/// quadrant's box (what makes its test sound) and in the tile's, so inside the frustum; a box
/// holding a point inside every plane is outside none. (The flat world's quadrant boxes also
/// lie within the tile's; the earth's need not, each being grown by its own curvature.)
pub fn tile_inside(levels: &Levels, p: &SelectionParams, t: Tile) -> bool {
    tile_visibility(levels, p, t) == Visibility::Inside
}

/// Is the box over the grid rectangle from sample `c0` to `c1`, `heights` (min, max) high,
/// inside every plane of the frustum (its corner nearest each plane's back side on or in front
/// of it)? `box_inside` in `shaders/include/terrain_common.wgsl`.
pub fn flat_box_inside(p: &SelectionParams, c0: [i32; 2], c1: [i32; 2], heights: [f32; 2]) -> bool {
    plane_distances(p, c0, c1, heights, Corner::Back).all(|d| d >= 0.0)
}

/// Is the box over the grid rectangle from sample `c0` to `c1`, `heights` (min, max) high, more
/// than `margin` metres outside a plane of the frustum? The flat world's test of
/// [`tile_culled`].
pub fn flat_box_outside(
    p: &SelectionParams,
    c0: [i32; 2],
    c1: [i32; 2],
    heights: [f32; 2],
    margin: f32,
) -> bool {
    plane_distances(p, c0, c1, heights, Corner::Front).any(|d| d < -margin)
}

/// Which corner of a box [`plane_distances`] measures: the one furthest along each plane's
/// normal, or the one furthest against it.
#[derive(Clone, Copy, PartialEq)]
enum Corner {
    Front,
    Back,
}

/// Per frustum plane, the signed distance of the flat box's `corner` (the arithmetic of
/// `box_outside` and `box_inside` in `shaders/include/terrain_common.wgsl`).
fn plane_distances(
    p: &SelectionParams,
    c0: [i32; 2],
    c1: [i32; 2],
    [zmin, zmax]: [f32; 2],
    corner: Corner,
) -> impl Iterator<Item = f32> + '_ {
    let lo = p.relative(c0);
    let hi = p.relative(c1);
    let (zlo, zhi) = (zmin - p.camera_z, zmax - p.camera_z);
    p.frustum.iter().map(move |pl| {
        let pick = |n: f32, low: f32, high: f32| {
            if (n >= 0.0) == (corner == Corner::Front) {
                high
            } else {
                low
            }
        };
        let (x, y, z) = (
            pick(pl[0], lo[0], hi[0]),
            pick(pl[1], lo[1], hi[1]),
            pick(pl[2], zlo, zhi),
        );
        pl[0] * x + pl[1] * y + pl[2] * z + pl[3]
    })
}

/// Where a tile's morphed vertices can lie ([`tile_reach`]): the rectangle of samples from `lo`
/// to `hi` (both included), and the tile whose statistics bound the heights there.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileReach {
    pub lo: [i32; 2],
    pub hi: [i32; 2],
    pub heights: Tile,
}

/// The rectangle a tile's morphed vertices can reach. A vertex's walk
/// ([`super::morph::morph_cascade`]) only moves towards lower coordinates, and where it stays within the
/// tile's first `cascade_levels` levels it ends inside the tile; past them the point it has
/// reached is one of the tile's corners, whose own walk it then follows. So every vertex
/// (each a blend of its walk's points) lies between the lowest point of the corners' walks
/// ([`walk_end`]) and the tile's far corner. With a bounded walk (`morph_levels` at most
/// `cascade_levels`, the reach term of the split field) the corners never move and this is
/// the tile itself. The heights: those of the smallest tile, the tile or an ancestor, that
/// holds the rectangle (its samples bound every height sampled there). `tile_reach` in
/// `shaders/udlod_tiling.wgsl`.
pub fn tile_reach(levels: &Levels, p: &SelectionParams, t: Tile) -> TileReach {
    let span = (levels.grid_size << t.lod) as i32;
    rect_reach(levels, p, tile_origin(levels, t), span, t.lod, t)
}

/// The rectangle quadrant `q` of tile `t`'s morphed vertices can reach. A quadrant is a square
/// of `grid / 2 << lod` samples aligned to its side, so [`tile_reach`]'s argument holds for it
/// as for a tile: a walk inside it ends inside it or at one of its corners. Its heights: from
/// the tile of the level below that covers it (for a level-0 tile the tile itself). `rect_reach`
/// in `shaders/udlod_tiling.wgsl`.
pub fn quadrant_reach(levels: &Levels, p: &SelectionParams, t: Tile, q: u32) -> TileReach {
    let half = (levels.grid_size << t.lod) as i32 / 2;
    let o = tile_origin(levels, t);
    let (qx, qy) = (q & 1, q >> 1);
    let c0 = [o[0] + qx as i32 * half, o[1] + qy as i32 * half];
    // The quadrant's tile one level down, unless the tile is level 0 or that tile lies past
    // the data's edge (the quadrant's vertices are then clamped onto the edge).
    let below = Tile {
        x: 2 * t.x + qx,
        y: 2 * t.y + qy,
        lod: t.lod.saturating_sub(1),
    };
    let heights = if t.lod > 0 && levels.inside(below) {
        below
    } else {
        t
    };
    rect_reach(levels, p, c0, half, t.lod, heights)
}

fn tile_origin(levels: &Levels, t: Tile) -> [i32; 2] {
    let span = (levels.grid_size << t.lod) as i32;
    [t.x as i32 * span, t.y as i32 * span]
}

/// The reach of the square of `span` samples from `c0` whose grid points walk from level
/// `lod`, with the heights of the smallest tile from `heights` up that holds it.
fn rect_reach(
    levels: &Levels,
    p: &SelectionParams,
    c0: [i32; 2],
    span: i32,
    lod: u32,
    heights: Tile,
) -> TileReach {
    let (w, h) = (levels.width as i32 - 1, levels.height as i32 - 1);
    let hi = [(c0[0] + span).min(w), (c0[1] + span).min(h)];
    let lo = QUAD.iter().fold(c0, |lo, &(i, j)| {
        let corner = [c0[0] + i as i32 * span, c0[1] + j as i32 * span];
        let end = walk_end(levels, p, corner, lod);
        [lo[0].min(end[0]), lo[1].min(end[1])]
    });
    // A quadrant past the data's edge: its vertices are clamped onto the edge.
    let lo = [lo[0].min(hi[0]), lo[1].min(hi[1])];
    TileReach { lo, hi, heights }.with_heights_from(levels, heights)
}

impl TileReach {
    /// `heights`: `start` or the smallest of its ancestors whose rectangle holds `lo`.
    fn with_heights_from(mut self, levels: &Levels, start: Tile) -> Self {
        let mut heights = start;
        while heights.lod < levels.root_lod && {
            let side = (levels.grid_size << heights.lod) as i32;
            self.lo[0] < heights.x as i32 * side || self.lo[1] < heights.y as i32 * side
        } {
            heights = Tile {
                x: heights.x / 2,
                y: heights.y / 2,
                lod: heights.lod + 1,
            };
        }
        self.heights = heights;
        self
    }
}

/// The reference selection: the same decisions as the GPU's refine passes, without capacity
/// limits. Returns the final (drawn) tiles.
pub fn select_tiles(levels: &Levels, p: &SelectionParams) -> Vec<Tile> {
    let mut out = Vec::new();
    walk(levels, p, |t, splits| {
        if !splits {
            out.push(t);
        }
    });
    out
}

/// Final-list entries the refinement reserves for `p`: one root leaf, 3 more per split of a
/// tile the frustum keeps (`refine` in `udlod_tiling.wgsl`); what [`reserved_leaves_bound`]
/// bounds.
pub fn reserved_leaves(levels: &Levels, p: &SelectionParams) -> u64 {
    1 + 3 * splits_per_level(levels, p).iter().sum::<u64>()
}

/// The tiles of each level (index = level) that split for `p`.
pub fn splits_per_level(levels: &Levels, p: &SelectionParams) -> Vec<u64> {
    let mut splits = vec![0; levels.levels() as usize];
    walk(levels, p, |t, s| splits[t.lod as usize] += s as u64);
    splits
}

/// The refinement's walk from the root, level by level: `kept(tile, splits)` for every tile
/// on the data that the frustum keeps; the children of those that split are walked next.
fn walk(levels: &Levels, p: &SelectionParams, mut kept: impl FnMut(Tile, bool)) {
    let mut layer = vec![Tile {
        x: 0,
        y: 0,
        lod: levels.root_lod,
    }];
    while !layer.is_empty() {
        let mut next = Vec::new();
        for t in layer {
            if !levels.inside(t) || (p.cull && tile_culled(levels, p, t)) {
                continue;
            }
            let splits = tile_splits(levels, p, t);
            kept(t, splits);
            if splits {
                next.extend(QUAD.map(|(dx, dy)| Tile {
                    x: t.x * 2 + dx,
                    y: t.y * 2 + dy,
                    lod: t.lod - 1,
                }));
            }
        }
        layer = next;
    }
}

/// An upper bound, known before the prepass, on the final-list entries a selection with this
/// split field and LOD metric `stretch` reserves, wherever the viewer is and whatever the
/// frustum culls: the refinement starts from one root leaf and every split reserves 3 more
/// (`refine` in `udlod_tiling.wgsl`; `select_tiles` here). A tile splits only when its
/// nearest point is nearer than its split distance `s` (`m_min * d < D`, `m_min >= 1`, and
/// `d` at least the horizontal part of the distance, [`tile_distance`]). So for any `t`, the
/// tiles of a level that split are at most the `k(t)` ranked above `t` plus those within
/// `t` of the viewer, whose rectangles meet the ellipse of radius `t` in the stretched metric:
/// at most `floor(2 t / (stretch S)) + 2` tiles of side `S` metres along each axis (`t` taken
/// 1e-4 larger for the GPU's f32 rounding). The bound takes the best `t` among the field's
/// [`SplitField::split_ranks`]. Used to size the tile lists before each frame (`Udlod::update`).
pub fn reserved_leaves_bound(levels: &Levels, field: &SplitField, stretch: [f32; 2]) -> u64 {
    let splits: u64 = (1..=levels.root_lod)
        .map(|lod| level_splits_bound(levels, field, stretch, lod))
        .sum();
    1 + 3 * splits
}

/// [`reserved_leaves_bound`]'s bound on the tiles of level `lod` (>= 1) that split.
pub fn level_splits_bound(levels: &Levels, field: &SplitField, stretch: [f32; 2], lod: u32) -> u64 {
    let side = (levels.grid_size << lod) as f64 * levels.spacing;
    let (nx, ny) = levels.tiles_per_side[lod as usize];
    let near = |t: f32| {
        // 1e-4 wider: the GPU's f32 test may split a tile a rounding beyond `t`.
        let reach = 2.0 * t as f64 * (1.0 + 1e-4);
        let along = |s: f32, n: u32| {
            let s = (s as f64).max(f64::MIN_POSITIVE);
            ((reach / (s * side)).floor().min(n as f64) as u64 + 2).min(n as u64)
        };
        along(stretch[0], nx) * along(stretch[1], ny)
    };
    (field.split_ranks[lod as usize].iter())
        .map(|&(k, t)| k as u64 + near(t))
        .min()
        .unwrap_or(0)
}

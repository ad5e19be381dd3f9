// UDLOD tiling prepass: the quadtree is refined one level per pass. The coarse levels are
// walked on the host (src/lod/udlod/seed.rs): the first pass's parents are that walk's
// frontier (tiles of several levels that do not split, and the last level walked), copied to
// the front of the temporary list; the passes go on from there. Each pass is a 1-thread
// `prepare` (turns the children of the last pass into this pass's parents and writes the
// indirect dispatch size) and a `refine` over those parents. One temporary list is used from
// both ends: even passes read parents from the front and write children from the back, odd
// passes the other way round. Tiles that do not split go to the final list's first half,
// unsorted, each with its draw group (static or morphing, and which quadrants collapse onto
// the parent's grid or lie outside the view); `finish` writes one indirect draw per group
// (one instance per tile) and `scatter` sorts the tiles by group into the list's second
// half, which the draws read.
//
// Capacity: a pass splits only if all of its splits fit (3 more final-list entries each: a
// split turns one would-be leaf into four, and 4 temporary slots). The splits are known
// before the pass: whoever writes a tile (the previous pass, or the host for the seed, which
// applies this rule to the levels it walks and leaves a level that does not fit to the first
// pass) decides it (`decided`: flags in `Tile.pad`) and counts it in `split_requests` when it will
// want to split. Otherwise no tile of that pass
// splits, so the whole view stops one level early: coarser, but a selection whose finest
// level is that pass's, crack-free like any other. Refusing single tiles instead left
// tiles unsplit nearer than their split distance, whose finer neighbours are not morphed onto
// them: cracks (docs/udlod.md "Capacity"). `overflow` counts the tiles that wanted to split and could not. Each
// workgroup reserves its splits' and leaves' entries with one atomic per list (`refine`).

//!include terrain_common.wgsl
//!include udlod_common.wgsl
//!include udlod_morph.wgsl

// Every entry point writes each workgroup variable before reading it (`refine` zeroes its
// counters and per-parent flags itself, and reads a base or rank only where it wrote one;
// `finish` writes all three tables before its barrier), so naga's zero-fill of workgroup
// memory is left out: on Mesa 22.3 it was a fifth of the prepass (build.rs,
// docs/architecture.md "Workgroup memory written first").
//!workgroup-memory written-first

// One indirect draw: `VkDrawIndexedIndirectCommand`, or with vertex pulling
// `VkDrawIndirectCommand` in its first four words (vertex count, instances, first vertex,
// first instance) and the fifth unused.
struct IndirectDraw {
    index_count: u32,
    instance_count: u32,
    first_index: u32,
    vertex_offset: u32,
    first_instance: u32,
}

// Draw groups: static tiles per draw mask (`tile_mask`), then morphing ones (`draw_group`).
const DRAW_GROUPS: u32 = 2u * UDLOD_TILE_MASKS;

struct TilingState {
    // vkCmdDispatchIndirect arguments of the next refine pass (after `finish`: of `scatter`).
    dispatch_x: u32,
    dispatch_y: u32,
    dispatch_z: u32,
    pass_index: u32,
    parent_count: u32,
    child_count: atomic<u32>,
    // Final tiles, written unsorted into the final list's first half.
    final_count: atomic<u32>,
    reserved_leaves: atomic<u32>,
    overflow: atomic<u32>,
    culled: atomic<u32>,
    // Passes begun this frame (the state is zero-filled before the first).
    passes_started: u32,
    // 1 when this pass's splits fit the lists, else 0.
    splits_allowed: u32,
    // Tiles written for the next pass that will want to split there.
    split_requests: atomic<u32>,
    // Draws with tiles (`finish`): the static groups' first in `draws`, the morphing ones'
    // from entry `UDLOD_TILE_MASKS` (read by `vkCmdDraw*IndirectCount`).
    static_draws: u32,
    morphing_draws: u32,
    // Final tiles per draw group, and (`finish`) where each group starts in the sorted half.
    group_count: array<atomic<u32>, DRAW_GROUPS>,
    group_first: array<u32, DRAW_GROUPS>,
    // The draws of the groups with tiles (`finish`), the static ones' (drawn with back-face
    // culling by default) from entry 0 and the morphing ones' (without: docs/udlod.md,
    // "Pinholes far away and back faces") from entry `UDLOD_TILE_MASKS`, each run followed
    // by draws of no instance.
    draws: array<IndirectDraw, DRAW_GROUPS>,
}

@group(1) @binding(1) var<storage, read_write> state: TilingState;
@group(1) @binding(2) var<storage, read_write> temp_tiles: array<Tile>;
@group(1) @binding(3) var<storage, read_write> final_tiles: array<Tile>;
@group(1) @binding(4) var<storage, read> min_max: array<vec2<f32>>;

@compute @workgroup_size(1)
fn prepare() {
    let pass_index = state.passes_started;
    state.passes_started = pass_index + 1u;
    state.pass_index = pass_index;
    var parents: u32;
    var requests: u32;
    if pass_index == 0u {
        // First pass: the host's seed (the coarse levels' frontier, every tile of it a
        // reserved leaf), copied to the front of the list.
        parents = udlod.seed.x;
        requests = udlod.seed.y;
        atomicStore(&state.final_count, 0u);
        atomicStore(&state.reserved_leaves, parents);
        atomicStore(&state.overflow, 0u);
        atomicStore(&state.culled, 0u);
    } else {
        parents = atomicLoad(&state.child_count);
        requests = atomicLoad(&state.split_requests);
    }
    state.parent_count = parents;
    // This pass's splits: 3 more final entries each; parents and children share the
    // temporary list.
    let leaves = atomicLoad(&state.reserved_leaves);
    let fits = leaves + 3u * requests <= udlod.sizes.z && parents + 4u * requests <= udlod.sizes.w;
    state.splits_allowed = select(0u, 1u, fits);
    atomicStore(&state.split_requests, 0u);
    atomicStore(&state.child_count, 0u);
    // Four invocations per parent (`refine`), in rows of at most `udlod.counts.y` workgroups
    // (the setting `dispatch_row`: 65,535, the least maxComputeWorkGroupCount a device may
    // have).
    let groups = (4u * parents + UDLOD_WORKGROUP - 1u) / UDLOD_WORKGROUP;
    let row = max(udlod.counts.y, 1u);
    state.dispatch_x = min(groups, row);
    state.dispatch_y = (groups + row - 1u) / row;
    state.dispatch_z = 1u;
}

fn parent_slot(i: u32) -> u32 {
    if (state.pass_index & 1u) == 0u {
        return i;
    }
    return udlod.sizes.w - 1u - i;
}

fn child_slot(i: u32) -> u32 {
    if (state.pass_index & 1u) == 0u {
        return udlod.sizes.w - 1u - i;
    }
    return i;
}

// Heights bounding the tile: its own, or for a level-0 tile (none stored when the root is
// coarser) its parent's (mirrors `Levels::stats_tile` in src/lod/udlod/levels.rs).
fn tile_min_max(t: Tile) -> vec2<f32> {
    var s = t;
    if t.lod == 0u && udlod.sizes.y >= 1u {
        s = Tile(t.x / 2u, t.y / 2u, 1u, 0u);
    }
    let level = udlod.levels[s.lod];
    return min_max[level.x + s.y * level.y + s.x];
}

// Distance from the LOD viewer to the nearest point of the tile's rectangle at the reference
// height, in the LOD metric (mirrors `tile_distance` in src/lod/udlod/select.rs).
fn tile_distance(t: Tile) -> f32 {
    let span = i32(udlod.sizes.x << t.lod);
    let lo = viewer_xy(vec2<i32>(i32(t.x) * span, i32(t.y) * span));
    let hi = viewer_xy(vec2<i32>((i32(t.x) + 1) * span, (i32(t.y) + 1) * span));
    let d = max(lo, min(vec2<f32>(0.0), hi)) * udlod.metric.xy;
    return length(vec3<f32>(d, udlod.viewer.z));
}

// The rectangle (samples `lo` to `hi`, both included) a tile's morphed vertices can reach:
// from the lowest point of its corners' walks to its far corner, clamped to the data, and the
// smallest tile (itself or an ancestor) holding it, whose heights bound it (mirrors
// `tile_reach` in src/lod/udlod/select.rs, which says why), with those heights.
struct TileReach {
    lo: vec2<i32>,
    hi: vec2<i32>,
    heights: Tile,
    min_max: vec2<f32>,
}

// A square of `span` samples from `c0` whose grid points walk from level `lod`, and the
// tile from which the heights bounding its reach are looked for (`reach_of`): a tile
// (`tile_square`) or a final tile's quadrant (`quadrant_square`).
struct ReachSquare {
    c0: vec2<i32>,
    span: i32,
    lod: u32,
    heights: Tile,
}

// What a reach reads first, all at once (the prepass waits on memory: on NVIDIA a pass
// lasts as long as its slowest invocation's chain of reads): the corners' first walk steps
// (`walk_on`; most walks end there) and the heights of the square's own tile (re-read only
// when the reach leaves it).
struct ReachReads {
    first: vec4<u32>,
    moves: vec4<bool>,
    min_max: vec2<f32>,
}

fn tile_square(t: Tile) -> ReachSquare {
    let span = i32(udlod.sizes.x << t.lod);
    return ReachSquare(vec2<i32>(i32(t.x), i32(t.y)) * span, span, t.lod, t);
}

fn square_corner(s: ReachSquare, k: u32) -> vec2<i32> {
    return s.c0 + vec2<i32>(i32(k & 1u), i32(k >> 1u)) * s.span;
}

fn reach_reads(s: ReachSquare) -> ReachReads {
    let first = vec4<u32>(
        next_odd_level(square_corner(s, 0u), s.lod),
        next_odd_level(square_corner(s, 1u), s.lod),
        next_odd_level(square_corner(s, 2u), s.lod),
        next_odd_level(square_corner(s, 3u), s.lod),
    );
    let at = vec4<u32>(
        first_read_level(first.x),
        first_read_level(first.y),
        first_read_level(first.z),
        first_read_level(first.w),
    );
    let moves = vec4<bool>(
        morph_moves(square_corner(s, 0u), at.x),
        morph_moves(square_corner(s, 1u), at.y),
        morph_moves(square_corner(s, 2u), at.z),
        morph_moves(square_corner(s, 3u), at.w),
    );
    return ReachReads(first, moves, tile_min_max(s.heights));
}

// The reach of a square from its first reads (`reach_reads`), with the heights of the smallest
// tile from `heights` up that holds it (mirrors `rect_reach` in src/lod/udlod/select.rs): the
// walks that move go on one by one.
fn reach_of(s: ReachSquare, reads: ReachReads) -> TileReach {
    let last = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    var r: TileReach;
    r.hi = min(s.c0 + vec2<i32>(s.span), last);
    let moves = (reads.first < vec4<u32>(udlod.sizes.y)) & reads.moves;
    let f = reads.first;
    r.lo = min(
        min(walk_past(square_corner(s, 0u), f.x, moves.x), walk_past(square_corner(s, 1u), f.y, moves.y)),
        min(walk_past(square_corner(s, 2u), f.z, moves.z), walk_past(square_corner(s, 3u), f.w, moves.w)),
    );
    // A quadrant past the data's edge: its vertices are clamped onto the edge.
    r.lo = min(r.lo, r.hi);
    r.heights = s.heights;
    loop {
        let side = i32(udlod.sizes.x << r.heights.lod);
        let origin = vec2<i32>(i32(r.heights.x), i32(r.heights.y)) * side;
        if r.heights.lod >= udlod.sizes.y || all(r.lo >= origin) {
            break;
        }
        r.heights = Tile(r.heights.x / 2u, r.heights.y / 2u, r.heights.lod + 1u, 0u);
    }
    r.min_max = reads.min_max;
    if r.heights.lod != s.heights.lod {
        r.min_max = tile_min_max(r.heights);
    }
    return r;
}

// The box of a reach: its rectangle x the heights of the tile holding it, camera-relative; on
// the earth the curved box over it (`earth_box`, the one every method culls with there).
fn reach_box(r: TileReach) -> Box3 {
    let mm = r.min_max;
    if EARTH_WORLD {
        return earth_box(r.lo, r.hi, mm);
    }
    let z = mm - vec2<f32>(frame.camera_offset.z);
    return Box3(vec3<f32>(relative_xy(r.lo), z.x), vec3<f32>(relative_xy(r.hi), z.y));
}

// How far (metres) the box of a square of `span` samples must lie outside a plane to be
// culled: 1e-3 of its side.
fn cull_slack(span: i32) -> f32 {
    return 1e-3 * (f32(span) * frame.camera_offset.w);
}

// Quadrant `q` of final tile `t` (bit `qx + 2 qy`): its square, with the heights of the tile
// one level down that covers it (the tile itself at level 0 or past the data's edge); its
// reach is tested against the frustum (`refine`; mirrors `quadrant_reach` and
// `quadrants_culled` in src/lod/udlod/select.rs).
fn quadrant_square(t: Tile, q: u32) -> ReachSquare {
    let half = i32(udlod.sizes.x << t.lod) / 2;
    let qxy = vec2<u32>(q & 1u, q >> 1u);
    let c0 = vec2<i32>(i32(t.x), i32(t.y)) * (2 * half) + vec2<i32>(qxy) * half;
    var heights = t;
    if t.lod > 0u {
        let below = Tile(2u * t.x + qxy.x, 2u * t.y + qxy.y, t.lod - 1u, 0u);
        if !outside_data(below) {
            heights = below;
        }
    }
    return ReachSquare(c0, half, t.lod, heights);
}

// Per workgroup of `refine`: its splits' child slots, final tiles, next-pass split requests and
// culled tiles, counted in workgroup memory; one invocation then reserves them in the global
// lists with one atomic each. (Each split and leaf taking its own global atomic serialised
// thousands of invocations on one address: 4 ms of prepass on the H200 at 17,600 tiles.)
var<workgroup> wg_children: atomic<u32>;
var<workgroup> wg_finals: atomic<u32>;
var<workgroup> wg_requests: atomic<u32>;
var<workgroup> wg_culled: atomic<u32>;
var<workgroup> wg_overflow: atomic<u32>;
var<workgroup> wg_child_base: u32;
var<workgroup> wg_final_base: u32;
// Per draw group: the workgroup's final tiles, and their first rank in the group.
var<workgroup> wg_groups: array<atomic<u32>, DRAW_GROUPS>;
var<workgroup> wg_group_base: array<u32, DRAW_GROUPS>;

// Four invocations per parent: their parent's slot in the workgroup's reservations (children,
// or the final tiles), and a final tile's rank in its draw group.
var<workgroup> wg_parent_local: array<u32, UDLOD_WORKGROUP / 4u>;
var<workgroup> wg_parent_rank: array<u32, UDLOD_WORKGROUP / 4u>;
// Per parent: 1 when one of its four invocations found a vertex of the (final) parent that
// may make slivers (`final_tile_checks`).
var<workgroup> wg_slivers: array<atomic<u32>, UDLOD_WORKGROUP / 4u>;
// Per parent: the quadrants (bits) of the (final) parent in which one of its four invocations
// found a vertex odd at its level that is not fully on the grid above (`final_tile_checks`):
// they keep their own grid.
var<workgroup> wg_keeps_grid: array<atomic<u32>, UDLOD_WORKGROUP / 4u>;
// Per parent: the quadrants (bits) of the (final) parent whose boxes lie outside the frustum,
// one invocation each (`quadrant_square`, `refine`): not drawn.
var<workgroup> wg_dropped: array<atomic<u32>, UDLOD_WORKGROUP / 4u>;

const_assert UDLOD_WORKGROUP % 4u == 0u;

const ACTION_NONE: u32 = 0u;
const ACTION_FINAL: u32 = 1u;
const ACTION_SPLIT: u32 = 2u;

// A final tile's draw group: its draw mask (`tile_mask`), plus `UDLOD_TILE_MASKS` when a
// vertex may make slivers.
fn draw_group(keeps_grid: u32, dropped: u32, slivers: bool) -> u32 {
    return tile_mask(ALL_QUADRANTS & ~keeps_grid, dropped) + select(0u, UDLOD_TILE_MASKS, slivers);
}

const ALL_QUADRANTS: u32 = 15u;

// The draw mask of a tile whose quadrants `collapsing` (bits) lie fully on the parent grid and
// `dropped` outside the frustum: quadrant q's digit (base 3) 0 its own grid, 1 collapsed, 2 not
// drawn; at grid 2 the tile collapses whole (then drawn whole unless all four are dropped) or
// not at all (mirrors `grid::TileMask::new` in src/lod/udlod/grid.rs).
fn tile_mask(collapsing_in: u32, dropped_in: u32) -> u32 {
    var collapsing = collapsing_in;
    var dropped = dropped_in;
    if udlod.sizes.x == 2u && dropped != ALL_QUADRANTS {
        if collapsing == ALL_QUADRANTS {
            dropped = 0u;
        } else {
            collapsing = 0u;
        }
    }
    var mask = 0u;
    var digit = 1u;
    for (var q = 0u; q < 4u; q++) {
        let bit = 1u << q;
        mask += digit * select(select(0u, 1u, (collapsing & bit) != 0u), 2u, (dropped & bit) != 0u);
        digit *= 3u;
    }
    return mask;
}

// Refines this pass's parents, four invocations per parent, one per child (a pass waits on its
// slowest invocation: one invocation deciding all four children, each with its culling box,
// was most of the prepass's time on the earth). A splitting tile writes its four children
// (each decided by its own invocation, for the next pass) into the temporary list; the others
// go to the final list's first half, unsorted, with their draw group and rank in it (`scatter`
// sorts them). The parent's own bookkeeping is its first invocation's. A pass splits
// only when `prepare` found room for all of its splits (`splits_allowed`), so the slots
// reserved here always fit; writes past a list's end are skipped all the same.
@compute @workgroup_size(UDLOD_WORKGROUP)
fn refine(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    if li == 0u {
        atomicStore(&wg_children, 0u);
        atomicStore(&wg_finals, 0u);
        atomicStore(&wg_requests, 0u);
        atomicStore(&wg_culled, 0u);
        atomicStore(&wg_overflow, 0u);
    }
    for (var g = li; g < DRAW_GROUPS; g += UDLOD_WORKGROUP) {
        atomicStore(&wg_groups[g], 0u);
    }
    if (li & 3u) == 0u {
        atomicStore(&wg_slivers[li / 4u], 0u);
        atomicStore(&wg_keeps_grid[li / 4u], 0u);
        atomicStore(&wg_dropped[li / 4u], 0u);
    }
    workgroupBarrier();
    let invocation = (group.y * groups.x + group.x) * UDLOD_WORKGROUP + li;
    let parent = invocation / 4u;
    let k = invocation % 4u;
    let parents = state.parent_count;
    var action = ACTION_NONE;
    var draw = 0u;
    var t = Tile(0u, 0u, 0u, 0u);
    var child = Tile(0u, 0u, 0u, 0u);
    if parent < parents {
        // Decided when it was written (`decided`): outside the data, culled, splitting.
        t = temp_tiles[parent_slot(parent)];
        if (t.pad & UDLOD_TILE_OUTSIDE) != 0u {
            // A child of an edge tile.
        } else if (t.pad & UDLOD_TILE_CULLED) != 0u {
            if k == 0u {
                atomicAdd(&wg_culled, 1u);
            }
        } else if (t.pad & UDLOD_TILE_SPLITS) != 0u && state.splits_allowed != 0u {
            action = ACTION_SPLIT;
        } else {
            if (t.pad & UDLOD_TILE_SPLITS) != 0u && k == 0u {
                atomicAdd(&wg_overflow, 1u);
            }
            action = ACTION_FINAL;
        }
    }
    // Each invocation tests one box, built by one copy of the reach for both actions (Mesa
    // 22.3 runs every branch for every 8 invocations, so a copy per action cost both): a
    // splitting parent's child k (`decided`, when culling), or a final parent's quadrant k
    // (`udlod.counts.x`: `cull_quadrants` with culling, unless the tile's box lies inside the
    // frustum). Its reads go out before the split field's or the vertex checks' and are
    // waited on after them.
    var square: ReachSquare;
    var boxed = false;
    if action == ACTION_SPLIT {
        child = Tile(t.x * 2u + (k & 1u), t.y * 2u + (k >> 1u), t.lod - 1u, 0u);
        square = tile_square(child);
        boxed = udlod.params.w > 0.5 && !outside_data(child);
    } else if action == ACTION_FINAL {
        square = quadrant_square(t, k);
        boxed = udlod.counts.x != 0u && (t.pad & UDLOD_TILE_INSIDE) == 0u;
    }
    var reads: ReachReads;
    if boxed {
        reads = reach_reads(square);
    }
    var splits = false;
    if action == ACTION_SPLIT && !outside_data(child) {
        splits = splits_by_distance(child);
    }
    // A final tile's vertices are checked by all four of its invocations (one checking them
    // all was the prepass's slowest path on the H200 at 1080p).
    if action == ACTION_FINAL {
        let checks = final_tile_checks(t, k);
        if checks.slivers {
            atomicOr(&wg_slivers[li / 4u], 1u);
        }
        if checks.keeps_grid != 0u {
            atomicOr(&wg_keeps_grid[li / 4u], checks.keeps_grid);
        }
    }
    var culled = false;
    var inside = false;
    if boxed {
        let b = reach_box(reach_of(square, reads));
        culled = box_outside(udlod.frustum, b, cull_slack(square.span));
        inside = box_inside(udlod.frustum, b);
    }
    if action == ACTION_SPLIT {
        child = decided(child, splits, culled, inside);
        if (child.pad & ~UDLOD_TILE_INSIDE) == (UDLOD_TILE_DECIDED | UDLOD_TILE_SPLITS) {
            atomicAdd(&wg_requests, 1u);
        }
    } else if action == ACTION_FINAL && culled {
        atomicOr(&wg_dropped[li / 4u], 1u << k);
    }
    workgroupBarrier();
    if k == 0u {
        if action == ACTION_SPLIT {
            wg_parent_local[li / 4u] = atomicAdd(&wg_children, 4u);
        } else if action == ACTION_FINAL {
            let slivers = atomicLoad(&wg_slivers[li / 4u]) != 0u;
            let dropped = atomicLoad(&wg_dropped[li / 4u]);
            draw = draw_group(atomicLoad(&wg_keeps_grid[li / 4u]), dropped, slivers);
            wg_parent_local[li / 4u] = atomicAdd(&wg_finals, 1u);
            wg_parent_rank[li / 4u] = atomicAdd(&wg_groups[draw], 1u);
        }
    }
    workgroupBarrier();
    if li == 0u {
        reserve_in_lists();
    }
    for (var g = li; g < DRAW_GROUPS; g += UDLOD_WORKGROUP) {
        let n = atomicLoad(&wg_groups[g]);
        if n > 0u {
            wg_group_base[g] = atomicAdd(&state.group_count[g], n);
        }
    }
    workgroupBarrier();
    let local = wg_parent_local[li / 4u];
    if action == ACTION_SPLIT {
        let base = wg_child_base + local;
        if parents + base + 4u <= udlod.sizes.w {
            temp_tiles[child_slot(base + k)] = child;
        } else if k == 0u {
            atomicAdd(&state.overflow, 1u);
        }
    } else if action == ACTION_FINAL && k == 0u {
        // The leaves reserved before (`reserved_leaves`) fit the first half.
        let i = wg_final_base + local;
        if i < udlod.sizes.z {
            let rank = wg_group_base[draw] + wg_parent_rank[li / 4u];
            final_tiles[i] = Tile(t.x, t.y, t.lod, draw | (rank << DRAW_GROUP_BITS));
        } else {
            atomicAdd(&state.overflow, 1u);
        }
    }
}

// An unsorted final tile's `pad`: its draw group in the low bits, its rank in the group above.
const DRAW_GROUP_BITS: u32 = 8u;
const_assert DRAW_GROUPS <= (1u << DRAW_GROUP_BITS);

// `refine`'s one invocation per workgroup: reserves the workgroup's children and final tiles
// in the global lists (`wg_child_base`, `wg_final_base`) and adds its counts to the state's.
fn reserve_in_lists() {
    let nc = atomicLoad(&wg_children);
    if nc > 0u {
        wg_child_base = atomicAdd(&state.child_count, nc);
        atomicAdd(&state.reserved_leaves, 3u * (nc / 4u));
    }
    let nf = atomicLoad(&wg_finals);
    if nf > 0u {
        wg_final_base = atomicAdd(&state.final_count, nf);
    }
    let requests = atomicLoad(&wg_requests);
    if requests > 0u {
        atomicAdd(&state.split_requests, requests);
    }
    let culled = atomicLoad(&wg_culled);
    if culled > 0u {
        atomicAdd(&state.culled, culled);
    }
    let overflow = atomicLoad(&wg_overflow);
    if overflow > 0u {
        atomicAdd(&state.overflow, overflow);
    }
}

fn outside_data(t: Tile) -> bool {
    let level = udlod.levels[t.lod];
    return t.x >= level.y || t.y >= level.z;
}

// Split on the smallest scaled distance over the tile: the field's minimum (its nodes)
// times the distance to the nearest point (mirrors `tile_splits` in select.rs).
fn splits_by_distance(t: Tile) -> bool {
    return t.lod > 0u && tile_field_min(t.x, t.y, t.lod) * tile_distance(t) < udlod.split[t.lod].x;
}

// Tile t with its flags (`UDLOD_TILE_*` in `Tile.pad` of the temporary list): outside the data,
// else culled, else splitting (`splits`: near enough, `splits_by_distance`), and whether its box
// lies inside the frustum (then `refine` tests none of its quadrants should it be final: none
// would be culled, `tile_inside` in select.rs says why). `culled` and `inside` are its box's
// against the frustum (`tile_square`'s reach; both false without culling). What `refine` will
// do with the tile, decided by whoever writes it, so the next pass's splits are counted before
// it and each tile's culling box is built once (mirrors `seed::decided` in
// src/lod/udlod/seed.rs).
fn decided(t: Tile, splits: bool, culled: bool, inside: bool) -> Tile {
    var flags = UDLOD_TILE_DECIDED;
    if outside_data(t) {
        return Tile(t.x, t.y, t.lod, flags | UDLOD_TILE_OUTSIDE);
    }
    if culled {
        return Tile(t.x, t.y, t.lod, flags | UDLOD_TILE_CULLED);
    }
    if inside {
        flags |= UDLOD_TILE_INSIDE;
    }
    if splits {
        flags |= UDLOD_TILE_SPLITS;
    }
    return Tile(t.x, t.y, t.lod, flags);
}

// Two questions about final tile `t`, one walk over its vertices (invocation `k` of the tile's
// four checks every fourth vertex from its `k`th):
// slivers: whether some vertex may make sliver triangles (`morph_moved`, the vertex stage's
// own arithmetic): one part-way through its morph, or one carried on past the tile's own
// level. A tile whose vertices all stay put or slide fully onto the parent grid at the tile's
// level keeps the parent grid's triangles (or degenerate ones) and is drawn with back-face
// culling (docs/udlod.md, "Pinholes far away and back faces").
// keeps_grid: the quadrants (bit `qx + 2 qy`) that keep their own grid: those with a vertex odd
// at the tile's level short of the grid above by `UDLOD_COLLAPSE_MARGIN`
// (`morph::tile_collapse_mask`); the others' surface is the parent grid's over their even
// vertices, and they are drawn as that grid (docs/udlod-rounds.md, "Collapsed quadrants"). All four
// without the setting `collapse` (`udlod.params.x`) or with morphing off.
struct TileChecks {
    slivers: bool,
    keeps_grid: u32,
}

// Vertices whose first reads `final_tile_checks` sends out together: the checks wait on memory
// once per batch, not once per vertex (on NVIDIA a pass of `refine` lasts as long as its
// slowest invocation's chain of reads). Grid 4's tiles give each invocation 6 or 7 vertices.
// The batch is read inline, into arrays indexed in loops of constant bound: a helper returning
// it cost the H100 0.01 ms a frame on Puget Sound (with either loop bound).
const CHECK_BATCH: u32 = 8u;

fn final_tile_checks(t: Tile, k: u32) -> TileChecks {
    let all = ALL_QUADRANTS;
    var slivers = false;
    var keeps_grid = select(0u, all, udlod.params.x < 0.5 || udlod.params.z < 0.5);
    let quads = udlod.sizes.x;
    let step = 1u << t.lod;
    let origin = vec2<u32>(t.x, t.y) * quads * step;
    // Vertex v = k, k + 4, ... at (v mod row, v / row), stepped without dividing.
    let row = quads + 1u;
    var local = vec2<u32>(k, 0u);
    loop {
        var locals: array<vec2<u32>, CHECK_BATCH>;
        var firsts: array<u32, CHECK_BATCH>;
        var ramps: array<f32, CHECK_BATCH>;
        var n = 0u;
        for (var i = 0u; i < CHECK_BATCH; i++) {
            while local.x >= row {
                local.x -= row;
                local.y += 1u;
            }
            if local.y < row {
                let sample = vec2<i32>(origin + local * step);
                locals[i] = local;
                firsts[i] = next_odd_level(sample, t.lod);
                ramps[i] = morph_ramp(sample, first_read_level(firsts[i]));
                n = i + 1u;
                local.x += 4u;
            }
        }
        for (var i = 0u; i < CHECK_BATCH; i++) {
            if i >= n || (slivers && keeps_grid == all) {
                break;
            }
            let sample = vec2<i32>(origin + locals[i] * step);
            let odd = ((locals[i].x | locals[i].y) & 1u) == 1u;
            let quadrants = select(0u, quadrants_of(locals[i], quads), odd);
            let open = (quadrants & ~keeps_grid) != 0u;
            var ramp = 0.0;
            if !slivers {
                let m = morph_moved(sample, t.lod, firsts[i], ramps[i]);
                slivers = m.moved == MORPH_SLIVERS;
                ramp = m.first_ramp;
            } else if open {
                // Odd at the tile's level: its first read is `morph_ramp` there.
                ramp = ramps[i];
            }
            if open && ramp < 1.0 + UDLOD_COLLAPSE_MARGIN {
                keeps_grid |= quadrants;
            }
        }
        if n < CHECK_BATCH || (slivers && keeps_grid == all) {
            break;
        }
    }
    return TileChecks(slivers, keeps_grid);
}

// The quadrants (bits) holding grid vertex `local` of a tile of `quads` per side: one, two on
// a middle line, four at the centre (`grid::quadrants_of` in src/lod/udlod/grid.rs).
fn quadrants_of(local: vec2<u32>, quads: u32) -> u32 {
    let h = quads / 2u;
    let xs = select(0u, 1u, local.x <= h) | select(0u, 2u, local.x >= h);
    let ys = select(0u, 1u, local.y <= h) | select(0u, 2u, local.y >= h);
    // Bit qx + 2 qy for every qx in xs and qy in ys.
    return xs * (ys & 1u) | ((xs * (ys >> 1u)) << 2u);
}

// One workgroup: each draw group's first entry in the final list's second half (the groups
// one after another), the draws of the groups with tiles (the mask's index list from
// `udlod.masks`, the group's tiles as instances from that entry on), and `scatter`'s
// dispatch. Empty groups get no draw (on lavapipe each draw costs even without instances), so
// a run of draws per pipeline with its count, then draws of no instance (the state is
// zero-filled before each frame) for devices without `drawIndirectCount`. A frame whose final
// tiles did not all fit the list (never by construction: `reserved_leaves`) draws nothing
// rather than a stale entry. The groups' counts are read and their draws written by all
// invocations; one runs the scan in workgroup memory (one invocation walking the 162 groups'
// counters in the state buffer: most of the 0.02-0.04 ms that 81 masks first cost the H200,
// docs/udlod-rounds.md "Quadrants outside the view").
var<workgroup> wg_finish_count: array<u32, DRAW_GROUPS>;
var<workgroup> wg_finish_first: array<u32, DRAW_GROUPS>;
// Per group: its draw's entry in `state.draws`, or `NO_DRAW`.
var<workgroup> wg_finish_slot: array<u32, DRAW_GROUPS>;
const NO_DRAW: u32 = 0xffffffffu;

@compute @workgroup_size(UDLOD_WORKGROUP)
fn finish(@builtin(local_invocation_index) li: u32) {
    let total = atomicLoad(&state.final_count);
    let fits = total <= udlod.sizes.z;
    for (var g = li; g < DRAW_GROUPS; g += UDLOD_WORKGROUP) {
        wg_finish_count[g] = select(0u, atomicLoad(&state.group_count[g]), fits);
    }
    workgroupBarrier();
    if li == 0u {
        var first = 0u;
        var drawn = array<u32, 2>(0u, 0u);
        for (var g = 0u; g < DRAW_GROUPS; g++) {
            let count = wg_finish_count[g];
            wg_finish_first[g] = first;
            wg_finish_slot[g] = NO_DRAW;
            if count > 0u {
                let pipeline = g / UDLOD_TILE_MASKS;
                wg_finish_slot[g] = pipeline * UDLOD_TILE_MASKS + drawn[pipeline];
                drawn[pipeline] += 1u;
            }
            first += count;
        }
        // The rest stay as the frame's fill left them: draws of no instance.
        state.static_draws = drawn[0];
        state.morphing_draws = drawn[1];
        let groups = (select(0u, total, fits) + UDLOD_WORKGROUP - 1u) / UDLOD_WORKGROUP;
        let row = max(udlod.counts.y, 1u);
        state.dispatch_x = min(groups, row);
        state.dispatch_y = (groups + row - 1u) / row;
        state.dispatch_z = 1u;
    }
    workgroupBarrier();
    let pulling = udlod.counts.w != 0u;
    for (var g = li; g < DRAW_GROUPS; g += UDLOD_WORKGROUP) {
        let first = wg_finish_first[g];
        state.group_first[g] = first;
        let slot = wg_finish_slot[g];
        if slot != NO_DRAW {
            let mask = udlod.masks[g % UDLOD_TILE_MASKS];
            let count = wg_finish_count[g];
            if pulling {
                state.draws[slot] = IndirectDraw(mask.x, count, 0u, first, 0u);
            } else {
                state.draws[slot] = IndirectDraw(mask.x, count, mask.y, 0u, first);
            }
        }
    }
}

// One invocation per final tile: moves it from the first half, unsorted, to its place in the
// second half (its group's first entry plus its rank), where the draws read it as
// instance `first_instance + i` with its group in `pad`.
@compute @workgroup_size(UDLOD_WORKGROUP)
fn scatter(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let i = (group.y * groups.x + group.x) * UDLOD_WORKGROUP + li;
    let n = udlod.sizes.z;
    if i >= min(atomicLoad(&state.final_count), n) {
        return;
    }
    let t = final_tiles[i];
    let draw = t.pad & ((1u << DRAW_GROUP_BITS) - 1u);
    let slot = state.group_first[draw] + (t.pad >> DRAW_GROUP_BITS);
    if slot < n {
        final_tiles[n + slot] = Tile(t.x, t.y, t.lod, draw);
    }
}

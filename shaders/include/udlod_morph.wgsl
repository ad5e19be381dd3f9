// UDLOD's vertex morph, one function for every caller: the vertex shaders of udlod.wgsl, the
// prepass's back-face split (udlod_tiling.wgsl) and the test probe udlod_probe.wgsl. Mirrored
// operation for operation by `morph_factor`, `morph_cascade` and `morphed_vertex` in
// src/lod/udlod/morph.rs; tests/udlod.rs evaluates this code through the probe and proves the
// two equal. Needs terrain_common.wgsl and udlod_common.wgsl.

// 0 = the level's own grid, 1 = fully on the next level's grid (times the on/off switch
// `udlod.params.z`), for a grid point of level `lod`. `d` is the distance from the LOD viewer
// to the point at the reference height in the LOD metric (`udlod.metric`), scaled by the next
// level's split field; `parent_split` that level's split distance; the morph runs over the
// last `morph_range` of it; with the morph cascade (`split[l].y`, the zone's least width, > 0)
// over the last `max(zone, morph_range s)` metres of the point's split distance `s`.
fn morph_factor(sample: vec2<i32>, lod: u32) -> f32 {
    return factor_of_ramp(morph_ramp(sample, lod), sample, lod);
}

// `morph_factor` from the point's `morph_ramp`.
fn factor_of_ramp(ramp: f32, sample: vec2<i32>, lod: u32) -> f32 {
    var f = clamp(ramp, 0.0, 1.0);
    // A point odd along both axes slides along its block's diagonal from (1, 1) to (0, 0),
    // across the quad's split from (1, 0) to (0, 1): past `(1 + b) / 2`, `b` the smaller factor
    // of those two neighbours (each odd along one axis), the triangle between the three turns
    // over (docs/udlod-rounds.md, "Folds at the quads' diagonal").
    // (Never binding at or below 1/2: the neighbours are read only past it.)
    let folds = f > 0.5 && all(odd_at(sample, lod) == vec2<i32>(1));
    // The two neighbours through one copy of `morph_ramp` in a loop: Mesa 22.3 runs a branch
    // that no invocation takes all the same, and a loop's body once, so two inlined copies
    // cost every call of this function two more ramps there, the loop one.
    let step = i32(1u << lod);
    var least = 1.0;
    for (var n = 0; folds && n < 2; n++) {
        let neighbour = sample - select(vec2<i32>(step, 0), vec2<i32>(0, step), n == 0);
        least = min(least, clamp(morph_ramp(neighbour, lod), 0.0, 1.0));
    }
    if folds {
        f = min(f, 0.5 * (1.0 + least));
    }
    return f * udlod.params.z;
}

// Whether `morph_factor(sample, lod)` is not 0, without the fold's neighbour reads: the fold
// only lowers a factor above 1/2 to one of at least 1/2, so the factor is 0 exactly where the
// ramp is not above 0 or morphing is off (mirrored by `morph_moves` in morph.rs, which a test
// proves equal to `morph_factor != 0`). The walks ask only this.
fn morph_moves(sample: vec2<i32>, lod: u32) -> bool {
    return udlod.params.z != 0.0 && morph_ramp(sample, lod) > 0.0;
}

// `morph_factor` before its clamp and the on/off switch: at least 1 where the point lies fully
// on the next level's grid (the prepass's `final_tile_checks` asks for a margin past it).
fn morph_ramp(sample: vec2<i32>, lod: u32) -> f32 {
    let d = length(vec3<f32>(viewer_xy(sample) * udlod.metric.xy, udlod.viewer.z));
    let field = field_at(sample, lod + 1u);
    let parent_split = udlod.split[lod + 1u].x;
    let zone = udlod.split[lod + 1u].y;
    let morph_range = udlod.params.y;
    if zone > 0.0 {
        // The morph cascade: the zone is at least `zone` wide (a few grid steps).
        let s = parent_split / field;
        let width = max(zone, morph_range * s);
        return 1.0 - (s - d) / width;
    }
    let scaled = d * field;
    return 1.0 - (1.0 - scaled / parent_split) / morph_range;
}

// The walk's step at level `j` (`morph_cascade`, `morph_moved`): which of the point's
// coordinates are odd there (all zero: the point does not move at `j`).
fn odd_at(point: vec2<i32>, j: u32) -> vec2<i32> {
    return vec2<i32>((vec2<u32>(point) >> vec2<u32>(j)) & vec2<u32>(1u));
}

// One step of every morph walk: where a grid point slides at level `j`, its lower even
// neighbour there (itself where it is even at `j`). Mirrored by `slid_at` in morph.rs.
fn slid_at(point: vec2<i32>, j: u32) -> vec2<i32> {
    return point - odd_at(point, j) * i32(1u << j);
}

// Where grid point `sample` of a level-`lod` tile ends up after the morph cascade (docs/udlod.md,
// "The morph cascade"). Up: at every level `j` from `lod` on at which the point reached is
// odd, it has the factor `f_j` (`morph_factor` there) and slides towards its lower even
// neighbour, the next point; the first factor of 0 ends the walk. Down: the last point reached
// stays put, and each earlier point lies `1 - f` of the way from where the point it slides to
// ended up back towards itself. A point on the walk ends up exactly where its own vertex does
// (the same walk from there, the same operations), so a vertex fully morphed through the
// levels between two neighbours is bit-identical to the coarser one's, and a vertex nearly
// morphed onto its neighbour lies a small multiple of their offset away from it, never off
// to one side by rounding. Result: an integer cell plus a fraction (not yet folded or
// clamped) and the factor at the first odd level (how the point moved: `morph_moved`).
struct Cascade {
    cell: vec2<i32>,
    frac: vec2<f32>,
    morph: f32,
}

fn morph_cascade(sample: vec2<i32>, lod: u32) -> Cascade {
    var c = Cascade(sample, vec2<f32>(0.0), 0.0);
    var points: array<vec2<i32>, UDLOD_MAX_LEVELS>;
    var factors: array<f32, UDLOD_MAX_LEVELS>;
    var n = 0u;
    var point = sample;
    var first = true;
    for (var j = lod; j < udlod.sizes.y; j++) {
        let odd = odd_at(point, j);
        if all(odd == vec2<i32>(0)) {
            continue;
        }
        let f = morph_factor(point, j);
        if first {
            c.morph = f;
            first = false;
        }
        if f == 0.0 {
            break;
        }
        points[n] = point;
        factors[n] = f;
        n++;
        point = slid_at(point, j);
    }
    c.cell = point;
    for (var k = n; k > 0u; k--) {
        let f = factors[k - 1u];
        if f < 1.0 {
            c.frac = c.frac + (1.0 - f) * (vec2<f32>(points[k - 1u] - c.cell) - c.frac);
        }
    }
    return c;
}

// The first level from `lod` up at which `point` is odd, where its walk in `morph_cascade` can
// next move (`udlod.sizes.y` when there is none below it). Grid points are never negative.
fn next_odd_level(point: vec2<i32>, lod: u32) -> u32 {
    let bits = (u32(point.x) | u32(point.y)) >> lod;
    return min(lod + countTrailingZeros(bits), udlod.sizes.y);
}

// The last point of a grid point's walk in `morph_cascade` from its first odd level `first`
// (`next_odd_level`): the walk up without the positions. Every point of the walk lies between
// it and `sample` (the walk only moves towards lower coordinates): the prepass's culling box
// (`reach_of`, which reads every corner's first step at once, `walk_past`). Mirrored by
// `walk_end` in morph.rs.
fn walk_on(sample: vec2<i32>, first: u32) -> vec2<i32> {
    var point = sample;
    var j = first;
    loop {
        if j >= udlod.sizes.y || !morph_moves(point, j) {
            break;
        }
        point = slid_at(point, j);
        j = next_odd_level(point, j + 1u);
    }
    return point;
}

// `walk_on` of a point whose factor at its first odd level `first` was read already
// (`moves`: it is not 0 and `first` is a level of the walk).
fn walk_past(sample: vec2<i32>, first: u32, moves: bool) -> vec2<i32> {
    if !moves {
        return sample;
    }
    let next = slid_at(sample, first);
    return walk_on(next, next_odd_level(next, first + 1u));
}

// How a grid point moved: not at all; fully onto the next level's grid at the tile's own level
// and no further (the tile's triangles stay the parent grid's, or degenerate); anything else
// (part-way, or on through further levels: sliver triangles possible).
const MORPH_STILL: u32 = 0u;
const MORPH_ONE_LEVEL: u32 = 1u;
const MORPH_SLIVERS: u32 = 2u;

// How grid point `sample` of a level-`lod` tile moves in `morph_cascade`: the same walk up and
// the same factors without the positions (no per-level arrays), stopping at the first sliver,
// the only answer the prepass's back-face split needs from every vertex of every final tile
// (`final_tile_checks`); and for a point odd at `lod` the unclamped factor there
// (`morph_ramp`), which the prepass's collapse check reads. Mirrored by `Cascade::moved` of
// `morph_cascade` in morph.rs.
struct Moved {
    moved: u32,
    // `morph_ramp(sample, lod)` where the point is odd at `lod` (else 0).
    first_ramp: f32,
}

// The first step is read by the caller: `first`, the point's first odd level from `lod` up
// (`next_odd_level`), and `ramp`, its `morph_ramp` there (anything when `first` is past the
// levels), so that `final_tile_checks` can read a batch of vertices' at once. The walk on
// past the first step needs one more factor: any movement there is a sliver.
fn morph_moved(sample: vec2<i32>, lod: u32, first: u32, ramp: f32) -> Moved {
    var m = Moved(MORPH_STILL, 0.0);
    if first >= udlod.sizes.y {
        return m;
    }
    if first == lod {
        m.first_ramp = ramp;
    }
    let f = factor_of_ramp(ramp, sample, first);
    if f == 0.0 {
        return m;
    }
    if first != lod || f != 1.0 {
        m.moved = MORPH_SLIVERS;
        return m;
    }
    m.moved = MORPH_ONE_LEVEL;
    let next = slid_at(sample, first);
    let j = next_odd_level(next, first + 1u);
    if j < udlod.sizes.y && morph_moves(next, j) {
        m.moved = MORPH_SLIVERS;
    }
    return m;
}

// The level at which a walk's first step is read in a batch: `first`, or for a point with no
// odd level left (`first` past the levels) the last level, whose read is not used.
fn first_read_level(first: u32) -> u32 {
    return min(first, max(udlod.sizes.y, 1u) - 1u);
}

// A tile's grid vertex after morphing: the position in samples as an integer cell and a
// fraction in [0, 1) (what `project` takes), the same position as one vector (texturing and
// height lookup), its height and the morph factor at its first odd level.
struct MorphedVertex {
    cell: vec2<i32>,
    frac: vec2<f32>,
    grid_pos: vec2<f32>,
    height: f32,
    morph: f32,
}

// Everything here is a pure function of the vertex's integer sample position and the tile's
// level, so vertices shared by neighbouring tiles land on the same spot.
fn morphed_vertex(tile: Tile, local: vec2<u32>) -> MorphedVertex {
    let quads = udlod.sizes.x;
    let step = 1u << tile.lod;
    let sample = vec2<i32>(vec2<u32>(tile.x, tile.y) * quads * step + local * step);
    let c = morph_cascade(sample, tile.lod);
    // One representation per position: whole samples folded from the fraction into the cell,
    // or far from the camera an unmorphed odd vertex and the same sample as an even vertex of
    // the neighbouring tile would differ by an ulp and the shared edge show pinholes.
    let whole = floor(c.frac);
    var cell = c.cell + vec2<i32>(whole);
    var frac = c.frac - whole;
    // Tiles at the data's far edges reach past the last sample: clamp onto it.
    let last = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    frac = min(frac, vec2<f32>(max(last - cell, vec2<i32>(0))));
    cell = min(cell, last);
    var v: MorphedVertex;
    v.cell = cell;
    v.frac = frac;
    v.grid_pos = vec2<f32>(cell) + frac;
    v.height = height_at(v.grid_pos);
    v.morph = c.morph;
    return v;
}

// GPU chunked LOD selection (Hedberg 2022), two variants over the same chunk tests:
//
// Naive: the quadtree walked level by level from the root depth, one `refine` dispatch per
// level (indirect, sized by a 1-thread `prepare`), parents and children in the two halves of
// `lists` (ping-pong). A chunk outside the frustum (bounding sphere) is dropped; one whose
// projected error exceeds the threshold queues its four children; the others go to the
// render list.
//
// CBT: the tree kept in a concurrent binary tree (bit field `cbt_bits` + sum-reduction heap
// `cbt_heap`, src/lod/chunked/select.rs `CbtLayout`) across frames. Per frame `cbt_begin`
// sizes the dispatch from the root sum, `cbt_update` makes one split/merge step per leaf,
// `cbt_reduce_bits`, `cbt_reduce` and `cbt_reduce_top` rebuild the sums, and `cbt_list`
// lists the leaves that are inside the data and the frustum.
//
// Both end in `finish` (the indexed indirect draw and the LOD-map dispatch) and `lod_map`
// (each listed chunk writes its level into the level-0 cells it covers).

//!include terrain_common.wgsl
//!include chunked_common.wgsl

struct ChunkState {
    // vkCmdDispatchIndirect arguments of the next refine / update / list pass.
    dispatch_x: u32,
    dispatch_y: u32,
    dispatch_z: u32,
    pass_index: u32,
    // vkCmdDrawIndexedIndirect arguments.
    index_count: u32,
    instance_count: u32,
    first_index: u32,
    vertex_offset: i32,
    first_instance: u32,
    // vkCmdDispatchIndirect arguments of the LOD-map pass (one workgroup per listed chunk).
    map_x: u32,
    map_y: u32,
    map_z: u32,
    current_count: u32,
    next_count: atomic<u32>,
    final_count: atomic<u32>,
    overflow: atomic<u32>,
    culled: atomic<u32>,
    // Passes begun this frame (the state is zero-filled before the first).
    passes_started: u32,
    splits: atomic<u32>,
    merges: atomic<u32>,
    // vkCmdDrawMeshTasksIndirectEXT arguments (the mesh path: one task workgroup per chunk).
    mesh_x: u32,
    mesh_y: u32,
    mesh_z: u32,
}

@group(1) @binding(1) var<storage, read_write> state: ChunkState;
@group(1) @binding(2) var<storage, read_write> lists: array<Chunk>;
@group(1) @binding(3) var<storage, read_write> final_chunks: array<Chunk>;
@group(1) @binding(4) var<storage, read> min_max: array<vec2<f32>>;
@group(1) @binding(5) var<storage, read> chunk_error: array<f32>;
@group(1) @binding(6) var<storage, read_write> lod_map: array<u32>;
@group(1) @binding(7) var<storage, read_write> cbt_heap: array<u32>;
@group(1) @binding(8) var<storage, read_write> cbt_bits: array<atomic<u32>>;

fn chunk_index(t: Chunk) -> u32 {
    let level = chunked.levels[t.lod];
    return level.x + t.y * level.y + t.x;
}

fn chunk_inside(t: Chunk) -> bool {
    let level = chunked.levels[t.lod];
    return t.x < level.y && t.y < level.z;
}

// Bounding sphere (camera-relative centre, radius) of the chunk's box: the rectangle clamped
// to the data x its min/max height (mirrors `chunk_sphere` in select.rs).
fn chunk_sphere(t: Chunk) -> vec4<f32> {
    let span = i32(chunked.sizes.x << t.lod);
    let last = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    let lo = chunk_relative_xy(vec2<i32>(i32(t.x) * span, i32(t.y) * span));
    let hi = chunk_relative_xy(min(vec2<i32>((i32(t.x) + 1) * span, (i32(t.y) + 1) * span), last));
    let mm = min_max[chunk_index(t)];
    let centre = vec3<f32>((lo.x + hi.x) * 0.5, (lo.y + hi.y) * 0.5, (mm.x + mm.y) * 0.5 - frame.camera_offset.z);
    let half = vec3<f32>((hi.x - lo.x) * 0.5, (hi.y - lo.y) * 0.5, (mm.y - mm.x) * 0.5);
    return vec4<f32>(centre, length(half));
}

// Distance from the LOD viewer to the chunk's box (rectangle clamped to the data x its
// min/max height) in the LOD metric: grid-frame offsets stretched per axis (mirrors
// `chunk_box_distance` in select.rs, the same f32 operations).
fn chunk_box_distance(t: Chunk) -> f32 {
    let span = i32(chunked.sizes.x << t.lod);
    let last = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    let lo = chunk_relative_xy(vec2<i32>(i32(t.x) * span, i32(t.y) * span));
    let hi = chunk_relative_xy(min(vec2<i32>((i32(t.x) + 1) * span, (i32(t.y) + 1) * span), last));
    let mm = min_max[chunk_index(t)];
    let v = chunked.viewer.xyz;
    let dxy = max(lo - v.xy, min(vec2<f32>(0.0), hi - v.xy)) * chunked.metric.xy;
    let dz = max(mm.x - frame.camera_offset.z - v.z, min(0.0, mm.y - frame.camera_offset.z - v.z));
    return length(vec3<f32>(dxy, dz));
}

// Projected error above the threshold (mirrors `chunk_splits`); never below the finest level.
// Square grids (metric exactly (1, 1), a uniform branch): the distance to the bounding
// sphere; native non-square grids: to the box in the per-axis metric.
fn chunk_splits(t: Chunk) -> bool {
    if t.lod <= chunked.sizes.w {
        return false;
    }
    var d: f32;
    if all(chunked.metric.xy == vec2<f32>(1.0)) {
        let s = chunk_sphere(t);
        let to = s.xyz - chunked.viewer.xyz;
        d = max(length(to) - s.w, 0.0);
    } else {
        d = chunk_box_distance(t);
    }
    return chunk_error[chunk_index(t)] * chunked.params.y > chunked.params.x * d;
}

// Sphere wholly outside a frustum plane (mirrors `chunk_culled`). On the earth the curved
// box every method culls with there (`earth_box`), with UDLOD's margin (docs/chunked.md).
fn chunk_culled(t: Chunk) -> bool {
    if chunked.params.z < 0.5 {
        return false;
    }
    if EARTH_WORLD {
        let span = i32(chunked.sizes.x << t.lod);
        let last = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
        let c0 = vec2<i32>(i32(t.x) * span, i32(t.y) * span);
        let b = earth_box(c0, min(c0 + vec2<i32>(span), last), min_max[chunk_index(t)]);
        return box_outside(chunked.frustum, b, 1e-3 * (f32(span) * frame.camera_offset.w));
    }
    let s = chunk_sphere(t);
    for (var i = 0u; i < 6u; i++) {
        let pl = chunked.frustum[i];
        if pl.x * s.x + pl.y * s.y + pl.z * s.z + pl.w < -s.w {
            return true;
        }
    }
    return false;
}

fn emit_final(t: Chunk) {
    let i = atomicAdd(&state.final_count, 1u);
    if i < chunked.lists.x {
        final_chunks[i] = t;
    } else {
        atomicAdd(&state.overflow, 1u);
    }
}

fn set_dispatch(items: u32) {
    let groups = (items + UDLOD_WORKGROUP - 1u) / UDLOD_WORKGROUP;
    state.dispatch_x = groups;
    state.dispatch_y = 1u;
    state.dispatch_z = 1u;
}

// ---- naive traversal ----

@compute @workgroup_size(1)
fn prepare() {
    let pass_index = state.passes_started;
    state.passes_started = pass_index + 1u;
    state.pass_index = pass_index;
    var parents: u32;
    if pass_index == 0u {
        // The chunks of the start level, in the front half.
        let level = chunked.levels[chunked.sizes.z];
        parents = min(level.y * level.z, chunked.lists.y);
        for (var i = 0u; i < parents; i++) {
            lists[i] = Chunk(i % level.y, i / level.y, chunked.sizes.z, 0u);
        }
    } else {
        parents = min(atomicLoad(&state.next_count), chunked.lists.y);
    }
    state.current_count = parents;
    atomicStore(&state.next_count, 0u);
    set_dispatch(parents);
}

// Reserves 4 slots of the next list; -1 when it is full.
fn reserve_children() -> i32 {
    var n = atomicLoad(&state.next_count);
    loop {
        if n + 4u > chunked.lists.y {
            return -1;
        }
        let r = atomicCompareExchangeWeak(&state.next_count, n, n + 4u);
        if r.exchanged {
            return i32(n);
        }
        n = r.old_value;
    }
    return -1;
}

@compute @workgroup_size(UDLOD_WORKGROUP)
fn refine(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= state.current_count {
        return;
    }
    let odd = state.pass_index & 1u;
    let t = lists[odd * chunked.lists.y + id.x];
    if !chunk_inside(t) {
        return;
    }
    if chunk_culled(t) {
        atomicAdd(&state.culled, 1u);
        return;
    }
    if chunk_splits(t) {
        let base = reserve_children();
        if base >= 0 {
            let next = (1u - odd) * chunked.lists.y + u32(base);
            for (var k = 0u; k < 4u; k++) {
                lists[next + k] = Chunk(t.x * 2u + (k & 1u), t.y * 2u + (k >> 1u), t.lod - 1u, 0u);
            }
            atomicAdd(&state.splits, 1u);
            return;
        }
        atomicAdd(&state.overflow, 1u);
    }
    emit_final(t);
}

// ---- concurrent binary tree ----

// Sum of heap node `n` at binary depth `d` (a bit at the deepest level).
fn cbt_sum(n: u32, d: u32) -> u32 {
    let depth = chunked.cbt.x;
    if d == depth {
        let b = n - (1u << depth);
        return (atomicLoad(&cbt_bits[b >> 5u]) >> (b & 31u)) & 1u;
    }
    return cbt_heap[n];
}

// The `i`-th leaf: descend while a subtree holds more than one leaf. Returns (node, depth).
fn cbt_decode(leaf: u32) -> vec2<u32> {
    var i = leaf;
    var n = 1u;
    var d = 0u;
    while d < chunked.cbt.x && cbt_sum(n, d) > 1u {
        let left = cbt_sum(2u * n, d + 1u);
        if i < left {
            n = 2u * n;
        } else {
            i -= left;
            n = 2u * n + 1u;
        }
        d += 1u;
    }
    return vec2<u32>(n, d);
}

// The chunk of a node at even binary depth (x in the even bits of its index below the root).
fn cbt_chunk(n: u32, d: u32) -> Chunk {
    let m = n - (1u << d);
    var x = 0u;
    var y = 0u;
    for (var i = 0u; i < d / 2u; i++) {
        x |= ((m >> (2u * i)) & 1u) << i;
        y |= ((m >> (2u * i + 1u)) & 1u) << i;
    }
    return Chunk(x, y, chunked.sizes.y - d / 2u, 0u);
}

// Would the naive walk split this node? It and every ancestor below the root depth split.
fn cbt_keeps_split(n: u32, d: u32) -> bool {
    var k = n;
    var e = d;
    loop {
        if e < chunked.cbt.z {
            return true;
        }
        let t = cbt_chunk(k, e);
        if !chunk_inside(t) || chunk_culled(t) || !chunk_splits(t) {
            return false;
        }
        if e < 2u {
            return true;
        }
        k = k >> 2u;
        e -= 2u;
    }
    return true;
}

fn cbt_set(n: u32, d: u32, on: bool) {
    let b = (n << (chunked.cbt.x - d)) - (1u << chunked.cbt.x);
    let mask = 1u << (b & 31u);
    if on {
        atomicOr(&cbt_bits[b >> 5u], mask);
    } else {
        atomicAnd(&cbt_bits[b >> 5u], ~mask);
    }
}

@compute @workgroup_size(1)
fn cbt_begin() {
    // The root's sum (its bit when the tree is one chunk deep: depth 0).
    let leaves = cbt_sum(1u, 0u);
    state.current_count = leaves;
    set_dispatch(leaves);
}

@compute @workgroup_size(UDLOD_WORKGROUP)
fn cbt_update(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= state.current_count {
        return;
    }
    let leaf = cbt_decode(id.x);
    let n = leaf.x;
    let d = leaf.y;
    // Merge: four sibling leaves whose parent the naive walk would not split; the first
    // sibling clears the others' bits (the heap still holds last frame's sums, before any
    // change of this pass).
    if d >= chunked.cbt.z + 2u {
        let p = n >> 2u;
        if cbt_sum(p, d - 2u) == 4u && !cbt_keeps_split(p, d - 2u) {
            if (n & 3u) == 0u {
                cbt_set(4u * p + 1u, d, false);
                cbt_set(4u * p + 2u, d, false);
                cbt_set(4u * p + 3u, d, false);
                atomicAdd(&state.merges, 1u);
            }
            return;
        }
    }
    if d < chunked.cbt.x && cbt_keeps_split(n, d) {
        cbt_set(4u * n + 1u, d + 2u, true);
        cbt_set(4u * n + 2u, d + 2u, true);
        cbt_set(4u * n + 3u, d + 2u, true);
        atomicAdd(&state.splits, 1u);
    }
}

// Sums of the heap levels inside one 32-bit word of the bit field (depths D-1 .. D-5, fewer
// for a shallower tree), one thread per word.
@compute @workgroup_size(UDLOD_WORKGROUP)
fn cbt_reduce_bits(@builtin(global_invocation_id) id: vec3<u32>) {
    let depth = chunked.cbt.x;
    let bits = 1u << depth;
    let words = max(bits / 32u, 1u);
    if id.x >= words {
        return;
    }
    let word = atomicLoad(&cbt_bits[id.x]);
    let in_word = min(bits, 32u);
    for (var up = 1u; up <= min(depth, 5u); up++) {
        let d = depth - up;
        let span = 1u << up;
        for (var j = 0u; j < in_word / span; j++) {
            var part = word >> (j * span);
            if span < 32u {
                part &= (1u << span) - 1u;
            }
            cbt_heap[(1u << d) + (id.x * 32u) / span + j] = countOneBits(part);
        }
    }
}

// One heap level `d` (6 <= d <= D - 6): 2^d threads; the level from the dispatch size.
@compute @workgroup_size(UDLOD_WORKGROUP)
fn cbt_reduce(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let d = firstLeadingBit(groups.x * groups.y) + 6u;
    let k = id.y * groups.x * UDLOD_WORKGROUP + id.x;
    let n = (1u << d) + k;
    cbt_heap[n] = cbt_heap[2u * n] + cbt_heap[2u * n + 1u];
}

// The levels from min(D - 6, 5) up to the root, in one workgroup.
@compute @workgroup_size(UDLOD_WORKGROUP)
fn cbt_reduce_top(@builtin(local_invocation_id) lid: vec3<u32>) {
    let depth = chunked.cbt.x;
    if depth <= 5u {
        return;
    }
    var d = min(depth - 6u, 5u);
    loop {
        if lid.x < (1u << d) {
            let n = (1u << d) + lid.x;
            cbt_heap[n] = cbt_heap[2u * n] + cbt_heap[2u * n + 1u];
        }
        storageBarrier();
        workgroupBarrier();
        if d == 0u {
            break;
        }
        d -= 1u;
    }
}

@compute @workgroup_size(UDLOD_WORKGROUP)
fn cbt_list(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= state.current_count {
        return;
    }
    let leaf = cbt_decode(id.x);
    let t = cbt_chunk(leaf.x, leaf.y);
    if !chunk_inside(t) {
        return;
    }
    if chunk_culled(t) {
        atomicAdd(&state.culled, 1u);
        return;
    }
    emit_final(t);
}

// ---- both ----

@compute @workgroup_size(1)
fn finish() {
    let n = min(atomicLoad(&state.final_count), chunked.lists.x);
    state.index_count = chunked.cbt.y;
    state.instance_count = n;
    state.first_index = 0u;
    state.vertex_offset = 0;
    state.first_instance = 0u;
    state.map_x = n;
    state.map_y = 1u;
    state.map_z = 1u;
    state.mesh_x = n;
    state.mesh_y = 1u;
    state.mesh_z = 1u;
}

// One workgroup per listed chunk: its level into every level-0 cell it covers (the LOD map
// is zero-filled before: 0 where no chunk is drawn).
@compute @workgroup_size(UDLOD_WORKGROUP)
fn lod_map_fill(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = final_chunks[wg.x];
    let side = 1u << t.lod;
    let origin = vec2<u32>(t.x << t.lod, t.y << t.lod);
    for (var k = lid.x; k < side * side; k += UDLOD_WORKGROUP) {
        let c = origin + vec2<u32>(k % side, k / side);
        if c.x < chunked.lists.z && c.y < chunked.lists.w {
            lod_map[c.y * chunked.lists.z + c.x] = t.lod;
        }
    }
}

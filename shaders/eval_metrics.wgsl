// The evaluator's frame analysis (src/eval/gpu/): every metric of docs/metrics.md that is a
// sum over pixels, computed where the frame is. Per pixel of a rendered frame: the world point
// its depth gives, the exact level-0 surface there (the reference tiles: the full-resolution
// triangle mesh brute force draws), the height and screen-space errors, popping against the
// previous frame, holes against the reference frame, the PSNR and SSIM terms; per tracked
// world point the swimming observation; for the reference frame the swim seeds. Histograms
// are accumulated with atomics by the per-pixel pass (one invocation per pixel, no workgroup
// memory or barriers: on a CPU device such as lavapipe each workgroup is then plain SIMD
// code), which writes the error images; a per-block pass (one invocation per 8x8 block)
// sums them, counts holes and computes the block's SSIM window; one reducing workgroup sums
// the blocks: the host reads kilobytes. Mirrors src/eval/metrics.rs; tests/eval_gpu.rs proves
// both equal.

struct EvalView {
    // xyz: camera right (world); w: focal length (px).
    right: vec4<f32>,
    // xyz: camera up; w: near plane (m).
    up: vec4<f32>,
    // xyz: camera forward; w: far plane (m).
    forward: vec4<f32>,
    // xy: the sample cell the camera is in (on the earth: the sample under it,
    // Lattice::sample_at); z: the view's first column; w: its columns.
    cell: vec4<i32>,
    // xy: camera's sample position - cell, times spacing (m); z + w: camera z (on the earth:
    // its height above the lattice surface) (m) as f32 high and low parts.
    offset: vec4<f32>,
    // On the earth: the camera's world position split into f32 hi and lo parts (the
    // renderer's camera_hi / camera_lo).
    cam_hi: vec4<f32>,
    cam_lo: vec4<f32>,
}

struct EvalFrame {
    views: array<EvalView, EVAL_MAX_VIEWS>,
    // x, y: frame width and height (px); z: views; w: 1 when the error image holds the
    // previous frame (popping is measured).
    size: vec4<u32>,
    // x, y: level-0 samples per side; z, w: reference tiles per side.
    data: vec4<u32>,
    // x: sample spacing (m).
    params: vec4<f32>,
    // x: tracked points; y: first seed written this frame; z: seeds written this frame (0:
    // none); w: 8x8 blocks of the frame (partials to sum).
    points: vec4<u32>,
    // x, y: the seed grid (columns, rows); z: 8x8 blocks per row.
    grid: vec4<u32>,
    // The geolocation lattice (src/geo/lattice.rs): x samples per node (0: flat world), y/z
    // nodes per row/column.
    lattice: vec4<u32>,
}

// A tracked world point: sample cell + fraction (x, y) and the exact surface's height there.
struct Seed {
    cell: vec2<i32>,
    valid: u32,
    pad0: u32,
    frac: vec2<f32>,
    z: f32,
    pad1: f32,
}

// One 8x8 block's sums.
struct Partial {
    // height error |m|, screen-space error px, SSIM of the window, 1 when the window counts.
    sums: vec4<f32>,
    // maximum height error, maximum screen-space error, 0 (pass 1 keeps the square sum's
    // high word here), the silhouette's drop in pixels (metrics::Holes::silhouette_px).
    maxes: vec4<f32>,
    // pixels with an error, holes, squared RGB differences, cracks (the holes with the
    // method's terrain above them in their column).
    counts: vec4<u32>,
}

struct Totals {
    metres_sum: f32,
    pixels_sum: f32,
    metres_max: f32,
    pixels_max: f32,
    ssim_sum: f32,
    silhouette_px: f32,
    error_count: u32,
    holes: u32,
    sq_lo: u32,
    sq_hi: u32,
    ssim_windows: u32,
    cracks: u32,
    // Pixels or points whose surface point had no reference tile (a bug if not 0).
    missing: atomic<u32>,
    pad1: u32,
    pad2: u32,
    pad3: u32,
}

struct Stats {
    totals: Totals,
    // EVAL_HIST_BINS each: |height error| (m), screen-space error (px), popping (px).
    hist: array<atomic<u32>, EVAL_HIST_TOTAL>,
    // Per tracked point: (height error m, distance m); distance < 0: not seen this frame.
    swim: array<vec2<f32>>,
}

const EVAL_HIST_TOTAL: u32 = 3u * EVAL_HIST_BINS;
// Error-image value of a pixel without an error (sky, or off the data); the host fills the
// buffer with it (EVAL_NO_ERROR_PX) before the first frame.
const NO_ERROR: f32 = EVAL_NO_ERROR_PX;
const NO_TILE: u32 = 0xffffffffu;
const TILE_SIDE: u32 = EVAL_REF_TILE + 1u;

@group(0) @binding(0) var<uniform> frame: EvalFrame;
// Reference tiles: TILE_SIDE^2 level-0 heights each (rows from the south).
@group(0) @binding(1) var<storage, read> ref_tiles: array<f32>;
// Per reference tile (row-major over the data): its slot in ref_tiles, or NO_TILE.
@group(0) @binding(2) var<storage, read> ref_table: array<u32>;
// The analysed frame: reversed-Z depth and RGBA8 colour, row 0 at the top.
@group(0) @binding(3) var<storage, read> depth: array<f32>;
@group(0) @binding(4) var<storage, read> color: array<u32>;
// The reference (brute-force) frame of the same cameras.
@group(0) @binding(5) var<storage, read> ref_depth: array<f32>;
@group(0) @binding(6) var<storage, read> ref_color: array<u32>;
@group(0) @binding(7) var<storage, read_write> seeds: array<Seed>;
// Signed screen-space error per pixel of the previous frame, then of this one (NO_ERROR).
@group(0) @binding(8) var<storage, read_write> error_image: array<f32>;
@group(0) @binding(9) var<storage, read_write> partials: array<Partial>;
@group(0) @binding(10) var<storage, read_write> stats: Stats;
// |height error| (m) per pixel of this frame (where error_image is not NO_ERROR).
@group(0) @binding(11) var<storage, read_write> metres_image: array<f32>;
// The renderer's geolocation lattice (three vec4 per node: hi, lo, up; one placeholder node
// in a flat world), the same data the vertex shaders place the terrain with.
@group(0) @binding(12) var<storage, read> geo_lattice: array<vec4<f32>>;

// Level-0 height of sample s (inside the data) from its reference tile, or a negative tile.
struct Sample4 {
    h00: f32,
    h10: f32,
    h01: f32,
    h11: f32,
    ok: bool,
}

// The four samples of the quad whose lower corner is c0 (0 <= c0 <= size - 2).
fn quad_samples(c0: vec2<i32>) -> Sample4 {
    var out = Sample4(0.0, 0.0, 0.0, 0.0, false);
    let t = vec2<u32>(c0) / EVAL_REF_TILE;
    let entry = ref_table[t.y * frame.data.z + t.x];
    if entry == NO_TILE {
        return out;
    }
    let local = vec2<u32>(c0) - t * EVAL_REF_TILE;
    let base = entry * TILE_SIDE * TILE_SIDE + local.y * TILE_SIDE + local.x;
    out.h00 = ref_tiles[base];
    out.h10 = ref_tiles[base + 1u];
    out.h01 = ref_tiles[base + TILE_SIDE];
    out.h11 = ref_tiles[base + TILE_SIDE + 1u];
    out.ok = true;
    return out;
}

struct Height {
    h: f32,
    ok: bool,
}

// The exact surface at sample position cell + frac (clamped to the data): the full-resolution
// mesh, quads split from (c + 1, r) to (c, r + 1) (Heightmap::mesh_height_at).
fn exact_height(cell: vec2<i32>, frac: vec2<f32>) -> Height {
    let hi = vec2<i32>(frame.data.xy) - vec2<i32>(1);
    var c0 = cell;
    var f = frac;
    if c0.x < 0 {
        c0.x = 0;
        f.x = 0.0;
    }
    if c0.y < 0 {
        c0.y = 0;
        f.y = 0.0;
    }
    if c0.x >= hi.x {
        c0.x = hi.x - 1;
        f.x = 1.0;
    }
    if c0.y >= hi.y {
        c0.y = hi.y - 1;
        f.y = 1.0;
    }
    let q = quad_samples(c0);
    if !q.ok {
        atomicAdd(&stats.totals.missing, 1u);
        return Height(0.0, false);
    }
    if f.x + f.y <= 1.0 {
        return Height(q.h00 + (q.h10 - q.h00) * f.x + (q.h01 - q.h00) * f.y, true);
    }
    return Height(q.h11 + (q.h01 - q.h11) * (1.0 - f.x) + (q.h10 - q.h11) * (1.0 - f.y), true);
}

// The view whose columns hold frame column x.
fn view_of(x: u32) -> u32 {
    var v = 0u;
    for (var i = 1u; i < frame.size.z; i += 1u) {
        if x >= u32(frame.views[i].cell.z) {
            v = i;
        }
    }
    return v;
}

// Camera-relative world point of the surface at pixel (x, y) (x within the view) with
// reversed-Z depth d > 0 (metrics::world_point).
fn world_rel(v: u32, x: u32, y: u32, d: f32) -> vec3<f32> {
    let view = frame.views[v];
    let focal = view.right.w;
    let near = view.up.w;
    let far = view.forward.w;
    let along = near * far / (d * (far - near) + near);
    let sx = f32(x) + 0.5 - f32(view.cell.w) * 0.5;
    let sy = f32(frame.size.y) * 0.5 - (f32(y) + 0.5);
    let r = view.forward.xyz * focal + view.right.xyz * sx + view.up.xyz * sy;
    return r * (along / focal);
}

struct GridPos {
    cell: vec2<i32>,
    frac: vec2<f32>,
}

// A camera-relative point in the grid's frame: its sample position and its height (m) above
// the surface of height 0 along the surface's up (flat world: z).
struct GridPoint {
    p: GridPos,
    // Height minus the camera's (m): add the camera's (offset.z + offset.w) for the height.
    dz: f32,
}

fn grid_pos(v: u32, rel: vec3<f32>) -> GridPos {
    return grid_point(v, rel).p;
}

fn grid_point(v: u32, rel: vec3<f32>) -> GridPoint {
    if frame.lattice.x != 0u {
        return lattice_inverse(v, rel);
    }
    let view = frame.views[v];
    let q = (view.offset.xy + rel.xy) / frame.params.x;
    let fl = floor(q);
    return GridPoint(GridPos(view.cell.xy + vec2<i32>(fl), q - fl), rel.z);
}

// The lattice helpers and their inverse (lattice_invert) are shared with PGM.
//!include lattice_inverse.wgsl

// Camera-relative position (view v) of the surface point at sample cell + frac and height h:
// the vertex shaders' relative_position on the earth.
fn lattice_position(v: u32, cell: vec2<i32>, frac: vec2<f32>, h: f32) -> vec3<f32> {
    let l = i32(frame.lattice.x);
    let n = lattice_cell_of(cell);
    let f = (vec2<f32>(cell - n * l) + frac) / f32(l);
    let view = frame.views[v];
    let q = lattice_patch(n, view.cam_hi.xyz, view.cam_lo.xyz);
    return lattice_bilerp(q.p00, q.p10, q.p01, q.p11, f) + h * lattice_bilerp(q.u00, q.u10, q.u01, q.u11, f);
}

// The inverse of lattice_position (Lattice::sample_at on the CPU): the sample position and
// height whose surface point is the camera-relative `rel`, starting from the camera's own
// sample position and height (lattice_invert in include/lattice_inverse.wgsl).
fn lattice_inverse(v: u32, rel: vec3<f32>) -> GridPoint {
    let view = frame.views[v];
    let hit = lattice_invert(
        view.cam_hi.xyz, view.cam_lo.xyz, view.cell.xy, view.offset.xy / frame.params.x,
        view.offset.z + view.offset.w, rel, EVAL_LATTICE_ITERATIONS,
    );
    return GridPoint(GridPos(hit.cell, hit.frac), hit.dz);
}

// The up vector (unit length on the earth) at sample cell + frac; the flat world's is z.
fn up_at(cell: vec2<i32>, frac: vec2<f32>) -> vec3<f32> {
    if frame.lattice.x == 0u {
        return vec3<f32>(0.0, 0.0, 1.0);
    }
    let l = i32(frame.lattice.x);
    let n = lattice_cell_of(cell);
    let f = (vec2<f32>(cell - n * l) + frac) / f32(l);
    let x = vec2<i32>(1, 0);
    let y = vec2<i32>(0, 1);
    return normalize(lattice_bilerp(lattice_node_up(n), lattice_node_up(n + x), lattice_node_up(n + y), lattice_node_up(n + x + y), f));
}

// Whether a sample position lies on the data, at least EVAL_EDGE_BAND samples inside its
// border (metrics::on_data).
fn on_data(p: GridPos) -> bool {
    let hi = vec2<i32>(frame.data.xy) - vec2<i32>(1);
    let low_ok = p.cell > vec2<i32>(0) | (p.cell == vec2<i32>(0) & p.frac >= vec2<f32>(EVAL_EDGE_BAND));
    let high_ok = p.cell < hi - vec2<i32>(1)
        | (p.cell == hi - vec2<i32>(1) & p.frac <= vec2<f32>(1.0 - EVAL_EDGE_BAND));
    return all(low_ok) && all(high_ok);
}

// Height of a point `rel_z` above the camera's height (flat world: its camera-relative z; on
// the earth: its height above the lattice surface minus the camera's) above the exact surface
// of height h there (metres).
fn height_error(v: u32, rel_z: f32, h: f32) -> f32 {
    let off = frame.views[v].offset;
    return ((off.z - h) + rel_z) + off.w;
}

fn hist_bin(value: f32) -> u32 {
    if !(value > EVAL_HIST_MIN) {
        return 0u;
    }
    let b = ceil(log(value / EVAL_HIST_MIN) / log(EVAL_HIST_STEP));
    return u32(min(b, f32(EVAL_HIST_BINS - 1u)));
}

fn count_in(hist: u32, value: f32) {
    atomicAdd(&stats.hist[hist * EVAL_HIST_BINS + hist_bin(value)], 1u);
}

fn luma(c: u32) -> f32 {
    let p = unpack4x8unorm(c) * 255.0;
    return 0.299 * p.x + 0.587 * p.y + 0.114 * p.z;
}

fn sq_diff(a: u32, b: u32) -> u32 {
    let d = vec3<i32>(vec3<u32>(a & 255u, (a >> 8u) & 255u, (a >> 16u) & 255u))
        - vec3<i32>(vec3<u32>(b & 255u, (b >> 8u) & 255u, (b >> 16u) & 255u));
    return u32(dot(d, d));
}

struct PixelResult {
    // |height error| m, screen-space error px (valid when counted).
    metres: f32,
    pixels: f32,
    counted: bool,
    // Signed screen-space error for the error image (NO_ERROR when none).
    signed_px: f32,
}

// Pixel x (within view v, whose uniforms are `view`) of row y with depth d.
fn pixel_error(v: u32, view: EvalView, x: u32, y: u32, d: f32) -> PixelResult {
    var out = PixelResult(0.0, 0.0, false, NO_ERROR);
    if !(d > 0.0) {
        return out;
    }
    let rel = world_rel(v, x, y, d);
    let g = grid_point(v, rel);
    let p = g.p;
    if !on_data(p) {
        return out;
    }
    let h = exact_height(p.cell, p.frac);
    if !h.ok {
        return out;
    }
    let dh = height_error(v, g.dz, h.h);
    out.metres = abs(dh);
    out.pixels = abs(dh) * view.right.w / length(rel);
    out.counted = true;
    out.signed_px = select(out.pixels, -out.pixels, dh < 0.0);
    return out;
}

// Whether a neighbour's depth dn continues the surface at depth d (within 5%).
fn continues(dn: f32, d: f32) -> bool {
    return dn > 0.0 && abs(dn - d) <= 0.05 * d;
}

// Whether the depth around interior pixel i is continuous (no occlusion edge): every
// 4-neighbour shows terrain within 5% of the pixel's depth (metrics::popping).
fn continuous(i: u32, d: f32) -> bool {
    let w = frame.size.x;
    return continues(depth[i - 1u], d) && continues(depth[i + 1u], d)
        && continues(depth[i - w], d) && continues(depth[i + w], d);
}

// Holes (metrics::holes): sky at interior pixel i although the reference and its 8
// neighbours show terrain.
fn is_hole(i: u32) -> bool {
    if depth[i] > 0.0 {
        return false;
    }
    let w = frame.size.x;
    let a = i - w;
    let b = i + w;
    return ref_depth[a - 1u] > 0.0 && ref_depth[a] > 0.0 && ref_depth[a + 1u] > 0.0
        && ref_depth[i - 1u] > 0.0 && ref_depth[i] > 0.0 && ref_depth[i + 1u] > 0.0
        && ref_depth[b - 1u] > 0.0 && ref_depth[b] > 0.0 && ref_depth[b + 1u] > 0.0;
}

// The silhouette's drop at a hole (x, y) that is not a crack: the rows down to the frame's
// first terrain pixel in the column (the frame's height if none), plus one.
fn silhouette_drop(x: u32, y: u32) -> u32 {
    let w = frame.size.x;
    var below = y + 1u;
    while below < frame.size.y && depth[below * w + x] <= 0.0 {
        below += 1u;
    }
    return below - y + 1u;
}

// Whether the frame shows terrain above pixel (x, y) in its column: a hole there is sky seen
// through the surface, a crack (metrics::holes); without, the method's skyline lies below the
// reference's. Holes are rare, so the column walk costs little.
fn terrain_above(x: u32, y: u32) -> bool {
    let w = frame.size.x;
    for (var above = 0u; above < y; above += 1u) {
        if depth[above * w + x] > 0.0 {
            return true;
        }
    }
    return false;
}

// Per pixel (one invocation each, no workgroup memory or barriers: a CPU device runs it as
// plain SIMD loops): the errors into the histograms, the error and metre images, popping.
// The z dimension is the view (its uniforms are the same in every invocation).
@compute @workgroup_size(EVAL_TILE_PX, EVAL_TILE_PX)
fn pixels_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = gid.z;
    let view = frame.views[v];
    if gid.x >= u32(view.cell.w) || gid.y >= frame.size.y {
        return;
    }
    let w = frame.size.x;
    let hgt = frame.size.y;
    let x = u32(view.cell.z) + gid.x;
    let y = gid.y;
    let i = y * w + x;
    let d = depth[i];
    let e = pixel_error(v, view, gid.x, y, d);
    let previous = error_image[i];
    error_image[i] = e.signed_px;
    metres_image[i] = e.metres;
    if e.counted {
        count_in(0u, e.metres);
        count_in(1u, e.pixels);
        let interior = x >= 1u && y >= 1u && x + 1u < w && y + 1u < hgt;
        if frame.size.w == 1u && interior && previous != NO_ERROR && continuous(i, d) {
            count_in(2u, abs(e.signed_px - previous));
        }
    }
}

// Per 8x8 block of the frame (one invocation each, after pixels_main): sums and maxima of
// the errors, holes, squared RGB differences, and the block's SSIM window.
@compute @workgroup_size(EVAL_POINT_WORKGROUP)
fn blocks_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let b = gid.x;
    if b >= frame.points.w {
        return;
    }
    let w = frame.size.x;
    let hgt = frame.size.y;
    let origin = vec2<u32>(b % frame.grid.z, b / frame.grid.z) * EVAL_TILE_PX;
    let end = min(origin + vec2<u32>(EVAL_TILE_PX), vec2<u32>(w, hgt));
    var sums = vec4<f32>(0.0);
    var maxes = vec4<f32>(0.0);
    var counts = vec4<u32>(0u);
    var sa = 0.0;
    var sb = 0.0;
    for (var y = origin.y; y < end.y; y += 1u) {
        let inner_y = y >= 1u && y + 1u < hgt;
        for (var x = origin.x; x < end.x; x += 1u) {
            let i = y * w + x;
            let e = error_image[i];
            if e != NO_ERROR {
                let m = metres_image[i];
                let p = abs(e);
                sums.x += m;
                sums.y += p;
                maxes.x = max(maxes.x, m);
                maxes.y = max(maxes.y, p);
                counts.x += 1u;
            }
            if inner_y && x >= 1u && x + 1u < w && is_hole(i) {
                counts.y += 1u;
                if terrain_above(x, y) {
                    counts.w += 1u;
                } else {
                    maxes.w = max(maxes.w, f32(silhouette_drop(x, y)));
                }
            }
            let c = color[i];
            let r = ref_color[i];
            counts.z += sq_diff(r, c);
            sa += luma(r);
            sb += luma(c);
        }
    }
    // SSIM of the block's window (metrics::ssim): means first, then centred moments.
    let window = origin.x + EVAL_TILE_PX <= w && origin.y + EVAL_TILE_PX <= hgt;
    var ssim = 0.0;
    if window {
        let n = f32(EVAL_TILE_PX * EVAL_TILE_PX);
        let ma = sa / n;
        let mb = sb / n;
        var m = vec3<f32>(0.0);
        for (var y = origin.y; y < end.y; y += 1u) {
            for (var x = origin.x; x < end.x; x += 1u) {
                let i = y * w + x;
                let la = luma(ref_color[i]) - ma;
                let lb = luma(color[i]) - mb;
                m += vec3<f32>(la * la, lb * lb, la * lb);
            }
        }
        m /= n;
        let c1 = (0.01 * 255.0) * (0.01 * 255.0);
        let c2 = (0.03 * 255.0) * (0.03 * 255.0);
        ssim = ((2.0 * ma * mb + c1) * (2.0 * m.z + c2)) / ((ma * ma + mb * mb + c1) * (m.x + m.y + c2));
    }
    partials[b] = Partial(vec4<f32>(sums.xy, ssim, select(0.0, 1.0, window)), maxes, counts);
}

// Sums the blocks' partials into stats.totals in two passes without workgroup barriers:
// llvmpipe builds compute shaders with barriers as coroutines, and Mesa 25's LLVM took minutes
// to build the frames of the former barrier tree (docs/architecture.md "Which lavapipe").

// a + b for 64-bit values as (low, high) u32 pairs.
fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

// Pass 1 (one workgroup): invocation `li` sums partials li, li + W, li + 2W, ... and stores
// the sum in partials[li]: only invocation `li` reads that entry, so no barrier is needed.
// The buffer holds at least W entries; those past the blocks' count become zero partials.
@compute @workgroup_size(EVAL_REDUCE_WORKGROUP)
fn fold_main(@builtin(local_invocation_index) li: u32) {
    var sums = vec4<f32>(0.0);
    var maxes = vec4<f32>(0.0);
    var counts = vec4<u32>(0u);
    var sq = vec2<u32>(0u);
    for (var i = li; i < frame.points.w; i += EVAL_REDUCE_WORKGROUP) {
        let p = partials[i];
        sums += p.sums;
        maxes = max(maxes, p.maxes);
        counts += vec4<u32>(p.counts.xy, 0u, p.counts.w);
        sq = add64(sq, vec2<u32>(p.counts.z, 0u));
    }
    // The 64-bit square sum: its low word in counts.z as the blocks' own, its high word
    // bit-cast into maxes.z (unused by the blocks; pass 2 reads it as bits, never as a max).
    let folded_maxes = vec4<f32>(maxes.xy, bitcast<f32>(sq.y), maxes.w);
    partials[li] = Partial(sums, folded_maxes, vec4<u32>(counts.xy, sq.x, counts.w));
}

// Pass 2 (one invocation): the W folded partials into stats.totals.
@compute @workgroup_size(1)
fn reduce_main() {
    var sums = vec4<f32>(0.0);
    var maxes = vec4<f32>(0.0);
    var counts = vec4<u32>(0u);
    var sq = vec2<u32>(0u);
    for (var i = 0u; i < EVAL_REDUCE_WORKGROUP; i += 1u) {
        let p = partials[i];
        sums += p.sums;
        maxes = max(maxes, vec4<f32>(p.maxes.xy, 0.0, p.maxes.w));
        counts += vec4<u32>(p.counts.xy, 0u, p.counts.w);
        sq = add64(sq, vec2<u32>(p.counts.z, bitcast<u32>(p.maxes.z)));
    }
    {
        let s = sums;
        let m = maxes;
        let c = counts;
        stats.totals.metres_sum = s.x;
        stats.totals.pixels_sum = s.y;
        stats.totals.ssim_sum = s.z;
        stats.totals.ssim_windows = u32(s.w);
        stats.totals.metres_max = m.x;
        stats.totals.pixels_max = m.y;
        stats.totals.silhouette_px = m.w;
        stats.totals.error_count = c.x;
        stats.totals.holes = c.y;
        stats.totals.cracks = c.w;
        stats.totals.sq_lo = sq.x;
        stats.totals.sq_hi = sq.y;
    }
}

// Reference frames: the exact-surface points a grid of pixels sees join the tracked set
// (metrics::SwimTracker::seed).
@compute @workgroup_size(EVAL_POINT_WORKGROUP)
fn seed_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x;
    if k >= frame.points.z {
        return;
    }
    let nx = frame.grid.x;
    let ny = frame.grid.y;
    let i = k % nx;
    let j = k / nx;
    // (i + 0.5) / nx of the width, in integers (the CPU side computes the same).
    let x = ((2u * i + 1u) * frame.size.x) / (2u * nx);
    let y = ((2u * j + 1u) * frame.size.y) / (2u * ny);
    var s = Seed(vec2<i32>(0), 0u, 0u, vec2<f32>(0.0), 0.0, 0.0);
    let d = ref_depth[y * frame.size.x + x];
    if d > 0.0 {
        let v = view_of(x);
        let rel = world_rel(v, x - u32(frame.views[v].cell.z), y, d);
        let p = grid_pos(v, rel);
        let h = exact_height(p.cell, p.frac);
        if h.ok {
            s = Seed(p.cell, 1u, 0u, p.frac, h.h, 0.0);
        }
    }
    seeds[frame.points.y + k] = s;
}

// Camera-relative position of a seed for view v.
fn seed_rel(s: Seed, v: u32) -> vec3<f32> {
    if frame.lattice.x != 0u {
        return lattice_position(v, s.cell, s.frac, s.z);
    }
    let view = frame.views[v];
    let spacing = frame.params.x;
    let xy = vec2<f32>(s.cell - view.cell.xy) * spacing + s.frac * spacing - view.offset.xy;
    return vec3<f32>(xy, (s.z - view.offset.z) - view.offset.w);
}

// Each tracked point: where this frame shows it, the method's height error there
// (metrics::SwimTracker::observe).
@compute @workgroup_size(EVAL_POINT_WORKGROUP)
fn swim_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x;
    if k >= frame.points.x {
        return;
    }
    var obs = vec2<f32>(0.0, -1.0);
    let s = seeds[k];
    if s.valid == 1u {
        obs = observe(s);
    }
    stats.swim[k] = obs;
}

fn observe(s: Seed) -> vec2<f32> {
    let none = vec2<f32>(0.0, -1.0);
    for (var v = 0u; v < frame.size.z; v += 1u) {
        let view = frame.views[v];
        let rel = seed_rel(s, v);
        let z = dot(rel, view.forward.xyz);
        if z <= view.up.w {
            continue;
        }
        let focal = view.right.w;
        let wv = f32(view.cell.w);
        let px = floor(wv * 0.5 + dot(rel, view.right.xyz) * focal / z - 0.5 + 0.5);
        let py = floor(f32(frame.size.y) * 0.5 - dot(rel, view.up.xyz) * focal / z - 0.5 + 0.5);
        if px < 0.0 || py < 0.0 || px >= wv || py >= f32(frame.size.y) {
            continue;
        }
        // The first view the point projects into decides.
        let x = u32(px);
        let y = u32(py);
        let d = depth[y * frame.size.x + u32(view.cell.z) + x];
        if !(d > 0.0) {
            return none;
        }
        let q = world_rel(v, x, y, d);
        let footprint = length(rel) / focal;
        // Horizontal: across the surface's up at the point.
        let up = up_at(s.cell, s.frac);
        let dq = q - rel;
        if length(dq - up * dot(dq, up)) > 2.0 * footprint + 1e-6 {
            return none;
        }
        let g = grid_point(v, q);
        let h = exact_height(g.p.cell, g.p.frac);
        if !h.ok {
            return none;
        }
        return vec2<f32>(height_error(v, g.dz, h.h), length(q));
    }
    return none;
}

// UDLOD bindings (descriptor set 1, one set per frame slot). Mirrors `UdlodUniforms` and
// `TilingState` in src/lod/udlod/mod.rs; a test proves the layouts equal.

struct Udlod {
    // Camera-relative frustum planes (normal.xyz, offset): dot(n, p) + offset >= 0 inside.
    frustum: array<vec4<f32>, 6>,
    // x: split distance D of each level in metres (UDLOD_NO_SPLIT past the root); y: the
    // least width of the zone over which the level below morphs onto it (0: `morph_range` of
    // the split distance; the morph cascade sets it: `SplitField::zone`).
    split: array<vec4<f32>, UDLOD_MAX_LEVELS>,
    // x: offset of the level's min/max entries, y/z: tiles per side of the level, w: offset
    // of the level's split-field nodes ((y d + 1) x (z d + 1) values, d = counts.z).
    levels: array<vec4<u32>, UDLOD_MAX_LEVELS>,
    // x: quads per tile side, y: root level, z: final list capacity, w: temporary list capacity.
    sizes: vec4<u32>,
    // x: 1 = collapsing quadrants on, y: morph range, z: 1 = morphing on, w: 1 = frustum culling on.
    params: vec4<f32>,
    // The LOD viewer (distances for levels and morphs are measured from it): x/y relative to
    // the camera (m), z: reference height (terrain under the LOD viewer) minus its height.
    viewer: vec4<f32>,
    // x: 1 = quadrants of final tiles outside the frustum are not drawn (`cull_quadrants` with
    // culling), y: workgroups per row of a `refine` or `scatter` dispatch, z: split-field
    // nodes per tile side (`field_density`: 1 = the tiles' corners), w: 1 = vertex pulling.
    counts: vec4<u32>,
    // xy: the LOD metric's stretch of the grid frame per axis (metres per sample along x and
    // y, each a lower bound on the drawn surface, over the grid frame's spacing): exactly
    // (1, 1) on square grids (`Levels::stretch` in src/lod/udlod/levels.rs).
    metric: vec4<f32>,
    // Per draw mask (`grid::IndexLayout` in src/lod/udlod/grid.rs): x: its indices (with
    // vertex pulling its vertices) per tile, y: its first index in the index buffer.
    masks: array<vec4<u32>, UDLOD_TILE_MASKS>,
    // The first pass's parents, decided on the host and copied to the front of the temporary
    // list (`seed` in src/lod/udlod/seed.rs): x tiles, y those that split.
    seed: vec4<u32>,
}

struct Tile {
    x: u32,
    y: u32,
    lod: u32,
    pad: u32,
}

// Uniform, as `frame` (include/terrain_common.wgsl): as a read-only storage buffer it spared
// Mesa 22.3 some shader rebuilding on small scenes but slowed the prepass's compute passes
// there by a quarter on the main job (docs/architecture.md, "Uniform buffers on Mesa 22.3").
@group(1) @binding(0) var<uniform> udlod: Udlod;
// The split field: per level, values m >= 1 at the corners of the level's tiles; a point's
// split distance is split[lod] / m (see `SplitField` in src/lod/udlod/field.rs).
@group(1) @binding(5) var<storage, read> split_field: array<f32>;

// Camera-relative metres of an integer sample position (integers subtracted first: exact).
fn relative_xy(sample: vec2<i32>) -> vec2<f32> {
    return vec2<f32>(sample - frame.camera_cell.xy) * frame.camera_offset.w - frame.camera_offset.xy;
}

// LOD-viewer-relative grid-frame metres of an integer sample position (times `udlod.metric.xy`:
// metres of the LOD metric).
fn viewer_xy(sample: vec2<i32>) -> vec2<f32> {
    return relative_xy(sample) - udlod.viewer.xy;
}

fn field_corner(lod: u32, i: u32, j: u32) -> f32 {
    let level = udlod.levels[lod];
    return split_field[level.w + j * (level.y * udlod.counts.z + 1u) + i];
}

// The least split field over a tile of level `lod` at (x, y): its (d + 1)^2 nodes (mirrors
// `SplitField::tile_range`).
fn tile_field_min(x: u32, y: u32, lod: u32) -> f32 {
    let d = udlod.counts.z;
    var m = field_corner(lod, x * d, y * d);
    for (var j = 0u; j <= d; j++) {
        for (var i = 0u; i <= d; i++) {
            m = min(m, field_corner(lod, x * d + i, y * d + j));
        }
    }
    return m;
}

// The split field of level `lod` at an integer sample position: bilinear in the level's field
// cell, clamped to the cell's corner range; 1 past the root (mirrors `SplitField::at`).
fn field_at(sample: vec2<i32>, lod: u32) -> f32 {
    if lod > udlod.sizes.y {
        return 1.0;
    }
    let d = udlod.counts.z;
    // The cell's span in samples is a power of two: a shift and an exact scaling by 2^-shift
    // instead of divisions (a vector division is one scalar division per lane on llvmpipe:
    // 0.5 ms of Puget Sound's prepass at 640x360). The same cell and fraction as the
    // divisions of `SplitField::at` for every sample (a negative one clamps to cell 0 either
    // way).
    // Quads per tile side and field nodes per side are both powers of two
    // (`UdlodSettings::validate`): the cell's quads as a difference of exponents, not a
    // division (llvmpipe divides once per lane, in every inlined copy of this function).
    let shift = countTrailingZeros(udlod.sizes.x) - countTrailingZeros(d) + lod;
    let span = 1i << shift;
    let level = udlod.levels[lod];
    let cell = clamp(sample >> vec2<u32>(shift), vec2<i32>(0), vec2<i32>(i32(level.y * d) - 1, i32(level.z * d) - 1));
    let f = vec2<f32>(sample - cell * span) * bitcast<f32>((127u - shift) << 23u);
    let c = vec2<u32>(cell);
    let c00 = field_corner(lod, c.x, c.y);
    let c10 = field_corner(lod, c.x + 1u, c.y);
    let c01 = field_corner(lod, c.x, c.y + 1u);
    let c11 = field_corner(lod, c.x + 1u, c.y + 1u);
    let south = c00 * (1.0 - f.x) + c10 * f.x;
    let north = c01 * (1.0 - f.x) + c11 * f.x;
    let v = south * (1.0 - f.y) + north * f.y;
    return clamp(v, min(min(c00, c10), min(c01, c11)), max(max(c00, c10), max(c01, c11)));
}

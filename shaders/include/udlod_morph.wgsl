// UDLOD's vertex morph, one function for every caller: the vertex shaders of udlod.wgsl and the
// test probe udlod_probe.wgsl. Mirrored operation for operation by `morph_factor` and
// `morphed_vertex` in src/lod/udlod/select.rs; tests/udlod.rs evaluates this code through the
// probe and proves the two equal. Needs terrain_common.wgsl and udlod_common.wgsl.

// 0 = the tile's own grid, 1 = fully on the parent's grid (times the on/off switch
// `udlod.params.z`). `d` is the distance from the LOD viewer to the un-morphed vertex at the
// reference height in the LOD metric (`udlod.metric`), scaled by the parent level's split
// field; `parent_split` the parent level's split distance; the morph runs over the last
// `morph_range` of it.
fn morph_factor(sample: vec2<i32>, lod: u32) -> f32 {
    let d = length(vec3<f32>(viewer_xy(sample) * udlod.metric.xy, udlod.viewer.z));
    let scaled = d * field_at(sample, lod + 1u);
    let parent_split = udlod.split[lod + 1u].x;
    let morph_range = udlod.params.y;
    return clamp(1.0 - (1.0 - scaled / parent_split) / morph_range, 0.0, 1.0) * udlod.params.z;
}

// A tile's grid vertex after morphing: the position in samples as an integer cell and a
// fraction in [0, 1) (what `project` takes), the same position as one vector (texturing and
// height lookup), its height and the morph factor.
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
    let morph = morph_factor(sample, tile.lod);
    // Odd vertices slide onto their lower even neighbour: integer part and fraction kept apart
    // so that a fully morphed vertex is exactly the neighbour's sample.
    let odd = vec2<i32>(local & vec2<u32>(1u));
    var cell = sample - odd * i32(step);
    var frac = (1.0 - morph) * vec2<f32>(odd) * f32(step);
    // Tiles at the data's far edges reach past the last sample: clamp onto it.
    let last = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    frac = min(frac, vec2<f32>(max(last - cell, vec2<i32>(0))));
    cell = min(cell, last);
    // One representation per position: an unmorphed odd vertex (frac = step) and the same
    // sample as an even vertex of the neighbouring tile (frac = 0) must project through the
    // same arithmetic, or far from the camera their f32 positions differ by an ulp and the
    // shared edge shows pinholes.
    let whole = floor(frac);
    cell = cell + vec2<i32>(whole);
    frac = frac - whole;
    var v: MorphedVertex;
    v.cell = cell;
    v.frac = frac;
    v.grid_pos = vec2<f32>(cell) + frac;
    v.height = height_at(v.grid_pos);
    v.morph = morph;
    return v;
}

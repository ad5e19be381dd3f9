// Persistent grid mapping: a fixed grid of `cols` x `rows` vertices in the screen space of an
// auxiliary camera, projected onto the reference plane under the camera; every vertex takes
// the data's height at its projected point from a mip level chosen by the longest projected
// edge of its cells. Each vertex is a pure function of its grid index (one shared index grid,
// instanced over bands of rows), so the mesh has no cracks; but the grid follows the camera,
// so vertices slide over the terrain ("swimming"). See src/lod/pgm.rs and docs/pgm.md.

//!include terrain_common.wgsl
//!include lattice_inverse.wgsl
//!include pgm_sphere.wgsl
//!include pgm_grid.wgsl

// The heights (R32F, metres) with a 2x2-box mip chain; sampled trilinearly.
@group(1) @binding(1) var height_mips: texture_2d<f32>;
@group(1) @binding(2) var mip_sampler: sampler;
// On the earth: every grid vertex's sample position and mip level, written by `prepare_earth`
// (pgm_earth.wgsl) before the render pass; unused (a placeholder) on the flat world.
@group(1) @binding(4) var<storage, read> earth_vertices: array<EarthVertex>;

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> TerrainVertex {
    let cols = pgm.grid.x;
    let g = vec2<i32>(
        i32(vertex % cols),
        i32(min(instance * pgm.grid.z + vertex / cols, pgm.grid.y - 1u)),
    );
    var sp: SamplePos;
    if pgm.earth.w == 0.0 {
        sp = flat_sample(g);
    } else {
        let e = earth_vertices[u32(g.y) * cols + u32(g.x)];
        sp = SamplePos(e.cell, e.frac, e.level);
    }
    let cell = sp.cell;
    let frac = sp.frac;
    let level = sp.level;
    // Outside the data the vertex keeps its position and takes the border's height (clamped
    // sample); the fragment stage cuts every triangle at the border, where brute force ends.
    let last = vec2<i32>(frame.data_size.xy) - vec2<i32>(1);
    let outside = (cell < vec2<i32>(0)) | (cell >= last);
    let grid_pos = vec2<f32>(cell) + frac;
    let inside_pos = vec2<f32>(clamp(cell, vec2<i32>(0), last)) + select(frac, vec2<f32>(0.0), outside);
    let uv = (inside_pos + 0.5) / vec2<f32>(frame.data_size.xy);
    let h = textureSampleLevel(height_mips, mip_sampler, uv, level).r;
    return TerrainVertex(project(cell, frac, h), grid_pos);
}

@fragment
fn fs_main(v: TerrainVertex) -> @location(0) vec4<f32> {
    // Shaded first: its derivatives need every fragment of the quad.
    let colour = shade(v);
    // Beyond the data's edge (grid positions 0..size-1 are the data's samples): nothing.
    let last = vec2<f32>(frame.data_size.xy) - vec2<f32>(1.0);
    if any(v.grid_pos < vec2<f32>(0.0)) || any(v.grid_pos > last) {
        discard;
    }
    return colour;
}

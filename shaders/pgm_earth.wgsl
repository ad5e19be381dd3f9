// PGM on the earth (docs/pgm.md, "On the earth"): places every grid vertex once per frame
// before the render pass, so the vertex stage reads its sample position and mip level instead
// of computing its own and its four neighbours' points on the reference sphere and inverting
// the lattice per invocation. A workgroup computes the sphere points of its tile of grid
// vertices plus a one-vertex halo (the neighbours for the mip level) into workgroup memory,
// then each vertex's level and lattice inverse.

//!include terrain_common.wgsl
//!include lattice_inverse.wgsl
//!include pgm_sphere.wgsl
//!include pgm_grid.wgsl

@group(1) @binding(4) var<storage, read_write> earth_vertices: array<EarthVertex>;

// The tile's side with its halo.
const HALO_SIDE: u32 = PGM_EARTH_TILE + 2u;
// Every point is written (the loop below) before the barrier and any read: no zero-fill
// (build.rs, docs/architecture.md "Workgroup memory written first").
var<workgroup> sphere_points: array<vec3<f32>, HALO_SIDE * HALO_SIDE>;
//!workgroup-memory written-first

@compute @workgroup_size(PGM_EARTH_TILE, PGM_EARTH_TILE)
fn prepare_earth(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) index: u32,
) {
    let corner = vec2<i32>(group.xy * PGM_EARTH_TILE) - vec2<i32>(1);
    // Grid indices one past the grid's edges extrapolate (row_fraction), as the vertex
    // stage's neighbours did.
    for (var k = index; k < HALO_SIDE * HALO_SIDE; k += PGM_EARTH_TILE * PGM_EARTH_TILE) {
        let h = vec2<i32>(i32(k % HALO_SIDE), i32(k / HALO_SIDE));
        sphere_points[k] = earth_ground_point(corner + h);
    }
    workgroupBarrier();
    let g = group.xy * PGM_EARTH_TILE + local.xy;
    if g.x >= pgm.grid.x || g.y >= pgm.grid.y {
        return;
    }
    let c = (local.y + 1u) * HALO_SIDE + local.x + 1u;
    let p = sphere_points[c];
    let level = earth_level(
        p, sphere_points[c + 1u], sphere_points[c - 1u], sphere_points[c + HALO_SIDE],
        sphere_points[c - HALO_SIDE],
    );
    let hit = earth_hit(p);
    earth_vertices[g.y * pgm.grid.x + g.x] = EarthVertex(hit.cell, hit.frac, level);
}

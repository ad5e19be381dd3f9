// PGM's grid (docs/pgm.md): the uniforms, the row fractions and each grid vertex's sample
// position and mip level, on the flat world and on the earth. Shared by the vertex stage
// (pgm.wgsl) and, on the earth, the compute pass that places every grid vertex once per frame
// (pgm_earth.wgsl). The includer includes terrain_common.wgsl, lattice_inverse.wgsl and
// pgm_sphere.wgsl first.

// Mirrors `PgmUniforms` in src/lod/pgm.rs; a test proves the layouts equal.
struct Pgm {
    // xyz: camera-relative world direction of grid vertex (0, 0) (bottom left);
    // w: auxiliary camera height above the reference plane (m).
    dir0: vec4<f32>,
    // xyz: direction change from the first to the last column; w: largest ground distance (m).
    dcol: vec4<f32>,
    // xyz: direction change from the first to the last row; w: unused.
    drow: vec4<f32>,
    // x: columns, y: rows, z: rows per instanced band, w: mip levels of `height_mips`.
    grid: vec4<u32>,
    // On the earth (docs/pgm.md, "On the earth"; zero on the flat world): xyz: the up vector
    // at the camera's sample (world axes, as the directions above); w: radius of the
    // reference sphere (m), 0 on the flat world.
    earth: vec4<f32>,
    // xyz: columns per world metre at the camera; w: the reference height (m).
    to_col: vec4<f32>,
    // xyz: rows per world metre at the camera; w: sine of the sphere's horizon depression.
    to_row: vec4<f32>,
    // xy: the sample cell under the camera.
    cam_cell: vec4<i32>,
    // xy: the camera's sample position within it; z: the horizon's surface distance (m);
    // w: its depression angle (rad).
    cam_frac: vec4<f32>,
}

@group(1) @binding(0) var<uniform> pgm: Pgm;
// Each grid row's position in [0, 1] from the bottom of the auxiliary view to its top (rows
// warped towards the horizon, `row_fractions` in src/lod/pgm/mod.rs).
@group(1) @binding(3) var<storage, read> row_t: array<f32>;

// Row fraction of row `r`, extrapolated linearly one row past either end.
fn row_fraction(r: i32) -> f32 {
    let last = i32(pgm.grid.y) - 1;
    if r < 0 {
        return 2.0 * row_t[0] - row_t[1];
    }
    if r > last {
        return 2.0 * row_t[last] - row_t[last - 1];
    }
    return row_t[r];
}

// Camera-relative ground offset (metres) where the ray of grid vertex `g` meets the reference
// plane; rays at or above the horizon, and hits beyond it, are cut at the largest distance.
// `g` may lie one step outside the grid (neighbours for the edge length): it extrapolates.
fn ground_offset(g: vec2<i32>) -> vec2<f32> {
    let t = vec2<f32>(f32(g.x) / f32(pgm.grid.x - 1u), row_fraction(g.y));
    let dir = pgm.dir0.xyz + pgm.dcol.xyz * t.x + pgm.drow.xyz * t.y;
    let flat_len = length(dir.xy);
    if flat_len == 0.0 {
        return vec2<f32>(0.0);
    }
    var d = pgm.dcol.w;
    if dir.z < 0.0 {
        d = min(pgm.dir0.w * flat_len / -dir.z, d);
    }
    return dir.xy * (d / flat_len);
}

// On the earth: the camera-relative world point on the reference sphere that the ray of grid
// vertex `g` stands for, at surface distance `dist` along the sphere in the ray's azimuth:
// `sphere_distance` (shaders/include/pgm_sphere.wgsl).
fn earth_ground_point(g: vec2<i32>) -> vec3<f32> {
    let t = vec2<f32>(f32(g.x) / f32(pgm.grid.x - 1u), row_fraction(g.y));
    let d = normalize(pgm.dir0.xyz + pgm.dcol.xyz * t.x + pgm.drow.xyz * t.y);
    let up = pgm.earth.xyz;
    let rho = pgm.earth.w;
    let a = pgm.dir0.w;
    let d_max = pgm.dcol.w;
    // Sine of the ray's depression below the local horizontal, and its horizontal part.
    let s = -dot(d, up);
    let horizontal = d + s * up;
    let hl = length(horizontal);
    if hl == 0.0 {
        return -a * up;
    }
    let sphere = SphereView(rho, a, d_max, pgm.to_row.w, pgm.cam_frac.z, pgm.cam_frac.w);
    let dist = sphere_distance(sphere, s, hl);
    let phi = dist / rho;
    let half = sin(0.5 * phi);
    // rho (cos phi - 1) without cancellation: -2 rho sin^2(phi / 2).
    return horizontal * (rho * sin(phi) / hl) - up * (a + 2.0 * rho * half * half);
}

// World metres to texels at the camera (the lattice's Jacobian there, inverted).
fn earth_texels(e: vec3<f32>) -> f32 {
    return length(vec2<f32>(dot(pgm.to_col.xyz, e), dot(pgm.to_row.xyz, e)));
}

// A sample position: integer cell + fraction.
struct SamplePos {
    cell: vec2<i32>,
    frac: vec2<f32>,
    // Mip level of the heights.
    level: f32,
}

// The flat world: the ray's ground offset from the camera read as a grid offset from the
// camera's cell (and the ablation `earth_projection = false` on the earth).
fn flat_sample(g: vec2<i32>) -> SamplePos {
    let p = ground_offset(g);
    let spacing = frame.camera_offset.w;
    // Longest projected edge of the cells around the vertex, in texels -> mip level.
    var longest = 0.0;
    longest = max(longest, distance(p, ground_offset(g + vec2<i32>(1, 0))));
    longest = max(longest, distance(p, ground_offset(g - vec2<i32>(1, 0))));
    longest = max(longest, distance(p, ground_offset(g + vec2<i32>(0, 1))));
    longest = max(longest, distance(p, ground_offset(g - vec2<i32>(0, 1))));
    let level = clamp(log2(max(longest / spacing, 1.0)), 0.0, f32(pgm.grid.w - 1u));
    // Sample position as integer cell + fraction (relative to the camera cell first).
    let t = frame.camera_offset.xy / spacing + p / spacing;
    let fl = floor(t);
    return SamplePos(frame.camera_cell.xy + vec2<i32>(fl), t - fl, level);
}

// The earth, the mip level of a grid vertex from its point on the reference sphere `p` and
// its four neighbours' (the longest edge in texels, through the camera's Jacobian).
fn earth_level(p: vec3<f32>, east: vec3<f32>, west: vec3<f32>, north: vec3<f32>, south: vec3<f32>) -> f32 {
    var longest = earth_texels(east - p);
    longest = max(longest, earth_texels(west - p));
    longest = max(longest, earth_texels(north - p));
    longest = max(longest, earth_texels(south - p));
    return clamp(log2(max(longest, 1.0)), 0.0, f32(pgm.grid.w - 1u));
}

// The earth: the sample under the point `p` on the reference sphere, by the lattice's inverse
// from the first guess of the camera's Jacobian.
fn earth_hit(p: vec3<f32>) -> LatticeHit {
    let guess = pgm.cam_frac.xy + vec2<f32>(dot(pgm.to_col.xyz, p), dot(pgm.to_row.xyz, p));
    let fl = floor(guess);
    return lattice_invert(
        frame.camera_hi.xyz, frame.camera_lo.xyz, pgm.cam_cell.xy + vec2<i32>(fl), guess - fl,
        pgm.to_col.w, p, PGM_LATTICE_ITERATIONS,
    );
}

// A grid vertex's sample position and mip level as the earth pass stores it.
struct EarthVertex {
    cell: vec2<i32>,
    frac: vec2<f32>,
    level: f32,
}

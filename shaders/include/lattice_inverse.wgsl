// The inverse of the geolocation lattice's vertex mapping (src/geo/lattice.rs; the CPU's
// Lattice::sample_at), shared by the evaluator (shaders/eval_metrics.wgsl: each pixel's point
// back to the grid) and PGM on the earth (shaders/pgm.wgsl: each grid ray's surface point to
// the sample under it). The includer declares `frame.lattice` (x: samples per node, y/z: nodes
// per row/column) and `geo_lattice` (three vec4 per node: hi.xyz, lo.xyz, up.xyz), as both
// terrain_common.wgsl and eval_metrics.wgsl do. Cameras are given as split doubles (hi, lo).

// One lattice cell: corners (camera-relative) and up vectors.
struct LatticePatch {
    p00: vec3<f32>,
    p10: vec3<f32>,
    p01: vec3<f32>,
    p11: vec3<f32>,
    u00: vec3<f32>,
    u10: vec3<f32>,
    u01: vec3<f32>,
    u11: vec3<f32>,
}

// Camera-relative position of lattice node `node` (hi parts subtracted first, then lo parts:
// terrain_common.wgsl's lattice_relative for any camera).
fn lattice_node_rel(node: vec2<i32>, cam_hi: vec3<f32>, cam_lo: vec3<f32>) -> vec3<f32> {
    let i = 3 * (node.y * i32(frame.lattice.y) + node.x);
    return (geo_lattice[i].xyz - cam_hi) + (geo_lattice[i + 1].xyz - cam_lo);
}

fn lattice_node_up(node: vec2<i32>) -> vec3<f32> {
    return geo_lattice[3 * (node.y * i32(frame.lattice.y) + node.x) + 2].xyz;
}

// The lattice cell (lower node) of a sample cell, clamped like the vertex shaders'.
fn lattice_cell_of(cell: vec2<i32>) -> vec2<i32> {
    let l = i32(frame.lattice.x);
    let c = vec2<i32>(floor(vec2<f32>(cell) / f32(l)));
    return clamp(c, vec2<i32>(0), vec2<i32>(frame.lattice.yz) - vec2<i32>(2));
}

fn lattice_patch(n: vec2<i32>, cam_hi: vec3<f32>, cam_lo: vec3<f32>) -> LatticePatch {
    let x = vec2<i32>(1, 0);
    let y = vec2<i32>(0, 1);
    return LatticePatch(
        lattice_node_rel(n, cam_hi, cam_lo), lattice_node_rel(n + x, cam_hi, cam_lo),
        lattice_node_rel(n + y, cam_hi, cam_lo), lattice_node_rel(n + x + y, cam_hi, cam_lo),
        lattice_node_up(n), lattice_node_up(n + x), lattice_node_up(n + y), lattice_node_up(n + x + y),
    );
}

fn lattice_bilerp(a: vec3<f32>, b: vec3<f32>, c: vec3<f32>, d: vec3<f32>, f: vec2<f32>) -> vec3<f32> {
    return mix(mix(a, b, f.x), mix(c, d, f.x), f.y);
}

// A camera-relative point on the grid: its sample position (cell + fraction) and its height
// minus the start height (m) along the interpolated up vector.
struct LatticeHit {
    cell: vec2<i32>,
    frac: vec2<f32>,
    dz: f32,
}

// The sample position and height whose surface point (lattice position + height * up) is the
// camera-relative `rel`. Newton on the bilinear patch `P(f) + h U(f) = rel` of the current
// lattice cell, in camera-relative f32, from the sample position `start_cell + start_frac` at
// height `h0`; after each step the estimate moves into the cell it lies in (outside the
// lattice the edge cells extrapolate, as the vertex shaders do). At most `iterations` steps;
// it stops once the residual is f32 noise (docs/eval.md, "On the earth", derives the
// precision).
fn lattice_invert(cam_hi: vec3<f32>, cam_lo: vec3<f32>, start_cell: vec2<i32>, start_frac: vec2<f32>, h0: f32, rel: vec3<f32>, iterations: u32) -> LatticeHit {
    let l = i32(frame.lattice.x);
    let fl = f32(l);
    let last = vec2<i32>(frame.lattice.yz) - vec2<i32>(2);
    var n = lattice_cell_of(start_cell);
    var f = (vec2<f32>(start_cell - n * l) + start_frac) / fl;
    var q = lattice_patch(n, cam_hi, cam_lo);
    var dz = 0.0;
    // A residual this small is the f32 model's own noise (docs/eval.md, "On the earth").
    let tolerance = 5e-7 * length(rel) + 1e-4;
    for (var k = 0u; k < iterations; k += 1u) {
        let m = clamp(n + vec2<i32>(floor(f)), vec2<i32>(0), last);
        if any(m != n) {
            f -= vec2<f32>(m - n);
            n = m;
            q = lattice_patch(n, cam_hi, cam_lo);
        }
        let h = h0 + dz;
        let u = lattice_bilerp(q.u00, q.u10, q.u01, q.u11, f);
        let r = rel - (lattice_bilerp(q.p00, q.p10, q.p01, q.p11, f) + h * u);
        if dot(r, r) <= tolerance * tolerance {
            break;
        }
        let ux = mix(q.u10 - q.u00, q.u11 - q.u01, f.y);
        let uy = mix(q.u01 - q.u00, q.u11 - q.u10, f.x);
        let jx = mix(q.p10 - q.p00, q.p11 - q.p01, f.y) + h * ux;
        let jy = mix(q.p01 - q.p00, q.p11 - q.p10, f.x) + h * uy;
        // Solve [jx jy u] d = r (Cramer's rule).
        let c = cross(jy, u);
        let det = dot(jx, c);
        if abs(det) < 1e-30 {
            break;
        }
        let d = vec3<f32>(dot(r, c), dot(jx, cross(r, u)), dot(jx, cross(jy, r))) / det;
        f += d.xy;
        dz += d.z;
    }
    let s = f * fl;
    let cell = floor(s);
    return LatticeHit(n * l + vec2<i32>(cell), s - cell, dz);
}

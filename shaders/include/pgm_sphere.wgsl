// PGM on the earth: the surface distance (m, along the reference sphere) of the point a ray of
// the auxiliary camera stands for (docs/pgm.md, "On the earth"). One definition for the vertex
// shader (`pgm.wgsl`) and its probe (`pgm_probe.wgsl`); `lod::pgm::earth::Sphere::distance`
// is the same formula in f64 and a test (tests/pgm.rs) proves the two equal.

// The sphere as the camera sees it: what `PgmUniforms` carries (`Sphere::gpu_terms`).
struct SphereView {
    // Radius (m) and the camera's height above it (m).
    radius: f32,
    height: f32,
    // The largest distance (m).
    d_max: f32,
    // The horizon's depression: its sine, its surface distance (m) and the angle (rad).
    sin_h: f32,
    d_h: f32,
    e_h: f32,
}

// `s`: sine of the ray's depression below the local horizontal; `hl`: the length of its
// horizontal part (`sqrt(1 - s^2)` for a unit ray). Where the ray meets the sphere, no farther
// than the largest distance; a ray above the sphere's horizon takes a distance between the
// horizon's and the largest, logarithmic in its depression angle, so rows towards the
// horizontal keep covering terrain beyond the sphere's horizon that rises into view.
fn sphere_distance(v: SphereView, s: f32, hl: f32) -> f32 {
    let rho = v.radius;
    let a = v.height;
    if s > v.sin_h {
        // Along the ray: t^2 - 2 t (rho + a) s + a (2 rho + a) = 0, the nearer root in the
        // form without cancellation; the discriminant factored by the horizon's sine.
        let ra = rho + a;
        let disc = ra * ra * (s - v.sin_h) * (s + v.sin_h);
        let along = a * (2.0 * rho + a) / (ra * s + sqrt(disc));
        return min(rho * atan2(along * hl, ra - along * s), v.d_max);
    }
    if v.d_h < v.d_max && s > 0.0 {
        return v.d_max * exp(log(v.d_h / v.d_max) * asin(s) / v.e_h);
    }
    return v.d_max;
}

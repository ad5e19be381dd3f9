// Constants shared by the Rust code and the WGSL shaders: the single source of truth.
//
// `build.rs` includes this file and prepends a WGSL `const` for every entry of
// [`WGSL_CONSTANTS`] to each WGSL shader and a `#define` with the same literal to each GLSL
// shader (`shaders/glsl/`), so the sides cannot drift apart. Keep this file free of
// `use` statements and crate paths: it is compiled twice (by the build script and the crate).

/// A constant value as it is written into WGSL.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WgslValue {
    U32(u32),
    F32(f32),
}

impl WgslValue {
    /// The WGSL type and literal, e.g. `("u32", "64u")`.
    pub fn wgsl(&self) -> (&'static str, String) {
        match self {
            WgslValue::U32(v) => ("u32", format!("{v}u")),
            // `{:?}` always prints a decimal point or exponent, so WGSL reads it as f32.
            WgslValue::F32(v) => ("f32", format!("{v:?}")),
        }
    }
}

macro_rules! shared_constants {
    ($($(#[$doc:meta])* $name:ident : $ty:ident = $value:expr;)*) => {
        $($(#[$doc])* pub const $name: $ty = $value;)*
        /// Every shared constant with its WGSL value, in declaration order.
        pub const WGSL_CONSTANTS: &[(&str, WgslValue)] = &[
            $((stringify!($name), shared_constants!(@value $ty, $name)),)*
        ];
    };
    (@value u32, $name:ident) => { WgslValue::U32($name) };
    (@value f32, $name:ident) => { WgslValue::F32($name) };
}

shared_constants! {
    /// Quads per side of the shared index grid that brute force instances over the terrain.
    /// 128 keeps the index buffer small (~400 KB) while an instance still covers 16k triangles,
    /// so per-instance overhead is negligible.
    BRUTE_CHUNK_QUADS: u32 = 128;
    /// Below the smallest radius of curvature of the WGS84 ellipsoid (the meridian radius at
    /// the equator, 6,335,439 m): culling boxes on the earth grow by the sagitta over it times
    /// `cos(max latitude)` (`Lattice::curve_radius`, uploaded per lattice).
    GEO_MIN_RADIUS: f32 = 6.3e6;
    /// Chunked LOD's mesh path: quads per side of the block one mesh workgroup emits (a chunk
    /// of more quads is split into blocks: 81 vertices and 128 triangles per workgroup, within
    /// every VK_EXT_mesh_shader device's output limits of 256 each).
    CHUNKED_MESH_QUADS: u32 = 8;
    /// Quads per side of a GeoMipMapping block (blocks of 2^5 + 1 = 33 samples, 6 levels).
    GEOMIPMAP_BLOCK_QUADS: u32 = 32;
    /// Ambient term of the directional light, so slopes facing away from the sun stay readable.
    LIGHT_AMBIENT: f32 = 0.25;
    /// Scale applied to the diffuse term (ambient + diffuse <= 1 keeps albedo unsaturated).
    LIGHT_DIFFUSE: f32 = 0.75;
    /// Most quadtree levels UDLOD supports (16384 samples with 4-quad tiles need 13).
    UDLOD_MAX_LEVELS: u32 = 16;
    /// Split distance meaning "never split / never morph" (beyond the root level).
    UDLOD_NO_SPLIT: f32 = 3.0e38;
    /// Threads per workgroup of the tiling passes.
    UDLOD_WORKGROUP: u32 = 64;
    /// How far past 1 a quadrant's odd vertices' unclamped morph factor must lie for the
    /// quadrant to be drawn as its parent's grid (`morph::tile_collapse_mask`): the vertex stage,
    /// which recomputes the factor, then clamps it to exactly 1 even where a device rounds the two
    /// stages' arithmetic differently (Vulkan allows it; the H200 does).
    UDLOD_COLLAPSE_MARGIN: f32 = 1e-3;
    /// Draw masks of a tile: per quadrant its own grid, its parent's grid (collapsed) or
    /// nothing (outside the frustum), 3^4 (`lod::udlod::grid::TileMask`), each with its own
    /// index list and indirect draw.
    UDLOD_TILE_MASKS: u32 = 81;
    /// Most tiles the host hands the tiling prepass as its first pass's parents: the coarse
    /// levels walked on the CPU (`lod::udlod::seed`), so those levels cost no GPU passes. 256
    /// keeps the walk to tens of microseconds of host time per view.
    UDLOD_SEED_TILES: u32 = 256;
    /// Flags of a tile in the prepass's temporary list (`Tile.pad`), set by whoever writes it
    /// (a `refine` pass, or the host's seed): decided; outside the data; culled; splitting;
    /// inside the frustum (no quadrant of it needs a test, `select::tile_inside`).
    UDLOD_TILE_DECIDED: u32 = 1;
    UDLOD_TILE_OUTSIDE: u32 = 2;
    UDLOD_TILE_CULLED: u32 = 4;
    UDLOD_TILE_SPLITS: u32 = 8;
    UDLOD_TILE_INSIDE: u32 = 16;
    /// Most levels a clipmap quadtree holds (per-level windows in the quadtree header).
    CLIPMAP_MAX_LEVELS: u32 = 16;
    /// A quadtree entry is `atlas_index | atlas_lod << CLIPMAP_LOD_SHIFT` (R16G16_UINT-like).
    CLIPMAP_LOD_SHIFT: u32 = 16;
    /// Threads per workgroup of the height probe (tests: GPU heights read back).
    CLIPMAP_PROBE_WORKGROUP: u32 = 64;
    /// Evaluator (`src/eval/gpu/`): pixels per side of a workgroup of the per-pixel pass,
    /// which is also the side of an SSIM window (non-overlapping 8x8 windows).
    EVAL_TILE_PX: u32 = 8;
    /// Evaluator: samples per side of a reference tile of level 0 (a tile stores one more
    /// row and column, shared with its neighbours, so every mesh triangle lies in one tile).
    EVAL_REF_TILE: u32 = 64;
    /// Evaluator: most views (cameras) of one frame (`render::MAX_VIEWS`).
    EVAL_MAX_VIEWS: u32 = 4;
    /// Evaluator histograms: log-spaced bins, bin `i` holding values up to
    /// `EVAL_HIST_MIN * EVAL_HIST_STEP^i` (bin 0 everything up to `EVAL_HIST_MIN`).
    EVAL_HIST_BINS: u32 = 2200;
    EVAL_HIST_MIN: f32 = 1e-6;
    EVAL_HIST_STEP: f32 = 1.012;
    /// Evaluator: points closer than this (in samples) to the data's border are not measured:
    /// methods collapse geometry that leaves the data onto the border (PGM), and whether such
    /// a point lies in or out is f32 noise.
    EVAL_EDGE_BAND: f32 = 1e-3;
    /// Evaluator: the error-image value of a pixel without an error (sky, off the data).
    EVAL_NO_ERROR_PX: f32 = 3.0e38;
    /// Threads per workgroup of the swimming and seeding passes.
    EVAL_POINT_WORKGROUP: u32 = 64;
    /// Invocations of the fold pass summing the 8x8 blocks' partials (one workgroup, no
    /// barriers), then summed by one invocation (shaders/eval_metrics.wgsl `fold_main`).
    EVAL_REDUCE_WORKGROUP: u32 = 256;
    /// Evaluator on the earth: most Newton iterations inverting the geolocation lattice per
    /// point (camera-relative f32, docs/eval.md "On the earth"; converged after 3-4 from the
    /// camera's lattice cell; the loop stops once the residual is f32 noise, 2^-21 of the
    /// point's distance).
    EVAL_LATTICE_ITERATIONS: u32 = 6;
    /// PGM on the earth: most Newton iterations inverting the geolocation lattice per grid
    /// vertex (`lattice_invert`, from the camera's Jacobian as the first guess; docs/pgm.md
    /// "On the earth").
    PGM_LATTICE_ITERATIONS: u32 = 6;
    /// Threads per workgroup of the UDLOD morph probe (tests: morphed vertices read back).
    UDLOD_PROBE_WORKGROUP: u32 = 64;
    /// PGM on the earth: grid vertices per side of the tile one workgroup of
    /// `shaders/pgm_earth.wgsl` places (its sphere points, with a one-vertex halo, in workgroup
    /// memory).
    PGM_EARTH_TILE: u32 = 16;
    /// Threads per workgroup of the PGM sphere probe (tests: reference-sphere distances read
    /// back).
    PGM_PROBE_WORKGROUP: u32 = 64;
    /// Threads per workgroup of the terrain-helper probes (tests: WGSL vs GLSL helpers).
    TERRAIN_PROBE_WORKGROUP: u32 = 64;
}

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
    /// Most levels a clipmap quadtree holds (per-level windows in the quadtree header).
    CLIPMAP_MAX_LEVELS: u32 = 16;
    /// A quadtree entry is `atlas_index | atlas_lod << CLIPMAP_LOD_SHIFT` (R16G16_UINT-like).
    CLIPMAP_LOD_SHIFT: u32 = 16;
    /// Threads per workgroup of the height probe (tests: GPU heights read back).
    CLIPMAP_PROBE_WORKGROUP: u32 = 64;
    /// Threads per workgroup of the UDLOD morph probe (tests: morphed vertices read back).
    UDLOD_PROBE_WORKGROUP: u32 = 64;
    /// Threads per workgroup of the terrain-helper probes (tests: WGSL vs GLSL helpers).
    TERRAIN_PROBE_WORKGROUP: u32 = 64;
}

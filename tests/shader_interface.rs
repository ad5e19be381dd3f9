//! The CPU and WGSL sides of shared data must agree: the uniform block layout is checked
//! against naga's reflection of the composed shader, and the shared constants against the
//! values the shader was built with.

use std::mem::{offset_of, size_of};

use vkterrain::driver::shaders::{BRUTE_WGSL, PGM_WGSL, UDLOD_TILING_WGSL, UDLOD_WGSL};
use vkterrain::frame::FrameUniforms;
use vkterrain::gpu_constants::{WGSL_CONSTANTS, WgslValue};
use vkterrain::lod::udlod::{TilingState, UdlodUniforms};

fn composed_shaders() -> [(&'static str, &'static str); 4] {
    [
        ("brute", BRUTE_WGSL),
        ("udlod", UDLOD_WGSL),
        ("udlod_tiling", UDLOD_TILING_WGSL),
        ("pgm", PGM_WGSL),
    ]
}

/// Asserts that the WGSL struct `struct_name` in each of `shaders` has exactly the member
/// names/offsets `rust` (in order) and the size `size`.
fn assert_struct_layout(
    shaders: &[(&str, &str)],
    struct_name: &str,
    rust: &[(&str, usize)],
    size: usize,
) {
    for (name, source) in shaders {
        let module = naga::front::wgsl::parse_str(source).expect("composed shader parses");
        let ty = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(struct_name))
            .unwrap_or_else(|| panic!("{name}: no struct {struct_name}"))
            .1;
        let naga::TypeInner::Struct { members, span } = &ty.inner else {
            panic!("{name}: {struct_name} is not a struct")
        };
        let wgsl: Vec<(&str, usize)> = members
            .iter()
            .map(|m| (m.name.as_deref().unwrap_or("?"), m.offset as usize))
            .collect();
        assert_eq!(
            wgsl, rust,
            "{name}: {struct_name} member names/offsets differ"
        );
        assert_eq!(*span as usize, size, "{name}: {struct_name} size differs");
    }
}

#[test]
fn pgm_uniforms_match_the_wgsl_struct() {
    use vkterrain::lod::pgm::PgmUniforms;
    let rust = [
        ("dir0", offset_of!(PgmUniforms, dir0)),
        ("dcol", offset_of!(PgmUniforms, dcol)),
        ("drow", offset_of!(PgmUniforms, drow)),
        ("grid", offset_of!(PgmUniforms, grid)),
    ];
    assert_struct_layout(&[("pgm", PGM_WGSL)], "Pgm", &rust, size_of::<PgmUniforms>());
}

#[test]
fn frame_uniforms_match_the_wgsl_struct() {
    let rust = [
        ("view_proj", offset_of!(FrameUniforms, view_proj)),
        ("camera_cell", offset_of!(FrameUniforms, camera_cell)),
        ("camera_offset", offset_of!(FrameUniforms, camera_offset)),
        ("sun_dir", offset_of!(FrameUniforms, sun_dir)),
        ("data_size", offset_of!(FrameUniforms, data_size)),
    ];
    assert_struct_layout(
        &composed_shaders(),
        "Frame",
        &rust,
        size_of::<FrameUniforms>(),
    );
}

#[test]
fn udlod_uniforms_match_the_wgsl_struct() {
    let rust = [
        ("frustum", offset_of!(UdlodUniforms, frustum)),
        ("split", offset_of!(UdlodUniforms, split)),
        ("levels", offset_of!(UdlodUniforms, levels)),
        ("sizes", offset_of!(UdlodUniforms, sizes)),
        ("params", offset_of!(UdlodUniforms, params)),
        ("viewer", offset_of!(UdlodUniforms, viewer)),
        ("counts", offset_of!(UdlodUniforms, counts)),
    ];
    let shaders = composed_shaders();
    assert_struct_layout(&shaders[1..3], "Udlod", &rust, size_of::<UdlodUniforms>());
}

#[test]
fn tiling_state_matches_the_wgsl_struct() {
    // The WGSL side spells the indirect-argument arrays out member by member.
    let draw = offset_of!(TilingState, draw);
    let rust = [
        ("dispatch_x", offset_of!(TilingState, dispatch)),
        ("dispatch_y", offset_of!(TilingState, dispatch) + 4),
        ("dispatch_z", offset_of!(TilingState, dispatch) + 8),
        ("pass_index", offset_of!(TilingState, pass_index)),
        ("index_count", draw),
        ("instance_count", draw + 4),
        ("first_index", draw + 8),
        ("vertex_offset", draw + 12),
        ("first_instance", draw + 16),
        ("parent_count", offset_of!(TilingState, parent_count)),
        ("child_count", offset_of!(TilingState, child_count)),
        ("final_count", offset_of!(TilingState, final_count)),
        ("reserved_leaves", offset_of!(TilingState, reserved_leaves)),
        ("overflow", offset_of!(TilingState, overflow)),
        ("culled", offset_of!(TilingState, culled)),
        ("passes_started", offset_of!(TilingState, passes_started)),
    ];
    assert_struct_layout(
        &[("udlod_tiling", UDLOD_TILING_WGSL)],
        "TilingState",
        &rust,
        size_of::<TilingState>(),
    );
    // The vkCmdDispatchIndirect / vkCmdDrawIndexedIndirect argument layouts.
    assert_eq!(offset_of!(TilingState, dispatch), 0);
    assert_eq!(draw % 4, 0);
    assert_eq!(size_of::<[u32; 5]>(), 20);
}

#[test]
fn tile_record_matches_the_wgsl_struct() {
    assert_struct_layout(
        &composed_shaders()[1..3],
        "Tile",
        &[("x", 0), ("y", 4), ("lod", 8), ("pad", 12)],
        vkterrain::lod::udlod::TILE_BYTES as usize,
    );
}

#[test]
fn shared_constants_are_in_every_shader_with_their_rust_values() {
    for (name, source) in composed_shaders() {
        let module = naga::front::wgsl::parse_str(source).expect("composed shader parses");
        for &(constant_name, rust_value) in WGSL_CONSTANTS {
            let (_, constant) = module
                .constants
                .iter()
                .find(|(_, k)| k.name.as_deref() == Some(constant_name))
                .unwrap_or_else(|| panic!("{name}: constant {} missing", constant_name));
            let value = &module.global_expressions[constant.init];
            let naga::Expression::Literal(literal) = value else {
                panic!("{name}: {} is not a literal", constant_name)
            };
            let matches = match (rust_value, literal) {
                (WgslValue::U32(a), naga::Literal::U32(b)) => a == *b,
                (WgslValue::F32(a), naga::Literal::F32(b)) => a.to_bits() == b.to_bits(),
                _ => false,
            };
            assert!(
                matches,
                "{name}: {} = {literal:?}, Rust has {rust_value:?}",
                constant_name
            );
        }
    }
}

#[test]
fn clipmap_header_matches_the_wgsl_struct() {
    use vkterrain::clipmap::quadtree::HEADER_BYTES;
    use vkterrain::driver::shaders::CLIPMAP_PROBE_WGSL;
    let mut shaders = composed_shaders().to_vec();
    shaders.push(("clipmap_probe", CLIPMAP_PROBE_WGSL));
    for (name, source) in shaders {
        let module = naga::front::wgsl::parse_str(source).expect("composed shader parses");
        let ty = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some("Clipmap"))
            .unwrap_or_else(|| panic!("{name}: no struct Clipmap"))
            .1;
        let naga::TypeInner::Struct { members, .. } = &ty.inner else {
            panic!("{name}: Clipmap is not a struct")
        };
        let wgsl: Vec<(&str, u64)> = members
            .iter()
            .map(|m| (m.name.as_deref().unwrap_or("?"), m.offset as u64))
            .collect();
        // `ViewQuadtree::gpu_bytes`: two vec4<u32>, a vec4<f32>, CLIPMAP_MAX_LEVELS vec4<i32>, then
        // entries.
        assert_eq!(
            wgsl,
            [
                ("params", 0),
                ("params2", 16),
                ("viewer", 32),
                ("levels", 48),
                ("entries", HEADER_BYTES)
            ],
            "{name}"
        );
    }
}

//! The CPU and WGSL sides of shared data must agree: the uniform block layout is checked
//! against naga's reflection of the composed shader, and the shared constants against the
//! values the shader was built with.

use vkterrain::gpu_constants::{WGSL_CONSTANTS, WgslValue};
use vkterrain::render::terrain::FrameUniforms;

fn composed_shaders() -> [(&'static str, &'static str); 2] {
    [
        ("brute", vkterrain::driver::shaders::BRUTE_WGSL),
        ("pgm", vkterrain::driver::shaders::PGM_WGSL),
    ]
}

/// Member names and offsets of WGSL struct `name` in `source`, and its size.
fn wgsl_struct(source: &str, name: &str) -> (Vec<(String, usize)>, usize) {
    let module = naga::front::wgsl::parse_str(source).expect("composed shader parses");
    let ty = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("no struct {name}"))
        .1;
    let naga::TypeInner::Struct { members, span } = &ty.inner else {
        panic!("{name} is not a struct")
    };
    (
        members
            .iter()
            .map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize))
            .collect(),
        *span as usize,
    )
}

#[test]
fn pgm_uniforms_match_the_wgsl_struct() {
    use std::mem::{offset_of, size_of};
    use vkterrain::lod::pgm::PgmUniforms;
    let rust: Vec<(String, usize)> = [
        ("dir0", offset_of!(PgmUniforms, dir0)),
        ("dcol", offset_of!(PgmUniforms, dcol)),
        ("drow", offset_of!(PgmUniforms, drow)),
        ("grid", offset_of!(PgmUniforms, grid)),
    ]
    .into_iter()
    .map(|(n, o)| (n.to_string(), o))
    .collect();
    let (wgsl, span) = wgsl_struct(vkterrain::driver::shaders::PGM_WGSL, "Pgm");
    assert_eq!(wgsl, rust);
    assert_eq!(span, size_of::<PgmUniforms>());
}

#[test]
fn frame_uniforms_match_the_wgsl_struct() {
    use std::mem::{offset_of, size_of};
    let rust = [
        ("view_proj", offset_of!(FrameUniforms, view_proj)),
        ("camera_cell", offset_of!(FrameUniforms, camera_cell)),
        ("camera_offset", offset_of!(FrameUniforms, camera_offset)),
        ("sun_dir", offset_of!(FrameUniforms, sun_dir)),
        ("data_size", offset_of!(FrameUniforms, data_size)),
    ];
    for (name, source) in composed_shaders() {
        let module = naga::front::wgsl::parse_str(source).expect("composed shader parses");
        let frame = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some("Frame"))
            .unwrap_or_else(|| panic!("{name}: no struct Frame"))
            .1;
        let naga::TypeInner::Struct { members, span } = &frame.inner else {
            panic!("{name}: Frame is not a struct")
        };
        let wgsl: Vec<(&str, usize)> = members
            .iter()
            .map(|m| (m.name.as_deref().unwrap_or("?"), m.offset as usize))
            .collect();
        assert_eq!(wgsl, rust, "{name}: member names/offsets differ");
        assert_eq!(
            *span as usize,
            size_of::<FrameUniforms>(),
            "{name}: size differs"
        );
    }
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

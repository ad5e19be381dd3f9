//! The CPU and WGSL sides of shared data must agree, checked against naga's reflection of each
//! composed shader: struct layouts (uniform blocks, indirect arguments, probe records), the
//! shared constants, and every descriptor-set table (binding, WGSL name, resource kind, stages)
//! against the shaders' `@group/@binding` globals.

use std::mem::{offset_of, size_of};

use ash::vk;
use vkterrain::driver::descriptors::{Binding, PROBE_SET};
use vkterrain::driver::shaders::{
    BRUTE_WGSL, CHUNKED_PROBE_WGSL, CHUNKED_SELECT_WGSL, CHUNKED_WGSL, CLIPMAP_PROBE_WGSL,
    EVAL_METRICS_WGSL, GEOMIPMAP_WGSL, PGM_EARTH_WGSL, PGM_PROBE_WGSL, PGM_WGSL, UDLOD_PROBE_WGSL,
    UDLOD_TILING_WGSL, UDLOD_WGSL,
};
use vkterrain::eval::gpu::EVAL_SET;
use vkterrain::frame::FrameUniforms;
use vkterrain::frame::terrain::TERRAIN_SET;
use vkterrain::gpu_constants::{WGSL_CONSTANTS, WgslValue};
use vkterrain::lod::pgm::PGM_SET;
use vkterrain::lod::udlod::{
    DRAW_GROUPS, DRAW_STRIDE, DRAWS_OFFSET, TilingState, UDLOD_SET, UdlodUniforms,
};

/// The drawing shaders (the probes come on top where a test covers them too).
fn composed_shaders() -> [(&'static str, &'static str); 4] {
    [
        ("brute", BRUTE_WGSL),
        ("udlod", UDLOD_WGSL),
        ("udlod_tiling", UDLOD_TILING_WGSL),
        ("pgm", PGM_WGSL),
    ]
}

/// A descriptor-set table by name.
type Table = (&'static str, &'static [Binding]);

/// Shaders (name, composed source) with the table bound at each of their groups.
type ShaderSets = Vec<(&'static str, &'static str, Vec<(u32, Table)>)>;

/// Every shader with the table bound at each of its groups (what each pipeline layout uses).
fn shader_sets() -> ShaderSets {
    let terrain = ("TERRAIN_SET", TERRAIN_SET);
    let udlod = ("UDLOD_SET", UDLOD_SET);
    let pgm = ("PGM_SET", PGM_SET);
    let probe = ("PROBE_SET", PROBE_SET);
    let chunked = ("CHUNKED_SET", vkterrain::lod::chunked::CHUNKED_SET);
    vec![
        ("chunked", CHUNKED_WGSL, vec![(0, terrain), (1, chunked)]),
        (
            "chunked_probe",
            CHUNKED_PROBE_WGSL,
            vec![(0, terrain), (1, chunked), (2, probe)],
        ),
        (
            "chunked_select",
            CHUNKED_SELECT_WGSL,
            vec![(0, terrain), (1, chunked)],
        ),
        ("brute", BRUTE_WGSL, vec![(0, terrain)]),
        ("geomipmap", GEOMIPMAP_WGSL, vec![(0, terrain)]),
        ("udlod", UDLOD_WGSL, vec![(0, terrain), (1, udlod)]),
        (
            "udlod_tiling",
            UDLOD_TILING_WGSL,
            vec![(0, terrain), (1, udlod)],
        ),
        ("pgm", PGM_WGSL, vec![(0, terrain), (1, pgm)]),
        ("pgm_earth", PGM_EARTH_WGSL, vec![(0, terrain), (1, pgm)]),
        ("pgm_probe", PGM_PROBE_WGSL, vec![(0, probe)]),
        (
            "clipmap_probe",
            CLIPMAP_PROBE_WGSL,
            vec![(0, terrain), (1, probe)],
        ),
        (
            "udlod_probe",
            UDLOD_PROBE_WGSL,
            vec![(0, terrain), (1, udlod), (2, probe)],
        ),
        (
            "eval_metrics",
            EVAL_METRICS_WGSL,
            vec![(0, ("EVAL_SET", EVAL_SET))],
        ),
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
        ("earth", offset_of!(PgmUniforms, earth)),
        ("to_col", offset_of!(PgmUniforms, to_col)),
        ("to_row", offset_of!(PgmUniforms, to_row)),
        ("cam_cell", offset_of!(PgmUniforms, cam_cell)),
        ("cam_frac", offset_of!(PgmUniforms, cam_frac)),
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
        ("haze", offset_of!(FrameUniforms, haze)),
        ("lattice", offset_of!(FrameUniforms, lattice)),
        ("camera_hi", offset_of!(FrameUniforms, camera_hi)),
        ("camera_lo", offset_of!(FrameUniforms, camera_lo)),
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
        ("metric", offset_of!(UdlodUniforms, metric)),
        ("masks", offset_of!(UdlodUniforms, masks)),
        ("seed", offset_of!(UdlodUniforms, seed)),
    ];
    let shaders = composed_shaders();
    assert_struct_layout(&shaders[1..3], "Udlod", &rust, size_of::<UdlodUniforms>());
}

#[test]
fn chunk_probe_record_matches_the_wgsl_struct() {
    use vkterrain::lod::chunked::probe::ChunkProbe as P;
    assert_struct_layout(
        &[("chunked_probe", CHUNKED_PROBE_WGSL)],
        "ChunkProbe",
        &[
            ("chunk", offset_of!(P, chunk)),
            ("local", offset_of!(P, local)),
            ("sample", offset_of!(P, sample)),
        ],
        size_of::<P>(),
    );
}

#[test]
fn chunked_uniforms_match_the_wgsl_struct() {
    use vkterrain::lod::chunked::ChunkedUniforms as U;
    let rust = [
        ("frustum", offset_of!(U, frustum)),
        ("levels", offset_of!(U, levels)),
        ("viewer", offset_of!(U, viewer)),
        ("params", offset_of!(U, params)),
        ("sizes", offset_of!(U, sizes)),
        ("lists", offset_of!(U, lists)),
        ("cbt", offset_of!(U, cbt)),
        ("metric", offset_of!(U, metric)),
    ];
    assert_struct_layout(
        &[
            ("chunked", CHUNKED_WGSL),
            ("chunked_select", CHUNKED_SELECT_WGSL),
        ],
        "Chunked",
        &rust,
        size_of::<U>(),
    );
    assert_struct_layout(
        &[
            ("chunked", CHUNKED_WGSL),
            ("chunked_select", CHUNKED_SELECT_WGSL),
        ],
        "Chunk",
        &[("x", 0), ("y", 4), ("lod", 8), ("pad", 12)],
        vkterrain::lod::chunked::CHUNK_BYTES as usize,
    );
}

/// `ChunkState` as the selection kernels see it, with its indirect arguments where Vulkan
/// reads them (dispatch at 0, the indexed draw at `DRAW_OFFSET`, the LOD-map dispatch at
/// `MAP_OFFSET`, the mesh-task draw at `MESH_OFFSET`).
#[test]
fn chunk_state_matches_the_wgsl_struct() {
    use vkterrain::lod::chunked::{
        ChunkState as S, DRAW_OFFSET as D, MAP_OFFSET as M, MESH_OFFSET as ME,
    };
    let draw = offset_of!(S, draw);
    let map = offset_of!(S, map);
    let mesh = offset_of!(S, mesh);
    assert_eq!((D as usize, M as usize, ME as usize), (draw, map, mesh));
    type T = vk::DrawMeshTasksIndirectCommandEXT;
    type I = vk::DrawIndexedIndirectCommand;
    type P = vk::DispatchIndirectCommand;
    let rust = [
        ("dispatch_x", offset_of!(S, dispatch) + offset_of!(P, x)),
        ("dispatch_y", offset_of!(S, dispatch) + offset_of!(P, y)),
        ("dispatch_z", offset_of!(S, dispatch) + offset_of!(P, z)),
        ("pass_index", offset_of!(S, pass_index)),
        ("index_count", draw + offset_of!(I, index_count)),
        ("instance_count", draw + offset_of!(I, instance_count)),
        ("first_index", draw + offset_of!(I, first_index)),
        ("vertex_offset", draw + offset_of!(I, vertex_offset)),
        ("first_instance", draw + offset_of!(I, first_instance)),
        ("map_x", map + offset_of!(P, x)),
        ("map_y", map + offset_of!(P, y)),
        ("map_z", map + offset_of!(P, z)),
        ("current_count", offset_of!(S, current_count)),
        ("next_count", offset_of!(S, next_count)),
        ("final_count", offset_of!(S, final_count)),
        ("overflow", offset_of!(S, overflow)),
        ("culled", offset_of!(S, culled)),
        ("passes_started", offset_of!(S, passes_started)),
        ("splits", offset_of!(S, splits)),
        ("merges", offset_of!(S, merges)),
        ("mesh_x", mesh + offset_of!(T, group_count_x)),
        ("mesh_y", mesh + offset_of!(T, group_count_y)),
        ("mesh_z", mesh + offset_of!(T, group_count_z)),
    ];
    assert_struct_layout(
        &[("chunked_select", CHUNKED_SELECT_WGSL)],
        "ChunkState",
        &rust,
        size_of::<S>(),
    );
    assert_eq!(offset_of!(S, dispatch), 0);
}

#[test]
fn tiling_state_matches_the_wgsl_struct() {
    let rust = [
        ("dispatch_x", offset_of!(TilingState, dispatch)),
        ("dispatch_y", offset_of!(TilingState, dispatch) + 4),
        ("dispatch_z", offset_of!(TilingState, dispatch) + 8),
        ("pass_index", offset_of!(TilingState, pass_index)),
        ("parent_count", offset_of!(TilingState, parent_count)),
        ("child_count", offset_of!(TilingState, child_count)),
        ("final_count", offset_of!(TilingState, final_count)),
        ("reserved_leaves", offset_of!(TilingState, reserved_leaves)),
        ("overflow", offset_of!(TilingState, overflow)),
        ("culled", offset_of!(TilingState, culled)),
        ("passes_started", offset_of!(TilingState, passes_started)),
        ("splits_allowed", offset_of!(TilingState, splits_allowed)),
        ("split_requests", offset_of!(TilingState, split_requests)),
        ("static_draws", offset_of!(TilingState, static_draws)),
        ("morphing_draws", offset_of!(TilingState, morphing_draws)),
        ("group_count", offset_of!(TilingState, group_count)),
        ("group_first", offset_of!(TilingState, group_first)),
        ("draws", offset_of!(TilingState, draws)),
    ];
    let tiling = [("udlod_tiling", UDLOD_TILING_WGSL)];
    assert_struct_layout(&tiling, "TilingState", &rust, size_of::<TilingState>());
    // The arrays' lengths and strides.
    let module = naga::front::wgsl::parse_str(UDLOD_TILING_WGSL).unwrap();
    let (_, state) = (module.types.iter())
        .find(|(_, t)| t.name.as_deref() == Some("TilingState"))
        .unwrap();
    let naga::TypeInner::Struct { members, .. } = &state.inner else {
        panic!("TilingState is not a struct")
    };
    for (m, stride) in members[members.len() - 3..].iter().zip([4, 4, DRAW_STRIDE]) {
        let naga::TypeInner::Array {
            size: naga::ArraySize::Constant(n),
            stride: s,
            ..
        } = module.types[m.ty].inner
        else {
            panic!("{:?} is not a fixed-size array", m.name)
        };
        assert_eq!((n.get() as usize, s), (DRAW_GROUPS, stride), "{:?}", m.name);
    }
}

/// The indirect arguments inside `TilingState` are laid out as Vulkan reads them: the WGSL
/// members sit at the offsets of `VkDispatchIndirectCommand` (at 0, where the prepass
/// dispatches from) and each group's `IndirectDraw` at those of
/// `VkDrawIndexedIndirectCommand` (from `DRAWS_OFFSET`, drawn with `DRAW_STRIDE`), its first
/// four words at those of a `VkDrawIndirectCommand` for vertex pulling.
#[test]
fn indirect_arguments_are_vulkan_commands() {
    let module = naga::front::wgsl::parse_str(UDLOD_TILING_WGSL).unwrap();
    let wgsl = struct_offsets(&module, "TilingState");
    let at = |name: &str| wgsl.iter().find(|(n, _)| n == name).unwrap().1;
    type D = vk::DispatchIndirectCommand;
    assert_eq!(at("dispatch_x"), offset_of!(D, x));
    assert_eq!(at("dispatch_y"), offset_of!(D, y));
    assert_eq!(at("dispatch_z"), offset_of!(D, z));
    assert_eq!(at("draws"), DRAWS_OFFSET as usize);
    // Vulkan: the offset is a multiple of 4, the stride at least the command's size.
    assert_eq!(DRAWS_OFFSET % 4, 0);
    let draw = struct_offsets(&module, "IndirectDraw");
    let at = |name: &str| draw.iter().find(|(n, _)| n == name).unwrap().1;
    type I = vk::DrawIndexedIndirectCommand;
    assert_eq!(DRAW_STRIDE as usize, size_of::<I>());
    assert_eq!(at("index_count"), offset_of!(I, index_count));
    assert_eq!(at("instance_count"), offset_of!(I, instance_count));
    assert_eq!(at("first_index"), offset_of!(I, first_index));
    assert_eq!(at("vertex_offset"), offset_of!(I, vertex_offset));
    assert_eq!(at("first_instance"), offset_of!(I, first_instance));
    // Vertex pulling: vertex_count, instance_count, first_vertex, first_instance read
    // index_count, instance_count, first_index and vertex_offset (`finish` writes them so).
    type P = vk::DrawIndirectCommand;
    assert!(size_of::<P>() <= DRAW_STRIDE as usize);
    assert_eq!(at("index_count"), offset_of!(P, vertex_count));
    assert_eq!(at("instance_count"), offset_of!(P, instance_count));
    assert_eq!(at("first_index"), offset_of!(P, first_vertex));
    assert_eq!(at("vertex_offset"), offset_of!(P, first_instance));
    // The last group's draw ends inside the state.
    let end = DRAWS_OFFSET as usize + DRAW_GROUPS * DRAW_STRIDE as usize;
    assert_eq!(end, size_of::<TilingState>());
}

/// Member names and byte offsets of WGSL struct `name`.
fn struct_offsets(module: &naga::Module, name: &str) -> Vec<(String, usize)> {
    let ty = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("no struct {name}"))
        .1;
    let naga::TypeInner::Struct { members, .. } = &ty.inner else {
        panic!("{name} is not a struct")
    };
    members
        .iter()
        .map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize))
        .collect()
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
    for (name, source, _) in shader_sets() {
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
    use vkterrain::clipmap::quadtree::{ClipmapHeader, HEADER_BYTES};
    let mut shaders = composed_shaders().to_vec();
    shaders.push(("clipmap_probe", CLIPMAP_PROBE_WGSL));
    for (name, source) in shaders {
        let module = naga::front::wgsl::parse_str(source).expect("composed shader parses");
        let wgsl = struct_offsets(&module, "Clipmap");
        // `ViewQuadtree::gpu_bytes`: the header, then the entries.
        let rust = [
            ("params", offset_of!(ClipmapHeader, params)),
            ("params2", offset_of!(ClipmapHeader, params2)),
            ("viewer", offset_of!(ClipmapHeader, viewer)),
            ("levels", offset_of!(ClipmapHeader, levels)),
            ("entries", HEADER_BYTES as usize),
        ]
        .map(|(n, o)| (n.to_string(), o));
        assert_eq!(wgsl, rust, "{name}");
    }
}

#[test]
fn udlod_probe_record_matches_the_wgsl_struct() {
    use vkterrain::lod::udlod::probe::ProbeVertex;
    let rust = [
        ("tile", offset_of!(ProbeVertex, tile)),
        ("local", offset_of!(ProbeVertex, local)),
        ("cell", offset_of!(ProbeVertex, cell)),
        ("frac", offset_of!(ProbeVertex, frac)),
        ("values", offset_of!(ProbeVertex, values)),
    ];
    assert_struct_layout(
        &[("udlod_probe", UDLOD_PROBE_WGSL)],
        "ProbeVertex",
        &rust,
        size_of::<ProbeVertex>(),
    );
}

#[test]
fn pgm_earth_vertex_matches_the_wgsl_struct() {
    use vkterrain::lod::pgm::EarthVertex;
    let rust = [
        ("cell", offset_of!(EarthVertex, cell)),
        ("frac", offset_of!(EarthVertex, frac)),
        ("level", offset_of!(EarthVertex, level)),
    ];
    assert_struct_layout(
        &[("pgm", PGM_WGSL), ("pgm_earth", PGM_EARTH_WGSL)],
        "EarthVertex",
        &rust,
        size_of::<EarthVertex>(),
    );
}

#[test]
fn pgm_probe_record_matches_the_wgsl_struct() {
    use vkterrain::lod::pgm::probe::SphereProbe;
    let rust = [
        ("sphere", offset_of!(SphereProbe, sphere)),
        ("horizon", offset_of!(SphereProbe, horizon)),
    ];
    assert_struct_layout(
        &[("pgm_probe", PGM_PROBE_WGSL)],
        "SphereProbe",
        &rust,
        size_of::<SphereProbe>(),
    );
}

/// The descriptor type a WGSL resource global needs, from its address space and type.
fn descriptor_type(
    module: &naga::Module,
    var: &naga::GlobalVariable,
) -> Option<vk::DescriptorType> {
    match (var.space, &module.types[var.ty].inner) {
        (naga::AddressSpace::Uniform, _) => Some(vk::DescriptorType::UNIFORM_BUFFER),
        (naga::AddressSpace::Storage { .. }, _) => Some(vk::DescriptorType::STORAGE_BUFFER),
        (naga::AddressSpace::Handle, naga::TypeInner::Sampler { .. }) => {
            Some(vk::DescriptorType::SAMPLER)
        }
        (naga::AddressSpace::Handle, naga::TypeInner::Image { class, .. }) => match class {
            naga::ImageClass::Storage { .. } => Some(vk::DescriptorType::STORAGE_IMAGE),
            _ => Some(vk::DescriptorType::SAMPLED_IMAGE),
        },
        _ => None,
    }
}

fn stage_flag(stage: naga::ShaderStage) -> vk::ShaderStageFlags {
    match stage {
        naga::ShaderStage::Vertex => vk::ShaderStageFlags::VERTEX,
        naga::ShaderStage::Fragment => vk::ShaderStageFlags::FRAGMENT,
        naga::ShaderStage::Compute => vk::ShaderStageFlags::COMPUTE,
        other => panic!("stage {other:?} is not used by vkterrain"),
    }
}

/// What disagrees between a shader's `@group/@binding` globals and the tables bound at its
/// groups (`sets`: group, table): a global whose group has no table, whose binding the table
/// lacks, or whose name or resource kind differs; an entry point reading a binding from a stage
/// the table does not grant. Also returns the `(group, binding)` pairs the shader declares.
fn interface_problems(
    shader: &str,
    source: &str,
    sets: &[(u32, Table)],
) -> (Vec<String>, Vec<(u32, u32)>) {
    let module = naga::front::wgsl::parse_str(source).expect("composed shader parses");
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .expect("composed shader validates");
    let mut problems = Vec::new();
    let mut declared = Vec::new();
    for (handle, var) in module.global_variables.iter() {
        let Some(rb) = &var.binding else { continue };
        let name = var.name.as_deref().unwrap_or("?");
        let what = format!(
            "{shader}: @group({}) @binding({}) {name}",
            rb.group, rb.binding
        );
        declared.push((rb.group, rb.binding));
        let Some((_, (_, table))) = sets.iter().find(|(g, _)| *g == rb.group) else {
            problems.push(format!("{what}: no table for group {}", rb.group));
            continue;
        };
        let Some(entry) = table.iter().find(|b| b.binding == rb.binding) else {
            problems.push(format!("{what}: not in the table"));
            continue;
        };
        if entry.name != name {
            problems.push(format!("{what}: the table calls it {:?}", entry.name));
        }
        let ty = descriptor_type(&module, var);
        if ty != Some(entry.ty) {
            problems.push(format!(
                "{what}: is a {ty:?}, the table says {:?}",
                entry.ty
            ));
        }
        for (i, ep) in module.entry_points.iter().enumerate() {
            let stage = stage_flag(ep.stage);
            if !info.get_entry_point(i)[handle].is_empty() && !entry.stages.contains(stage) {
                problems.push(format!(
                    "{what}: used by {} ({stage:?}), the table grants {:?}",
                    ep.name, entry.stages
                ));
            }
        }
    }
    (problems, declared)
}

/// Every problem of every table against every shader that binds it, plus table entries that
/// no shader binding that table declares.
fn all_interface_problems(shaders: &ShaderSets) -> Vec<String> {
    let mut problems = Vec::new();
    // Per table: the bindings its shaders declare at the group they bind it to.
    let mut seen: Vec<(Table, Vec<u32>)> = Vec::new();
    for (name, source, sets) in shaders {
        let (p, declared) = interface_problems(name, source, sets);
        problems.extend(p);
        for &(group, table) in sets {
            let bindings = declared
                .iter()
                .filter(|(g, _)| *g == group)
                .map(|(_, b)| *b);
            match seen.iter_mut().find(|(t, _)| t.0 == table.0) {
                Some((_, v)) => v.extend(bindings),
                None => seen.push((table, bindings.collect())),
            }
        }
    }
    for ((table_name, table), used) in seen {
        for (i, b) in table.iter().enumerate() {
            let what = format!("{table_name} entry {} {:?}", b.binding, b.name);
            if !used.contains(&b.binding) {
                problems.push(format!("{what}: no shader using the table declares it"));
            }
            if table[..i].iter().any(|o| o.binding == b.binding) {
                problems.push(format!("{what}: binding twice"));
            }
        }
    }
    problems
}

#[test]
fn descriptor_tables_match_the_shader_bindings() {
    let problems = all_interface_problems(&shader_sets());
    assert!(problems.is_empty(), "{problems:#?}");
}

/// Negative control: wrong tables are reported, each with the binding it concerns.
#[test]
fn a_wrong_descriptor_table_is_reported() {
    let leak = |v: Vec<Binding>| -> &'static [Binding] { Box::leak(v.into_boxed_slice()) };
    let mutate = |f: &dyn Fn(&mut Vec<Binding>)| {
        let mut t = TERRAIN_SET.to_vec();
        f(&mut t);
        leak(t)
    };
    let cases: Vec<(&str, &'static [Binding])> = vec![
        (
            "the table calls it \"quadtree\"",
            mutate(&|t| t[6].name = "quadtree"),
        ),
        (
            "the table says UNIFORM_BUFFER",
            mutate(&|t| t[6].ty = vk::DescriptorType::UNIFORM_BUFFER),
        ),
        (
            "geo_lattice: not in the table",
            mutate(&|t| {
                t.pop();
            }),
        ),
        (
            "TERRAIN_SET entry 10 \"extra\": no shader",
            mutate(&|t| {
                t.push(Binding::new(
                    10,
                    vk::DescriptorType::SAMPLER,
                    t[0].stages,
                    "extra",
                ))
            }),
        ),
        (
            "height_tex: used by vs_main (VERTEX)",
            mutate(&|t| t[1].stages = vk::ShaderStageFlags::FRAGMENT),
        ),
        ("binding twice", mutate(&|t| t[8].binding = 7)),
    ];
    for (words, table) in cases {
        let shaders: Vec<_> = shader_sets()
            .into_iter()
            .map(|(n, s, sets)| {
                let sets = sets
                    .into_iter()
                    .map(|(g, t)| match t.0 {
                        "TERRAIN_SET" => (g, ("TERRAIN_SET", table)),
                        _ => (g, t),
                    })
                    .collect();
                (n, s, sets)
            })
            .collect();
        let problems = all_interface_problems(&shaders);
        assert!(
            problems.iter().any(|p| p.contains(words)),
            "expected {words:?} among {problems:#?}"
        );
    }
    // A shader whose group has no table at all.
    let (problems, _) = interface_problems("pgm", PGM_WGSL, &[(0, ("TERRAIN_SET", TERRAIN_SET))]);
    assert!(
        problems.iter().any(|p| p.contains("no table for group 1")),
        "{problems:#?}"
    );
}

#[test]
fn tessellation_uniforms_match_the_wgsl_struct() {
    use vkterrain::driver::shaders::TESS_WGSL;
    use vkterrain::lod::tessellation::TessUniforms;
    let rust = [
        ("params", offset_of!(TessUniforms, params)),
        ("grid", offset_of!(TessUniforms, grid)),
        ("flags", offset_of!(TessUniforms, flags)),
    ];
    assert_struct_layout(
        &[("tess", TESS_WGSL)],
        "Tess",
        &rust,
        size_of::<TessUniforms>(),
    );
}

/// The evaluator's uniforms and swim seeds (`src/eval/gpu/layout.rs`) against
/// `shaders/eval_metrics.wgsl`: the views carry the camera's split position for the lattice
/// inverse, the frame the lattice's size.
#[test]
fn eval_structs_match_the_wgsl_structs() {
    use vkterrain::eval::gpu::layout::{EvalFrame, EvalView, Seed};
    let eval = [("eval_metrics", EVAL_METRICS_WGSL)];
    let view = [
        ("right", offset_of!(EvalView, right)),
        ("up", offset_of!(EvalView, up)),
        ("forward", offset_of!(EvalView, forward)),
        ("cell", offset_of!(EvalView, cell)),
        ("offset", offset_of!(EvalView, offset)),
        ("cam_hi", offset_of!(EvalView, cam_hi)),
        ("cam_lo", offset_of!(EvalView, cam_lo)),
    ];
    assert_struct_layout(&eval, "EvalView", &view, size_of::<EvalView>());
    let frame = [
        ("views", offset_of!(EvalFrame, views)),
        ("size", offset_of!(EvalFrame, size)),
        ("data", offset_of!(EvalFrame, data)),
        ("params", offset_of!(EvalFrame, params)),
        ("points", offset_of!(EvalFrame, points)),
        ("grid", offset_of!(EvalFrame, grid)),
        ("lattice", offset_of!(EvalFrame, lattice)),
    ];
    assert_struct_layout(&eval, "EvalFrame", &frame, size_of::<EvalFrame>());
    let seed = [
        ("cell", offset_of!(Seed, cell)),
        ("valid", offset_of!(Seed, valid)),
        ("pad0", offset_of!(Seed, pad0)),
        ("frac", offset_of!(Seed, frac)),
        ("z", offset_of!(Seed, z)),
        ("pad1", offset_of!(Seed, pad1)),
    ];
    assert_struct_layout(&eval, "Seed", &seed, size_of::<Seed>());
}

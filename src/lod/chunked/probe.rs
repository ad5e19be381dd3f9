//! Test support (feature `test-support`): chunked LOD's vertex placement (`chunk_sample`,
//! edge patching through the LOD map) evaluated on the GPU for given chunks and local grid
//! vertices, through the set 0 and set 1 a view slot last drew with: the WGSL the vertex
//! stage calls (`shaders/chunked_probe.wgsl`) or the GLSL port the mesh stage calls
//! (`shaders/glsl/chunked_probe.comp`). Tests compare both with [`super::select::chunk_sample`].

use std::ffi::CStr;
use std::sync::Arc;

use ash::vk;

use crate::driver::Gpu;
use crate::driver::shaders::TerrainVariant;
use crate::error::Result;
use crate::gpu_constants::UDLOD_PROBE_WORKGROUP;
use crate::lod::udlod::levels::Tile;

/// One probed vertex (`ChunkProbe` in `shaders/chunked_probe.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ChunkProbe {
    /// In: chunk x, y, lod, 0.
    pub chunk: [u32; 4],
    /// In: column and row of the vertex in the chunk's grid.
    pub local: [u32; 4],
    /// Out: xy the sample the vertex stands on (before clamping to the data).
    pub sample: [i32; 4],
}

/// Which compiled placement to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Port {
    /// The WGSL of the instanced path's vertex stage.
    Wgsl,
    /// The GLSL port of the mesh path's mesh stage.
    Glsl,
}

impl Port {
    fn shader(self, variant: TerrainVariant) -> (crate::driver::shaders::Spirv, &'static CStr) {
        match self {
            Port::Wgsl => (
                crate::driver::shaders::CHUNKED_PROBE_SPV.variant(variant),
                c"probe_samples",
            ),
            Port::Glsl => (
                crate::driver::shaders::CHUNKED_PROBE_COMP_SPV.variant(variant),
                c"main",
            ),
        }
    }
}

/// `chunk_sample` for each `(chunk, local vertex)` with set 0 `frame` and chunked set 1
/// `chunked` (layout, set) bound, the shader built for `variant` (the terrain's). Waits for the GPU.
pub fn probe(
    gpu: &Arc<Gpu>,
    frame: (vk::DescriptorSetLayout, vk::DescriptorSet),
    chunked: (vk::DescriptorSetLayout, vk::DescriptorSet),
    port: Port,
    variant: TerrainVariant,
    inputs: &[(Tile, [u32; 2])],
) -> Result<Vec<[i32; 2]>> {
    if inputs.is_empty() {
        return Ok(Vec::new());
    }
    let header = [inputs.len() as u32, 0, 0, 0];
    let items: Vec<ChunkProbe> = inputs
        .iter()
        .map(|(t, local)| ChunkProbe {
            chunk: [t.x, t.y, t.lod, 0],
            local: [local[0], local[1], 0, 0],
            ..Default::default()
        })
        .collect();
    let io = [bytemuck::bytes_of(&header), bytemuck::cast_slice(&items)].concat();
    let (spv, entry) = port.shader(variant);
    let out = crate::driver::probe::run(
        gpu,
        spv,
        entry,
        &[frame, chunked],
        &io,
        (inputs.len() as u32).div_ceil(UDLOD_PROBE_WORKGROUP),
    )?;
    let items: Vec<ChunkProbe> = bytemuck::pod_collect_to_vec(&out[size_of_val(&header)..]);
    Ok(items.iter().map(|p| [p.sample[0], p.sample[1]]).collect())
}

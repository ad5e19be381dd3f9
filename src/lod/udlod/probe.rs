//! Test support (feature `test-support`): UDLOD's vertex morph evaluated on the GPU
//! (`morphed_vertex` in `shaders/include/udlod_morph.wgsl`, the function both vertex shaders
//! call) for given tiles and local grid vertices, through the set 0 and set 1 a view slot
//! last drew with (`shaders/udlod_probe.wgsl`). Tests compare the results with
//! [`super::morph::morphed_vertex`].

use std::sync::Arc;

use ash::vk;

use super::levels::Tile;
use crate::driver::Gpu;
use crate::driver::shaders::TerrainVariant;
use crate::error::Result;
use crate::gpu_constants::UDLOD_PROBE_WORKGROUP;

/// One probed vertex as the probe shader reads and writes it (`ProbeVertex` in
/// `shaders/udlod_probe.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ProbeVertex {
    /// In: tile x, y, lod, 0.
    pub tile: [u32; 4],
    /// In: column and row of the vertex in the tile's grid.
    pub local: [u32; 4],
    /// Out: the morphed cell (xy).
    pub cell: [i32; 4],
    /// Out: fraction (xy) and grid position (zw).
    pub frac: [f32; 4],
    /// Out: morph factor (x) and height in metres (y).
    pub values: [f32; 4],
}

/// What the GPU computed for one vertex.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbedVertex {
    pub cell: [i32; 2],
    pub frac: [f32; 2],
    /// `vec2<f32>(cell) + frac`, as the shader passes it on.
    pub grid_pos: [f32; 2],
    pub morph: f32,
    /// `height_at(grid_pos)` (single texture or clipmap, as the frame drew).
    pub height: f32,
}

/// Evaluates the morph for each `(tile, local vertex)` with set 0 `frame` and UDLOD set 1
/// `udlod` (layout, set) bound, the probe built for `variant` (the terrain's). Waits for the GPU.
pub fn probe(
    gpu: &Arc<Gpu>,
    variant: TerrainVariant,
    frame: (vk::DescriptorSetLayout, vk::DescriptorSet),
    udlod: (vk::DescriptorSetLayout, vk::DescriptorSet),
    inputs: &[(Tile, [u32; 2])],
) -> Result<Vec<ProbedVertex>> {
    if inputs.is_empty() {
        return Ok(Vec::new());
    }
    let header = [inputs.len() as u32, 0, 0, 0];
    let items: Vec<ProbeVertex> = inputs
        .iter()
        .map(|(t, local)| ProbeVertex {
            tile: [t.x, t.y, t.lod, 0],
            local: [local[0], local[1], 0, 0],
            ..Default::default()
        })
        .collect();
    let io = [bytemuck::bytes_of(&header), bytemuck::cast_slice(&items)].concat();
    let out = crate::driver::probe::run(
        gpu,
        crate::driver::shaders::UDLOD_PROBE_SPV.variant(variant),
        c"probe_vertices",
        &[frame, udlod],
        &io,
        (inputs.len() as u32).div_ceil(UDLOD_PROBE_WORKGROUP),
    )?;
    let items: Vec<ProbeVertex> = bytemuck::pod_collect_to_vec(&out[size_of_val(&header)..]);
    Ok(items
        .iter()
        .map(|v| ProbedVertex {
            cell: [v.cell[0], v.cell[1]],
            frac: [v.frac[0], v.frac[1]],
            grid_pos: [v.frac[2], v.frac[3]],
            morph: v.values[0],
            height: v.values[1],
        })
        .collect())
}

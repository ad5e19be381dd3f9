//! Test support (feature `test-support`): evaluates the shaders' clipmap lookups on the GPU
//! through a view slot's set 0 and reads the results back (`shaders/clipmap_probe.wgsl`).

use std::sync::Arc;

use ash::vk;

use crate::driver::Gpu;
use crate::driver::shaders::TerrainVariant;
use crate::error::Result;
use crate::gpu_constants::CLIPMAP_PROBE_WORKGROUP;

/// What [`probe`] evaluates at each point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProbeKind {
    /// `[clipmap_height(p), single-texture bilinear texture_height_at(p)]`.
    Heights,
    /// The fragment stage's `clipmap_surface(p)` normal at mip 0: `[normal.x, normal.y]`.
    Normals,
}

/// Tests and tools: evaluates `kind` on the GPU for each point (level-0 sample units),
/// through descriptor set 0 `frame_set` (the state of the frame that set last rendered) and the
/// build of the terrain shaders `variant` (the terrain's).
/// Waits.
pub fn probe(
    gpu: &Arc<Gpu>,
    variant: TerrainVariant,
    frame_layout: vk::DescriptorSetLayout,
    frame_set: vk::DescriptorSet,
    points: &[[f32; 2]],
    kind: ProbeKind,
) -> Result<Vec<[f32; 2]>> {
    if points.is_empty() {
        return Ok(Vec::new());
    }
    // `Probe` in shaders/clipmap_probe.wgsl: a count, then per point (x, y, result, result).
    let header = [points.len() as u32, 0, 0, 0];
    let items: Vec<[f32; 4]> = points.iter().map(|p| [p[0], p[1], 0.0, 0.0]).collect();
    let io = [bytemuck::bytes_of(&header), bytemuck::cast_slice(&items)].concat();
    let out = crate::driver::probe::run(
        gpu,
        crate::driver::shaders::CLIPMAP_PROBE_SPV.variant(variant),
        match kind {
            ProbeKind::Heights => c"probe_main",
            ProbeKind::Normals => c"probe_surface_main",
        },
        &[(frame_layout, frame_set)],
        &io,
        (points.len() as u32).div_ceil(CLIPMAP_PROBE_WORKGROUP),
    )?;
    let items: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&out[size_of_val(&header)..]);
    Ok(items.iter().map(|v| [v[2], v[3]]).collect())
}

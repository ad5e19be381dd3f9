//! Test support (feature `test-support`): evaluates the shaders' clipmap lookups on the GPU
//! through a view slot's set 0 and reads the results back (`shaders/clipmap_probe.wgsl`).

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use crate::driver::Gpu;
use crate::driver::barrier::{Barriers, MemoryAccess};
use crate::driver::descriptors::DescriptorSets;
use crate::driver::memory::Buffer;
use crate::error::{Error, Result};
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
/// through descriptor set 0 `frame_set` (the state of the frame that set last rendered).
/// Waits.
pub fn probe(
    gpu: &Arc<Gpu>,
    frame_layout: vk::DescriptorSetLayout,
    frame_set: vk::DescriptorSet,
    points: &[[f32; 2]],
    kind: ProbeKind,
) -> Result<Vec<[f32; 2]>> {
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let d = &gpu.device;
    let mut io = Buffer::new(
        gpu,
        "clipmap probe",
        16 + points.len() as u64 * 16,
        vk::BufferUsageFlags::STORAGE_BUFFER,
        MemoryLocation::GpuToCpu,
    )?;
    let mut bytes = Vec::with_capacity(16 + points.len() * 16);
    for v in [points.len() as u32, 0, 0, 0] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    for p in points {
        for v in [p[0], p[1], 0.0, 0.0] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    io.write(&bytes)?;
    let probe_set = DescriptorSets::new(
        gpu,
        &[vk::DescriptorType::STORAGE_BUFFER],
        vk::ShaderStageFlags::COMPUTE,
        1,
    )?;
    let set = probe_set.sets[0];
    let info = [vk::DescriptorBufferInfo {
        buffer: io.raw,
        offset: 0,
        range: vk::WHOLE_SIZE,
    }];
    unsafe {
        d.update_descriptor_sets(
            &[vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(0)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .buffer_info(&info)],
            &[],
        )
    };
    let pipeline = crate::driver::pipeline::compute_pipeline(
        gpu,
        crate::driver::shaders::CLIPMAP_PROBE_SPV,
        match kind {
            ProbeKind::Heights => c"probe_main",
            ProbeKind::Normals => c"probe_surface_main",
        },
        &[frame_layout, probe_set.layout],
    )?;
    let groups = (points.len() as u32).div_ceil(CLIPMAP_PROBE_WORKGROUP);
    gpu.one_shot(|cmd| unsafe {
        d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, pipeline.raw);
        d.cmd_bind_descriptor_sets(
            cmd,
            vk::PipelineBindPoint::COMPUTE,
            pipeline.layout,
            0,
            &[frame_set, set],
            &[],
        );
        d.cmd_dispatch(cmd, groups, 1, 1);
        Barriers::new(gpu).memory(cmd, MemoryAccess::ComputeWrite, MemoryAccess::HostRead);
    })?;
    let m = io
        .mapped()
        .ok_or_else(|| Error::invalid("clipmap probe", "buffer not mapped"))?;
    let f = |o: usize| f32::from_le_bytes([m[o], m[o + 1], m[o + 2], m[o + 3]]);
    Ok((0..points.len())
        .map(|i| [f(16 + i * 16 + 8), f(16 + i * 16 + 12)])
        .collect())
}

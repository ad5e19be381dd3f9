//! Test support (feature `test-support`): runs a compute probe entry point (`shaders/*_probe.wgsl`)
//! that reads the sets a renderer drew with and writes into one input/output buffer, bound as
//! the last set ([`PROBE_SET`]), and returns that buffer. Waits for the GPU.

use std::ffi::CStr;
use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::Gpu;
use super::barrier::{Barriers, MemoryAccess};
use super::descriptors::{DescriptorSets, PROBE_SET, Resource};
use super::memory::Buffer;
use super::pipeline::compute_pipeline;
use super::shaders::Spirv;
use crate::error::{Error, Result};

/// Dispatches `groups` workgroups of `entry` in `spv` with `bound` (layout, set) as sets
/// `0..bound.len()` and a buffer holding `io` as the next set; returns the buffer's bytes
/// afterwards.
pub fn run(
    gpu: &Arc<Gpu>,
    spv: Spirv,
    entry: &CStr,
    bound: &[(vk::DescriptorSetLayout, vk::DescriptorSet)],
    io: &[u8],
    groups: u32,
) -> Result<Vec<u8>> {
    let d = &gpu.device;
    let mut buffer = Buffer::new(
        gpu,
        "probe io",
        io.len() as u64,
        vk::BufferUsageFlags::STORAGE_BUFFER,
        MemoryLocation::GpuToCpu,
    )?;
    buffer.write(io)?;
    let probe_set = DescriptorSets::new(gpu, PROBE_SET, 1)?;
    probe_set.write(0, &[("probe", Resource::Buffer(buffer.raw))])?;
    let mut layouts: Vec<_> = bound.iter().map(|(l, _)| *l).collect();
    let mut sets: Vec<_> = bound.iter().map(|(_, s)| *s).collect();
    layouts.push(probe_set.layout);
    sets.push(probe_set.sets[0]);
    let pipeline = compute_pipeline(gpu, spv, entry, &layouts)?;
    gpu.one_shot(|cmd| unsafe {
        pipeline.bind(cmd, vk::PipelineBindPoint::COMPUTE, &sets);
        d.cmd_dispatch(cmd, groups, 1, 1);
        Barriers::new(gpu).memory(cmd, MemoryAccess::ComputeWrite, MemoryAccess::HostRead);
    })?;
    buffer
        .mapped()
        .and_then(|m| m.get(..io.len()))
        .map(<[u8]>::to_vec)
        .ok_or_else(|| Error::invalid("probe", "io buffer not mapped"))
}

//! Brute force: the full-resolution mesh, every height sample a vertex. The correctness
//! reference for all LOD methods.
//!
//! One index buffer holds a grid of `BRUTE_CHUNK_QUADS`^2 quads (16-bit indices); it is drawn
//! once per chunk of the data with instancing, and the vertex shader turns (instance, vertex)
//! into a sample. No vertex buffers, memory independent of the data size.

use std::sync::Arc;

use ash::vk;

use super::{LodMethod, MethodContext};
use crate::driver::Gpu;
use crate::driver::memory::Buffer;
use crate::driver::pipeline::{Pipeline, TerrainPipelineDesc, terrain_pipeline};
use crate::error::Result;
use crate::frame::ViewState;
use crate::gpu_constants::BRUTE_CHUNK_QUADS;
use crate::slots::ViewSlot;

pub struct BruteForce {
    gpu: Arc<Gpu>,
    pipeline: Pipeline,
    indices: Buffer,
    index_count: u32,
    instances: u32,
    triangles: u64,
}

/// Counter-clockwise (seen from above) triangle list over a `quads` x `quads` vertex grid.
pub fn grid_indices(quads: u32) -> Vec<u16> {
    let row = quads + 1;
    assert!(
        row * row <= u16::MAX as u32 + 1,
        "grid too large for 16-bit indices"
    );
    let mut out = Vec::with_capacity((quads * quads * 6) as usize);
    for r in 0..quads {
        for c in 0..quads {
            let (a, b, cc, d) = (
                r * row + c,
                r * row + c + 1,
                (r + 1) * row + c,
                (r + 1) * row + c + 1,
            );
            out.extend([a, b, cc, b, d, cc].map(|i| i as u16));
        }
    }
    out
}

impl BruteForce {
    pub fn new(ctx: &MethodContext<'_>) -> Result<Self> {
        let gpu = ctx.gpu;
        let indices_data = grid_indices(BRUTE_CHUNK_QUADS);
        let bytes: &[u8] = bytemuck::cast_slice(&indices_data);
        let indices = Buffer::with_data(
            gpu,
            "brute grid indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            bytes,
        )?;
        let pipeline = terrain_pipeline(
            gpu,
            &ctx.formats,
            &TerrainPipelineDesc::triangles(
                crate::driver::shaders::BRUTE_SPV.variant(ctx.terrain.variant),
                &[ctx.terrain.descriptors.layout],
            ),
        )?;
        let info = &ctx.terrain.info;
        let chunks = |n: u32| (n - 1).div_ceil(BRUTE_CHUNK_QUADS);
        Ok(BruteForce {
            gpu: gpu.clone(),
            pipeline,
            indices,
            index_count: indices_data.len() as u32,
            instances: chunks(info.width) * chunks(info.height),
            triangles: 2 * (info.width as u64 - 1) * (info.height as u64 - 1),
        })
    }
}

impl LodMethod for BruteForce {
    fn name(&self) -> &'static str {
        "brute"
    }

    fn update(&mut self, _slot: ViewSlot, _view: &ViewState) -> Result<()> {
        Ok(())
    }

    fn record_draw(
        &mut self,
        cmd: vk::CommandBuffer,
        _slot: ViewSlot,
        frame_set: vk::DescriptorSet,
    ) {
        let d = &self.gpu.device;
        unsafe {
            self.pipeline
                .bind(cmd, vk::PipelineBindPoint::GRAPHICS, &[frame_set]);
            d.cmd_bind_index_buffer(cmd, self.indices.raw, 0, vk::IndexType::UINT16);
            d.cmd_draw_indexed(cmd, self.index_count, self.instances, 0, 0, 0);
        }
    }

    fn triangles(&self, _slot: ViewSlot) -> u64 {
        self.triangles
    }
}

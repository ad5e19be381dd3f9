//! Chunked LOD's per-frame work: uniforms on the host, the selection passes (naive walk or
//! CBT step) and the LOD map in the prepass, the instanced indirect draw.

use ash::vk;

use super::{
    ChunkState, Chunked, ChunkedUniforms, DRAW_OFFSET, MAP_OFFSET, MESH_OFFSET, Traversal,
};
use crate::driver::barrier::{Barriers, MemoryAccess};
use crate::error::Result;
use crate::frame::ViewState;
use crate::gpu_constants::UDLOD_WORKGROUP;
use crate::lod::LodMethod;
use crate::slots::ViewSlot;

/// Bytes between consecutive indexed indirect draws (one is drawn; Vulkan wants the stride).
const DRAW_STRIDE: u32 = size_of::<[u32; 5]>() as u32;

impl Chunked {
    fn uniforms(&self, view: &ViewState) -> ChunkedUniforms {
        let p = self.params(view);
        let mut u = ChunkedUniforms {
            frustum: p.frustum,
            viewer: [p.viewer[0], p.viewer[1], p.viewer[2], 0.0],
            metric: [p.stretch[0], p.stretch[1], 0.0, 0.0],
            params: [
                p.error_px,
                p.focal_px,
                if p.cull { 1.0 } else { 0.0 },
                if self.settings.stitch { 1.0 } else { 0.0 },
            ],
            ..Default::default()
        };
        for lod in 0..self.levels.levels() as usize {
            let (nx, ny) = self.levels.tiles_per_side[lod];
            u.levels[lod] = [self.levels.level_offsets[lod], nx, ny, 0];
        }
        let d = self.depths;
        u.sizes = [self.settings.chunk_quads, d.root, d.start, d.finest];
        let (nx, ny) = self.levels.tiles_per_side[0];
        let cap = self.settings.max_chunks;
        u.lists = [cap, cap, nx, ny];
        u.cbt = [self.cbt.depth, self.index_count, 2 * (d.root - d.start), 0];
        u
    }

    /// One compute step: bind, dispatch (`Some`: direct, `None`: indirect from the state at
    /// `offset`), then make its writes visible to the next step and to indirect reads.
    fn step(
        &self,
        cmd: vk::CommandBuffer,
        pipeline: vk::Pipeline,
        size: Option<[u32; 2]>,
        state: vk::Buffer,
    ) {
        let d = &self.gpu.device;
        let b = Barriers::new(&self.gpu);
        unsafe {
            d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, pipeline);
            match size {
                Some([x, y]) => d.cmd_dispatch(cmd, x, y, 1),
                None => d.cmd_dispatch_indirect(cmd, state, 0),
            }
            b.memory(cmd, MemoryAccess::ComputeWrite, MemoryAccess::IndirectRead);
            b.memory(
                cmd,
                MemoryAccess::ComputeWrite,
                MemoryAccess::ComputeReadWrite,
            );
        }
    }

    fn record_naive(&self, cmd: vk::CommandBuffer, state: vk::Buffer) {
        let p = &self.pipelines;
        for _ in self.depths.finest..=self.depths.start {
            self.step(cmd, p.prepare.raw, Some([1, 1]), state);
            self.step(cmd, p.refine.raw, None, state);
        }
    }

    /// One CBT frame: split/merge step on last frame's sums, the sum reduction, the list.
    fn record_cbt(&self, cmd: vk::CommandBuffer, state: vk::Buffer) {
        let p = &self.pipelines;
        let depth = self.cbt.depth;
        self.step(cmd, p.cbt_begin.raw, Some([1, 1]), state);
        self.step(cmd, p.cbt_update.raw, None, state);
        let words = ((1u32 << depth) / 32).max(1);
        self.step(
            cmd,
            p.cbt_reduce_bits.raw,
            Some([words.div_ceil(UDLOD_WORKGROUP), 1]),
            state,
        );
        // Levels D-6 .. 6, one pass each; the level is read back from the dispatch size.
        for level in (6..=depth.saturating_sub(6)).rev() {
            let groups = 1u32 << (level - 6);
            let x = groups.min(1 << 15);
            self.step(cmd, p.cbt_reduce.raw, Some([x, groups / x]), state);
        }
        self.step(cmd, p.cbt_reduce_top.raw, Some([1, 1]), state);
        self.step(cmd, p.cbt_begin.raw, Some([1, 1]), state);
        self.step(cmd, p.cbt_list.raw, None, state);
    }
}

impl LodMethod for Chunked {
    fn name(&self) -> &'static str {
        "chunked"
    }

    fn update(&mut self, slot: ViewSlot, view: &ViewState) -> Result<()> {
        let u = self.uniforms(view);
        self.slots[slot.index()]
            .uniforms
            .write(bytemuck::bytes_of(&u))
    }

    fn record_prepass(
        &mut self,
        cmd: vk::CommandBuffer,
        slot: ViewSlot,
        frame_set: vk::DescriptorSet,
    ) {
        let d = &self.gpu.device;
        let b = Barriers::new(&self.gpu);
        let s = &self.slots[slot.index()];
        let p = &self.pipelines;
        unsafe {
            // The buffers were last used by this slot's previous frame (same queue).
            b.memory(
                cmd,
                MemoryAccess::PreviousFrame,
                MemoryAccess::TransferWrite,
            );
            d.cmd_fill_buffer(cmd, s.state.raw, 0, vk::WHOLE_SIZE, 0);
            d.cmd_fill_buffer(cmd, s.lod_map.raw, 0, vk::WHOLE_SIZE, 0);
            b.memory(
                cmd,
                MemoryAccess::TransferWrite,
                MemoryAccess::ComputeReadWrite,
            );
            b.memory(
                cmd,
                MemoryAccess::PreviousFrame,
                MemoryAccess::ComputeReadWrite,
            );
            d.cmd_bind_descriptor_sets(
                cmd,
                vk::PipelineBindPoint::COMPUTE,
                p.refine.layout,
                0,
                &[frame_set, s.set],
                &[],
            );
        }
        match self.settings.traversal {
            Traversal::Naive => self.record_naive(cmd, s.state.raw),
            Traversal::Cbt => self.record_cbt(cmd, s.state.raw),
        }
        self.step(cmd, p.finish.raw, Some([1, 1]), s.state.raw);
        unsafe {
            d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, p.lod_map.raw);
            d.cmd_dispatch_indirect(cmd, s.state.raw, MAP_OFFSET);
            let draw_read = match self.mesh {
                None => MemoryAccess::VertexShaderRead,
                Some(_) => MemoryAccess::MeshShaderRead,
            };
            b.memory(cmd, MemoryAccess::ComputeWrite, draw_read);
            b.copy_for_host(
                cmd,
                MemoryAccess::ComputeWrite,
                (s.state.raw, 0),
                s.counters.raw,
                size_of::<ChunkState>() as u64,
            );
        }
    }

    fn record_draw(
        &mut self,
        cmd: vk::CommandBuffer,
        slot: ViewSlot,
        frame_set: vk::DescriptorSet,
    ) {
        let d = &self.gpu.device;
        let s = &self.slots[slot.index()];
        let draw = &self.pipelines.draw;
        unsafe {
            draw.bind(cmd, vk::PipelineBindPoint::GRAPHICS, &[frame_set, s.set]);
            match &self.mesh {
                None => {
                    d.cmd_bind_index_buffer(cmd, self.indices.raw, 0, vk::IndexType::UINT16);
                    d.cmd_draw_indexed_indirect(cmd, s.state.raw, DRAW_OFFSET, 1, DRAW_STRIDE);
                }
                Some(mesh) => {
                    let stride = size_of::<vk::DrawMeshTasksIndirectCommandEXT>() as u32;
                    mesh.cmd_draw_mesh_tasks_indirect(cmd, s.state.raw, MESH_OFFSET, 1, stride);
                }
            }
        }
    }

    fn triangles(&self, slot: ViewSlot) -> u64 {
        let c = self.read_counters(slot);
        c.draw[1] as u64 * 2 * (self.settings.chunk_quads as u64).pow(2)
    }

    fn budget_overflow(&self, slot: ViewSlot) -> u64 {
        self.read_counters(slot).overflow as u64
    }

    fn counters(&self, slot: ViewSlot) -> Vec<(&'static str, u64)> {
        let c = self.read_counters(slot);
        vec![
            ("chunks", c.draw[1] as u64),
            ("overflow", c.overflow as u64),
            ("culled", c.culled as u64),
            ("splits", c.splits as u64),
            ("merges", c.merges as u64),
        ]
    }

    #[cfg(feature = "test-support")]
    fn debug_tiles(&self, slot: ViewSlot) -> Result<Option<Vec<[u32; 3]>>> {
        self.debug_chunks(slot).map(Some)
    }

    #[cfg(feature = "test-support")]
    fn probe_set(&self, slot: ViewSlot) -> Option<(vk::DescriptorSetLayout, vk::DescriptorSet)> {
        Some((self.sets.layout, self.slots[slot.index()].set))
    }
}

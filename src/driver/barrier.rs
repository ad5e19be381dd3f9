//! Pipeline barriers described once and emitted through synchronization2 where the device has
//! it, or through the classic `vkCmdPipelineBarrier` otherwise.

use ash::vk;

use super::Gpu;

/// The states an image moves between, each with its layout, stages and accesses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageAccess {
    Undefined,
    /// Contents discarded (old layout UNDEFINED), but after a copy that read the image: the
    /// transition waits for that copy (write-after-read).
    TransferSrcDiscard,
    TransferDst,
    TransferSrc,
    SampledAnyShader,
    ColorAttachment,
    DepthAttachment,
}

impl ImageAccess {
    fn sync2(self) -> (vk::PipelineStageFlags2, vk::AccessFlags2, vk::ImageLayout) {
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        match self {
            ImageAccess::Undefined => (S::NONE, A::NONE, L::UNDEFINED),
            ImageAccess::TransferSrcDiscard => (S::COPY, A::NONE, L::UNDEFINED),
            ImageAccess::TransferDst => (S::COPY, A::TRANSFER_WRITE, L::TRANSFER_DST_OPTIMAL),
            ImageAccess::TransferSrc => (S::COPY, A::TRANSFER_READ, L::TRANSFER_SRC_OPTIMAL),
            ImageAccess::SampledAnyShader => (
                S::VERTEX_SHADER | S::FRAGMENT_SHADER | S::COMPUTE_SHADER,
                A::SHADER_SAMPLED_READ,
                L::SHADER_READ_ONLY_OPTIMAL,
            ),
            ImageAccess::ColorAttachment => (
                S::COLOR_ATTACHMENT_OUTPUT,
                A::COLOR_ATTACHMENT_WRITE | A::COLOR_ATTACHMENT_READ,
                L::COLOR_ATTACHMENT_OPTIMAL,
            ),
            ImageAccess::DepthAttachment => (
                S::EARLY_FRAGMENT_TESTS | S::LATE_FRAGMENT_TESTS,
                A::DEPTH_STENCIL_ATTACHMENT_WRITE | A::DEPTH_STENCIL_ATTACHMENT_READ,
                L::DEPTH_ATTACHMENT_OPTIMAL,
            ),
        }
    }

    fn legacy(self) -> (vk::PipelineStageFlags, vk::AccessFlags, vk::ImageLayout) {
        use vk::{AccessFlags as A, ImageLayout as L, PipelineStageFlags as S};
        match self {
            ImageAccess::Undefined => (S::TOP_OF_PIPE, A::empty(), L::UNDEFINED),
            ImageAccess::TransferSrcDiscard => (S::TRANSFER, A::empty(), L::UNDEFINED),
            ImageAccess::TransferDst => (S::TRANSFER, A::TRANSFER_WRITE, L::TRANSFER_DST_OPTIMAL),
            ImageAccess::TransferSrc => (S::TRANSFER, A::TRANSFER_READ, L::TRANSFER_SRC_OPTIMAL),
            ImageAccess::SampledAnyShader => (
                S::VERTEX_SHADER | S::FRAGMENT_SHADER | S::COMPUTE_SHADER,
                A::SHADER_READ,
                L::SHADER_READ_ONLY_OPTIMAL,
            ),
            ImageAccess::ColorAttachment => (
                S::COLOR_ATTACHMENT_OUTPUT,
                A::COLOR_ATTACHMENT_WRITE | A::COLOR_ATTACHMENT_READ,
                L::COLOR_ATTACHMENT_OPTIMAL,
            ),
            ImageAccess::DepthAttachment => (
                S::EARLY_FRAGMENT_TESTS | S::LATE_FRAGMENT_TESTS,
                A::DEPTH_STENCIL_ATTACHMENT_WRITE | A::DEPTH_STENCIL_ATTACHMENT_READ,
                // DEPTH_ATTACHMENT_OPTIMAL is Vulkan 1.2 core (separate depth/stencil layouts).
                L::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
            ),
        }
    }
}

/// Global memory dependencies between stages (buffers: compute -> indirect, copy -> host, ...).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MemoryAccess {
    ComputeWrite,
    ComputeRead,
    /// Storage reads, writes and atomics of a compute dispatch.
    ComputeReadWrite,
    TransferRead,
    /// Everything an earlier frame in this queue may still do with a buffer being reused.
    PreviousFrame,
    IndirectRead,
    VertexShaderRead,
    /// Storage reads of task and mesh stages (only with `VK_EXT_mesh_shader` enabled).
    MeshShaderRead,
    TransferWrite,
    HostRead,
    HostWrite,
}

impl MemoryAccess {
    fn sync2(self) -> (vk::PipelineStageFlags2, vk::AccessFlags2) {
        use vk::{AccessFlags2 as A, PipelineStageFlags2 as S};
        match self {
            MemoryAccess::ComputeWrite => (S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE),
            MemoryAccess::ComputeRead => (S::COMPUTE_SHADER, A::SHADER_STORAGE_READ),
            MemoryAccess::ComputeReadWrite => (
                S::COMPUTE_SHADER,
                A::SHADER_STORAGE_READ | A::SHADER_STORAGE_WRITE,
            ),
            MemoryAccess::TransferRead => (S::COPY, A::TRANSFER_READ),
            MemoryAccess::PreviousFrame => (S::ALL_COMMANDS, A::MEMORY_READ | A::MEMORY_WRITE),
            MemoryAccess::IndirectRead => (S::DRAW_INDIRECT, A::INDIRECT_COMMAND_READ),
            MemoryAccess::VertexShaderRead => (S::VERTEX_SHADER, A::SHADER_STORAGE_READ),
            MemoryAccess::MeshShaderRead => (
                S::TASK_SHADER_EXT | S::MESH_SHADER_EXT,
                A::SHADER_STORAGE_READ,
            ),
            MemoryAccess::TransferWrite => (S::COPY, A::TRANSFER_WRITE),
            MemoryAccess::HostRead => (S::HOST, A::HOST_READ),
            MemoryAccess::HostWrite => (S::HOST, A::HOST_WRITE),
        }
    }

    fn legacy(self) -> (vk::PipelineStageFlags, vk::AccessFlags) {
        use vk::{AccessFlags as A, PipelineStageFlags as S};
        match self {
            MemoryAccess::ComputeWrite => (S::COMPUTE_SHADER, A::SHADER_WRITE),
            MemoryAccess::ComputeRead => (S::COMPUTE_SHADER, A::SHADER_READ),
            MemoryAccess::ComputeReadWrite => (S::COMPUTE_SHADER, A::SHADER_READ | A::SHADER_WRITE),
            MemoryAccess::TransferRead => (S::TRANSFER, A::TRANSFER_READ),
            MemoryAccess::PreviousFrame => (S::ALL_COMMANDS, A::MEMORY_READ | A::MEMORY_WRITE),
            MemoryAccess::IndirectRead => (S::DRAW_INDIRECT, A::INDIRECT_COMMAND_READ),
            MemoryAccess::VertexShaderRead => (S::VERTEX_SHADER, A::SHADER_READ),
            MemoryAccess::MeshShaderRead => {
                (S::TASK_SHADER_EXT | S::MESH_SHADER_EXT, A::SHADER_READ)
            }
            MemoryAccess::TransferWrite => (S::TRANSFER, A::TRANSFER_WRITE),
            MemoryAccess::HostRead => (S::HOST, A::HOST_READ),
            MemoryAccess::HostWrite => (S::HOST, A::HOST_WRITE),
        }
    }
}

pub fn color_range() -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: vk::REMAINING_MIP_LEVELS,
        base_array_layer: 0,
        layer_count: vk::REMAINING_ARRAY_LAYERS,
    }
}

pub fn depth_range() -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::DEPTH,
        ..color_range()
    }
}

/// Records barriers with whichever API the device uses.
pub struct Barriers<'a> {
    gpu: &'a Gpu,
}

impl<'a> Barriers<'a> {
    pub fn new(gpu: &'a Gpu) -> Self {
        Barriers { gpu }
    }

    /// Layout transition + dependency for one image.
    pub fn image(
        &self,
        cmd: vk::CommandBuffer,
        image: vk::Image,
        range: vk::ImageSubresourceRange,
        from: ImageAccess,
        to: ImageAccess,
    ) {
        let d = &self.gpu.device;
        if self.gpu.modern {
            let (src_stage, src_access, old) = from.sync2();
            let (dst_stage, dst_access, new) = to.sync2();
            let barrier = vk::ImageMemoryBarrier2::default()
                .src_stage_mask(src_stage)
                .src_access_mask(src_access)
                .dst_stage_mask(dst_stage)
                .dst_access_mask(dst_access)
                .old_layout(old)
                .new_layout(new)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image)
                .subresource_range(range);
            let barriers = [barrier];
            unsafe {
                d.cmd_pipeline_barrier2(
                    cmd,
                    &vk::DependencyInfo::default().image_memory_barriers(&barriers),
                )
            };
        } else {
            let (src_stage, src_access, old) = from.legacy();
            let (dst_stage, dst_access, new) = to.legacy();
            let barrier = vk::ImageMemoryBarrier::default()
                .src_access_mask(src_access)
                .dst_access_mask(dst_access)
                .old_layout(old)
                .new_layout(new)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image)
                .subresource_range(range);
            unsafe {
                d.cmd_pipeline_barrier(
                    cmd,
                    src_stage,
                    dst_stage,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[barrier],
                )
            };
        }
    }

    /// Copies `size` bytes from `src` (buffer, byte offset) to the start of `dst` for the host
    /// to read: the copy waits for `after` (the last access to `src`), and the host read for
    /// the copy (it still waits for the submission's fence).
    pub fn copy_for_host(
        &self,
        cmd: vk::CommandBuffer,
        after: MemoryAccess,
        src: (vk::Buffer, u64),
        dst: vk::Buffer,
        size: u64,
    ) {
        self.memory(cmd, after, MemoryAccess::TransferRead);
        let region = vk::BufferCopy {
            src_offset: src.1,
            dst_offset: 0,
            size,
        };
        unsafe { self.gpu.device.cmd_copy_buffer(cmd, src.0, dst, &[region]) };
        self.memory(cmd, MemoryAccess::TransferWrite, MemoryAccess::HostRead);
    }

    /// A global memory dependency (all buffers).
    pub fn memory(&self, cmd: vk::CommandBuffer, from: MemoryAccess, to: MemoryAccess) {
        let d = &self.gpu.device;
        if self.gpu.modern {
            let (src_stage, src_access) = from.sync2();
            let (dst_stage, dst_access) = to.sync2();
            let barriers = [vk::MemoryBarrier2::default()
                .src_stage_mask(src_stage)
                .src_access_mask(src_access)
                .dst_stage_mask(dst_stage)
                .dst_access_mask(dst_access)];
            unsafe {
                d.cmd_pipeline_barrier2(
                    cmd,
                    &vk::DependencyInfo::default().memory_barriers(&barriers),
                )
            };
        } else {
            let (src_stage, src_access) = from.legacy();
            let (dst_stage, dst_access) = to.legacy();
            let barrier = vk::MemoryBarrier::default()
                .src_access_mask(src_access)
                .dst_access_mask(dst_access);
            unsafe {
                d.cmd_pipeline_barrier(
                    cmd,
                    src_stage,
                    dst_stage,
                    vk::DependencyFlags::empty(),
                    &[barrier],
                    &[],
                    &[],
                )
            };
        }
    }
}

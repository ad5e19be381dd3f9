//! What one frame slot owns: a command buffer (and its pool), the targets, the readback
//! buffers and timestamp queries, and the frame it holds until that frame is delivered.

use std::sync::Arc;

use ash::vk;

use super::delivery::{Readback, Timestamps};
use super::targets::{Targets, TerrainPass};
use crate::driver::Gpu;
use crate::error::{Result, VkResultExt};
use crate::readback::DirectTarget;
use crate::scene::Camera;
use crate::slots::FrameSlot;

/// A submitted frame waiting for delivery.
pub(super) struct Pending {
    pub index: u64,
    pub camera: Camera,
    pub cpu_record_ms: f64,
    /// Where the colour went when the sink asked for zero-copy ([`crate::readback::FrameSink::direct_target`]).
    pub direct: Option<DirectTarget>,
}

pub(super) struct FrameResources {
    gpu: Arc<Gpu>,
    pool: vk::CommandPool,
    pub cmd: vk::CommandBuffer,
    pub targets: Targets,
    pub readback: Readback,
    pub timestamps: Timestamps,
    pub pending: Option<Pending>,
}

impl FrameResources {
    pub fn new(
        gpu: &Arc<Gpu>,
        pass: &TerrainPass,
        extent: vk::Extent2D,
        readback_depth: bool,
        slot: FrameSlot,
    ) -> Result<Self> {
        let label = slot.index().to_string();
        let targets = Targets::new(gpu, pass, extent, &label)?;
        let readback = Readback::new(gpu, extent, readback_depth, &label)?;
        let timestamps = Timestamps::new(gpu)?;
        let d = &gpu.device;
        let pool = unsafe {
            d.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(gpu.queue_family)
                    .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                None,
            )
        }
        .vk("vkCreateCommandPool")?;
        let cmd = unsafe {
            d.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .command_buffer_count(1),
            )
        }
        .vk("vkAllocateCommandBuffers")
        .inspect_err(|_| unsafe { d.destroy_command_pool(pool, None) })?[0];
        Ok(FrameResources {
            gpu: gpu.clone(),
            pool,
            cmd,
            targets,
            readback,
            timestamps,
            pending: None,
        })
    }

    /// Resets and begins the command buffer (the slot's previous frame is complete) and
    /// writes the first timestamp.
    pub fn begin(&self) -> Result<vk::CommandBuffer> {
        let d = &self.gpu.device;
        unsafe {
            d.reset_command_pool(self.pool, vk::CommandPoolResetFlags::empty())
                .vk("vkResetCommandPool")?;
            d.begin_command_buffer(
                self.cmd,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )
            .vk("vkBeginCommandBuffer")?;
        }
        self.timestamps.begin(self.cmd);
        Ok(self.cmd)
    }

    pub fn end(&self) -> Result<()> {
        unsafe { self.gpu.device.end_command_buffer(self.cmd) }.vk("vkEndCommandBuffer")
    }
}

impl Drop for FrameResources {
    fn drop(&mut self) {
        unsafe { self.gpu.device.destroy_command_pool(self.pool, None) };
    }
}

//! How a finished frame leaves the GPU: the readback copies recorded at the end of its command
//! buffer, the timestamps around its passes, and the borrowed [`crate::readback::FrameView`] the sink gets.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::targets::Targets;
use crate::driver::Gpu;
use crate::driver::barrier::{Barriers, MemoryAccess};
use crate::driver::memory::Buffer;
use crate::error::{Error, Result, VkResultExt};

/// Where the readback buffers live.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum ReadbackPath {
    /// Device-local *and* host-visible memory (unified memory: Jetson, lavapipe): the copy
    /// lands where the host reads it, no staging and no bus transfer.
    Unified,
    /// Host-visible system memory written by the GPU over the bus (discrete GPUs).
    HostStaging,
}

/// The host-visible copies of one frame slot's targets.
pub struct Readback {
    color: Buffer,
    depth: Option<Buffer>,
}

impl Readback {
    /// Buffers for `extent` RGBA8 pixels and, with `with_depth`, as many f32 depths.
    pub fn new(
        gpu: &Arc<Gpu>,
        extent: vk::Extent2D,
        with_depth: bool,
        label: &str,
    ) -> Result<Self> {
        let bytes = extent.width as u64 * extent.height as u64 * 4;
        // GpuToCpu picks host-visible memory, preferring cached; on unified-memory devices the
        // only such type is also device-local, so the copy needs no staging there.
        let buffer = |what: &str| {
            Buffer::new(
                gpu,
                &format!("readback {what} {label}"),
                bytes,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
            )
        };
        Ok(Readback {
            color: buffer("color")?,
            depth: with_depth.then(|| buffer("depth")).transpose()?,
        })
    }

    pub fn path(&self) -> ReadbackPath {
        let unified = vk::MemoryPropertyFlags::DEVICE_LOCAL | vk::MemoryPropertyFlags::HOST_VISIBLE;
        if self.color.memory_properties().contains(unified) {
            ReadbackPath::Unified
        } else {
            ReadbackPath::HostStaging
        }
    }

    /// Records the copies of `targets` (transfer sources after the pass) and makes them
    /// visible to the host; the colour goes to `color_dst` (a sink's zero-copy target) when
    /// given, else to this readback's buffer.
    pub fn record(
        &self,
        gpu: &Gpu,
        cmd: vk::CommandBuffer,
        targets: &Targets,
        color_dst: Option<vk::Buffer>,
    ) {
        let copy = |aspect| {
            [vk::BufferImageCopy::default()
                .image_subresource(vk::ImageSubresourceLayers {
                    aspect_mask: aspect,
                    mip_level: 0,
                    base_array_layer: 0,
                    layer_count: 1,
                })
                .image_extent(vk::Extent3D {
                    width: targets.extent.width,
                    height: targets.extent.height,
                    depth: 1,
                })]
        };
        let layout = vk::ImageLayout::TRANSFER_SRC_OPTIMAL;
        let d = &gpu.device;
        unsafe {
            d.cmd_copy_image_to_buffer(
                cmd,
                targets.color.raw,
                layout,
                color_dst.unwrap_or(self.color.raw),
                &copy(vk::ImageAspectFlags::COLOR),
            );
            if let Some(depth) = &self.depth {
                d.cmd_copy_image_to_buffer(
                    cmd,
                    targets.depth.raw,
                    layout,
                    depth.raw,
                    &copy(vk::ImageAspectFlags::DEPTH),
                );
            }
        }
        Barriers::new(gpu).memory(cmd, MemoryAccess::TransferWrite, MemoryAccess::HostRead);
    }

    /// The pixels (and depths) of the last completed frame of this slot.
    pub fn frame(&self) -> Result<(&[u8], Option<&[f32]>)> {
        let rgba = self
            .color
            .mapped()
            .ok_or_else(|| Error::invalid("readback", "buffer not mapped"))?;
        let depth = match &self.depth {
            Some(b) => {
                let bytes = b
                    .mapped()
                    .ok_or_else(|| Error::invalid("readback", "depth buffer not mapped"))?;
                Some(bytemuck::try_cast_slice(bytes).map_err(|e| {
                    Error::invalid("readback", format!("depth buffer is not f32s: {e}"))
                })?)
            }
            None => None,
        };
        Ok((rgba, depth))
    }
}

/// The points of a frame's command buffer that are timestamped, in order.
#[derive(Clone, Copy, Debug)]
pub enum Stamp {
    Start = 0,
    AfterPrepass = 1,
    AfterTerrain = 2,
    AfterReadback = 3,
}

const STAMPS: u32 = 4;

/// GPU times of one frame's passes, milliseconds (0 where the queue has no timestamps).
#[derive(Clone, Copy, Debug, Default)]
pub struct PassTimes {
    pub prepass_ms: f64,
    pub terrain_ms: f64,
    pub readback_ms: f64,
}

/// The timestamp queries of one frame slot.
pub struct Timestamps {
    gpu: Arc<Gpu>,
    pool: vk::QueryPool,
    /// The queue family writes timestamps.
    valid: bool,
}

impl Timestamps {
    pub fn new(gpu: &Arc<Gpu>) -> Result<Self> {
        let pool = unsafe {
            gpu.device.create_query_pool(
                &vk::QueryPoolCreateInfo::default()
                    .query_type(vk::QueryType::TIMESTAMP)
                    .query_count(STAMPS),
                None,
            )
        }
        .vk("vkCreateQueryPool")?;
        Ok(Timestamps {
            gpu: gpu.clone(),
            pool,
            valid: gpu.info.queue_families[gpu.queue_family as usize].timestamp_valid_bits > 0,
        })
    }

    /// Resets the queries and writes [`Stamp::Start`] (first commands of the frame).
    pub fn begin(&self, cmd: vk::CommandBuffer) {
        unsafe {
            self.gpu
                .device
                .cmd_reset_query_pool(cmd, self.pool, 0, STAMPS)
        };
        self.write(cmd, Stamp::Start);
    }

    pub fn write(&self, cmd: vk::CommandBuffer, stamp: Stamp) {
        let stage = match stamp {
            Stamp::Start => vk::PipelineStageFlags::TOP_OF_PIPE,
            Stamp::AfterPrepass => vk::PipelineStageFlags::COMPUTE_SHADER,
            Stamp::AfterTerrain | Stamp::AfterReadback => vk::PipelineStageFlags::BOTTOM_OF_PIPE,
        };
        unsafe {
            self.gpu
                .device
                .cmd_write_timestamp(cmd, stage, self.pool, stamp as u32)
        };
    }

    /// The pass times of the slot's last completed frame.
    pub fn read(&self) -> Result<PassTimes> {
        if !self.valid {
            return Ok(PassTimes::default());
        }
        let mut ts = [0u64; STAMPS as usize];
        unsafe {
            self.gpu.device.get_query_pool_results(
                self.pool,
                0,
                &mut ts,
                vk::QueryResultFlags::TYPE_64,
            )
        }
        .vk("vkGetQueryPoolResults")?;
        let period = self.gpu.info.limits.timestamp_period as f64 * 1e-6;
        let ms = |a: Stamp, b: Stamp| ts[b as usize].saturating_sub(ts[a as usize]) as f64 * period;
        Ok(PassTimes {
            prepass_ms: ms(Stamp::Start, Stamp::AfterPrepass),
            terrain_ms: ms(Stamp::AfterPrepass, Stamp::AfterTerrain),
            readback_ms: ms(Stamp::AfterTerrain, Stamp::AfterReadback),
        })
    }
}

impl Drop for Timestamps {
    fn drop(&mut self) {
        unsafe { self.gpu.device.destroy_query_pool(self.pool, None) };
    }
}

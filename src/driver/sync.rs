//! The timeline semaphore that orders GPU work against the host.

use std::sync::Arc;
use std::time::Duration;

use ash::vk;

use super::Gpu;
use crate::error::{Error, Result, VkResultExt};

/// A timeline semaphore: frame `k` signals value `k + 1` when its GPU work is complete.
pub struct Timeline {
    gpu: Arc<Gpu>,
    pub raw: vk::Semaphore,
}

impl Timeline {
    pub fn new(gpu: &Arc<Gpu>) -> Result<Self> {
        let mut kind = vk::SemaphoreTypeCreateInfo::default()
            .semaphore_type(vk::SemaphoreType::TIMELINE)
            .initial_value(0);
        let raw = unsafe {
            gpu.device.create_semaphore(
                &vk::SemaphoreCreateInfo::default().push_next(&mut kind),
                None,
            )
        }
        .vk("vkCreateSemaphore")?;
        Ok(Timeline {
            gpu: gpu.clone(),
            raw,
        })
    }

    /// The value the GPU has reached.
    pub fn value(&self) -> Result<u64> {
        unsafe { self.gpu.device.get_semaphore_counter_value(self.raw) }
            .vk("vkGetSemaphoreCounterValue")
    }

    /// Blocks the host until the semaphore reaches `value`, or errors after `timeout`.
    pub fn wait(&self, value: u64, timeout: Duration) -> Result<()> {
        let semaphores = [self.raw];
        let values = [value];
        let info = vk::SemaphoreWaitInfo::default()
            .semaphores(&semaphores)
            .values(&values);
        match unsafe {
            self.gpu
                .device
                .wait_semaphores(&info, timeout.as_nanos() as u64)
        } {
            Ok(()) => Ok(()),
            Err(vk::Result::TIMEOUT) => Err(Error::Timeout {
                what: "timeline semaphore",
                seconds: timeout.as_secs_f64(),
            }),
            Err(result) => Err(Error::Vulkan {
                call: "vkWaitSemaphores",
                result,
            }),
        }
    }
}

impl Drop for Timeline {
    fn drop(&mut self) {
        unsafe { self.gpu.device.destroy_semaphore(self.raw, None) };
    }
}

//! Samplers: a handle that destroys itself, made from a [`SamplerInfo`].

use std::sync::Arc;

use ash::vk;

use super::Gpu;
use crate::error::{Result, VkResultExt};

/// What a terrain sampler does: trilinear filtering clamped at the edges over every mip
/// level (what both terrain samplers share), and how much anisotropy it may use.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SamplerInfo {
    /// Up to this many samples along the axis of anisotropy (1 or less: none), capped at the
    /// device's limit, and none where the device did not enable `samplerAnisotropy`.
    pub max_anisotropy: f32,
}

impl SamplerInfo {
    /// Trilinear, clamped at the edges, every mip level, no anisotropy.
    pub fn trilinear_clamped() -> Self {
        Self::default()
    }

    /// The same with up to `max` samples of anisotropic filtering where the device allows.
    pub fn anisotropic(self, max: f32) -> Self {
        Self {
            max_anisotropy: max,
        }
    }
}

/// A `VkSampler`, destroyed on drop.
pub struct Sampler {
    gpu: Arc<Gpu>,
    pub raw: vk::Sampler,
}

impl Sampler {
    pub fn new(gpu: &Arc<Gpu>, info: SamplerInfo) -> Result<Self> {
        let anisotropy = gpu.enabled.sampler_anisotropy && info.max_anisotropy > 1.0;
        let max_anisotropy = if anisotropy {
            gpu.info.caps.max_anisotropy.min(info.max_anisotropy)
        } else {
            1.0
        };
        let create = vk::SamplerCreateInfo::default()
            .mag_filter(vk::Filter::LINEAR)
            .min_filter(vk::Filter::LINEAR)
            .mipmap_mode(vk::SamplerMipmapMode::LINEAR)
            .address_mode_u(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .address_mode_v(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .address_mode_w(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .anisotropy_enable(anisotropy)
            .max_anisotropy(max_anisotropy)
            .max_lod(vk::LOD_CLAMP_NONE);
        let raw = unsafe { gpu.device.create_sampler(&create, None) }.vk("vkCreateSampler")?;
        Ok(Sampler {
            gpu: gpu.clone(),
            raw,
        })
    }
}

impl Drop for Sampler {
    fn drop(&mut self) {
        unsafe { self.gpu.device.destroy_sampler(self.raw, None) };
    }
}

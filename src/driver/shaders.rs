//! SPIR-V compiled from `shaders/*.wgsl` by `build.rs`, and shader-module creation.

use ash::vk;

use super::Gpu;
use crate::error::{Error, Result, VkResultExt};

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));

/// Creates a shader module from SPIR-V bytes embedded by the build script.
pub fn module(gpu: &Gpu, spv: &[u8]) -> Result<vk::ShaderModule> {
    let words = ash::util::read_spv(&mut std::io::Cursor::new(spv))
        .map_err(|e| Error::invalid("SPIR-V", e.to_string()))?;
    unsafe {
        gpu.device
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
    }
    .vk("vkCreateShaderModule")
}

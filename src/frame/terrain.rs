//! The GPU mirror of the data set: heights, normals and albedo (or the clipmap's atlas) and
//! one descriptor set 0 with its frame-uniform buffer per view slot
//! (`shaders/include/terrain_common.wgsl`).

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::FrameUniforms;
use crate::dataset::{Heightmap, Level0, Terrain};
use crate::driver::Gpu;
use crate::driver::descriptors::DescriptorSets;
use crate::driver::memory::{Buffer, Image};
use crate::error::{Error, Result, VkResultExt};
use crate::slots::ViewSlot;

/// The facts about the data set that methods and uniforms need.
#[derive(Clone, Debug)]
pub struct TerrainInfo {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub spacing: f64,
    pub min_height: f32,
    pub max_height: f32,
}

/// Data-set textures on the GPU plus the set-0 layout and one set per frame slot.
pub struct TerrainGpu {
    gpu: Arc<Gpu>,
    pub info: TerrainInfo,
    _height: Image,
    _normal: Image,
    _albedo: Image,
    sampler: vk::Sampler,
    /// Set 0: one per view slot (they differ in their uniform buffer and clipmap quadtree).
    pub descriptors: DescriptorSets,
    uniforms: Vec<Buffer>,
}

impl TerrainGpu {
    /// Set 0 for `slots` view slots. `clipmap`: the clipmap's device mirror bound at bindings 5
    /// (atlas) and 6 (the view slot's quadtree), 7 and 8 (normal and albedo atlases); a
    /// disabled placeholder keeps the single-texture path.
    pub fn new(
        gpu: &Arc<Gpu>,
        data: &Terrain,
        slots: usize,
        clipmap: &crate::clipmap::gpu::ClipmapGpu,
    ) -> Result<Self> {
        let (height, normal, albedo) = if clipmap.enabled {
            // Heights, normals and albedo all come through the clipmap's atlas: 1x1
            // placeholders keep the bindings valid without the full-resolution textures.
            let one = vk::Extent2D {
                width: 1,
                height: 1,
            };
            (
                Image::texture_with_data(gpu, "heights", vk::Format::R32_SFLOAT, one, &[0; 4])?,
                Image::texture_with_data(gpu, "normals", vk::Format::R8G8B8A8_SNORM, one, &[0; 4])?,
                Image::texture_with_data(gpu, "albedo", vk::Format::R8G8B8A8_SRGB, one, &[0; 4])?,
            )
        } else {
            let data = data.require_grid("the single-texture path (clipmap off)")?;
            Self::textures(gpu, data)?
        };
        let (min_height, max_height) = data.height_range();
        let info = TerrainInfo {
            name: data.name().to_string(),
            width: data.width(),
            height: data.height(),
            spacing: data.spacing(),
            min_height,
            max_height,
        };

        let d = &gpu.device;
        let anisotropy = gpu.enabled.sampler_anisotropy;
        let sampler = unsafe {
            d.create_sampler(
                &vk::SamplerCreateInfo::default()
                    .mag_filter(vk::Filter::LINEAR)
                    .min_filter(vk::Filter::LINEAR)
                    .mipmap_mode(vk::SamplerMipmapMode::LINEAR)
                    .address_mode_u(vk::SamplerAddressMode::CLAMP_TO_EDGE)
                    .address_mode_v(vk::SamplerAddressMode::CLAMP_TO_EDGE)
                    .address_mode_w(vk::SamplerAddressMode::CLAMP_TO_EDGE)
                    .anisotropy_enable(anisotropy)
                    .max_anisotropy(if anisotropy {
                        gpu.info.caps.max_anisotropy.min(16.0)
                    } else {
                        1.0
                    })
                    .max_lod(vk::LOD_CLAMP_NONE),
                None,
            )
        }
        .vk("vkCreateSampler")?;
        use vk::DescriptorType as T;
        let descriptors = DescriptorSets::new(
            gpu,
            &[
                T::UNIFORM_BUFFER, // 0: frame uniforms
                T::SAMPLED_IMAGE,  // 1: heights
                T::SAMPLED_IMAGE,  // 2: normals
                T::SAMPLED_IMAGE,  // 3: albedo
                T::SAMPLER,        // 4: linear sampler
                T::SAMPLED_IMAGE,  // 5: clipmap height atlas
                T::STORAGE_BUFFER, // 6: clipmap quadtree of the view slot
                T::SAMPLED_IMAGE,  // 7: clipmap normal atlas
                T::SAMPLED_IMAGE,  // 8: clipmap albedo atlas
            ],
            vk::ShaderStageFlags::VERTEX
                | vk::ShaderStageFlags::FRAGMENT
                | vk::ShaderStageFlags::COMPUTE,
            slots,
        )
        .inspect_err(|_| unsafe { d.destroy_sampler(sampler, None) })?;
        let mut uniforms = Vec::with_capacity(slots);
        for (slot, &set) in descriptors.sets.iter().enumerate() {
            let ubo = Buffer::new(
                gpu,
                &format!("frame uniforms {slot}"),
                size_of::<FrameUniforms>() as u64,
                vk::BufferUsageFlags::UNIFORM_BUFFER,
                MemoryLocation::CpuToGpu,
            )?;
            let buffer_info = [vk::DescriptorBufferInfo {
                buffer: ubo.raw,
                offset: 0,
                range: vk::WHOLE_SIZE,
            }];
            let image_info = |view| {
                [vk::DescriptorImageInfo {
                    sampler: vk::Sampler::null(),
                    image_view: view,
                    image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                }]
            };
            let (hi, ni, ai, ci) = (
                image_info(height.view),
                image_info(normal.view),
                image_info(albedo.view),
                image_info(clipmap.atlas.view),
            );
            let (cn, ca) = (
                image_info(clipmap.normals.view),
                image_info(clipmap.albedo.view),
            );
            let qi = [vk::DescriptorBufferInfo {
                buffer: clipmap.quadtrees[slot].raw,
                offset: 0,
                range: vk::WHOLE_SIZE,
            }];
            let si = [vk::DescriptorImageInfo {
                sampler,
                ..Default::default()
            }];
            let write = |b: u32, ty| {
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(b)
                    .descriptor_type(ty)
            };
            let writes = [
                write(0, vk::DescriptorType::UNIFORM_BUFFER).buffer_info(&buffer_info),
                write(1, vk::DescriptorType::SAMPLED_IMAGE).image_info(&hi),
                write(2, vk::DescriptorType::SAMPLED_IMAGE).image_info(&ni),
                write(3, vk::DescriptorType::SAMPLED_IMAGE).image_info(&ai),
                write(4, vk::DescriptorType::SAMPLER).image_info(&si),
                write(5, vk::DescriptorType::SAMPLED_IMAGE).image_info(&ci),
                write(6, vk::DescriptorType::STORAGE_BUFFER).buffer_info(&qi),
                write(7, vk::DescriptorType::SAMPLED_IMAGE).image_info(&cn),
                write(8, vk::DescriptorType::SAMPLED_IMAGE).image_info(&ca),
            ];
            unsafe { d.update_descriptor_sets(&writes, &[]) };
            uniforms.push(ubo);
        }
        Ok(TerrainGpu {
            gpu: gpu.clone(),
            info,
            _height: height,
            _normal: normal,
            _albedo: albedo,
            sampler,
            descriptors,
            uniforms,
        })
    }
}

impl TerrainGpu {
    /// Descriptor set 0 of `view`.
    pub fn set(&self, view: ViewSlot) -> vk::DescriptorSet {
        self.descriptors.sets[view.index()]
    }

    /// Writes the frame uniforms of `view` (its previous GPU use complete).
    pub fn write_uniforms(&mut self, view: ViewSlot, uniforms: &FrameUniforms) -> Result<()> {
        self.uniforms[view.index()].write(bytemuck::bytes_of(uniforms))
    }

    /// The full-resolution height, normal and albedo textures of the single-texture path.
    fn textures(gpu: &Arc<Gpu>, data: &Heightmap) -> Result<(Image, Image, Image)> {
        let max_side = gpu.info.limits.max_image_dimension2_d;
        if data.width > max_side || data.height > max_side {
            return Err(Error::invalid(
                &data.name,
                format!(
                    "{}x{} exceeds the device's {max_side} texels per side",
                    data.width, data.height
                ),
            ));
        }
        let extent = vk::Extent2D {
            width: data.width,
            height: data.height,
        };
        let heights: Vec<u8> = data.heights.iter().flat_map(|h| h.to_le_bytes()).collect();
        let height =
            Image::texture_with_data(gpu, "heights", vk::Format::R32_SFLOAT, extent, &heights)?;
        drop(heights);
        let normal = Image::texture_with_data(
            gpu,
            "normals",
            vk::Format::R8G8B8A8_SNORM,
            extent,
            &data.normals_snorm8(),
        )?;
        let albedo_data = data.albedo_or_ramp();
        let albedo = Image::texture_with_data(
            gpu,
            "albedo",
            vk::Format::R8G8B8A8_SRGB,
            vk::Extent2D {
                width: albedo_data.width,
                height: albedo_data.height,
            },
            &albedo_data.rgba,
        )?;
        Ok((height, normal, albedo))
    }
}

impl Drop for TerrainGpu {
    fn drop(&mut self) {
        unsafe {
            self.gpu.device.destroy_sampler(self.sampler, None);
        }
    }
}

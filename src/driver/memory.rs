//! Buffers and images with their memory, freed when dropped.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};

use super::Gpu;
use crate::error::{Error, Result, VkResultExt};

/// A buffer and its memory; host-visible buffers stay mapped for their whole life.
pub struct Buffer {
    gpu: Arc<Gpu>,
    pub raw: vk::Buffer,
    pub size: u64,
    allocation: Option<Allocation>,
}

impl Buffer {
    pub fn new(
        gpu: &Arc<Gpu>,
        name: &str,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
    ) -> Result<Self> {
        if size == 0 {
            return Err(Error::invalid(name, "buffer size is zero"));
        }
        let d = &gpu.device;
        let raw = unsafe {
            d.create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(size)
                    .usage(usage)
                    .sharing_mode(vk::SharingMode::EXCLUSIVE),
                None,
            )
        }
        .vk("vkCreateBuffer")?;
        let requirements = unsafe { d.get_buffer_memory_requirements(raw) };
        let allocation = gpu.allocator().allocate(&AllocationCreateDesc {
            name,
            requirements,
            location,
            linear: true,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        });
        let allocation = match allocation {
            Ok(a) => a,
            Err(source) => {
                unsafe { d.destroy_buffer(raw, None) };
                return Err(Error::Allocation {
                    what: name.to_string(),
                    source,
                });
            }
        };
        if let Err(e) =
            unsafe { d.bind_buffer_memory(raw, allocation.memory(), allocation.offset()) }
        {
            unsafe { d.destroy_buffer(raw, None) };
            let _ = gpu.allocator().free(allocation);
            return Err(Error::Vulkan {
                call: "vkBindBufferMemory",
                result: e,
            });
        }
        Ok(Buffer {
            gpu: gpu.clone(),
            raw,
            size,
            allocation: Some(allocation),
        })
    }

    /// A host-visible buffer of `usage` holding exactly `data`, written once at creation.
    pub fn with_data(
        gpu: &Arc<Gpu>,
        name: &str,
        usage: vk::BufferUsageFlags,
        data: &[u8],
    ) -> Result<Self> {
        let mut buffer = Self::new(
            gpu,
            name,
            data.len() as u64,
            usage,
            MemoryLocation::CpuToGpu,
        )?;
        buffer.write(data)?;
        Ok(buffer)
    }

    /// Host-visible contents (None for device-only memory).
    pub fn mapped(&self) -> Option<&[u8]> {
        self.allocation
            .as_ref()?
            .mapped_slice()
            .map(|s| &s[..self.size as usize])
    }

    pub fn mapped_mut(&mut self) -> Option<&mut [u8]> {
        let size = self.size as usize;
        self.allocation
            .as_mut()?
            .mapped_slice_mut()
            .map(|s| &mut s[..size])
    }

    /// Memory properties of the memory type backing this buffer.
    pub fn memory_properties(&self) -> vk::MemoryPropertyFlags {
        self.allocation
            .as_ref()
            .map(|a| a.memory_properties())
            .unwrap_or_default()
    }

    /// Writes `data` at the start of a host-visible buffer.
    pub fn write(&mut self, data: &[u8]) -> Result<()> {
        let dst = self
            .mapped_mut()
            .ok_or_else(|| Error::invalid("buffer write", "buffer is not host-visible"))?;
        if data.len() > dst.len() {
            return Err(Error::invalid(
                "buffer write",
                "data larger than the buffer",
            ));
        }
        dst[..data.len()].copy_from_slice(data);
        Ok(())
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        unsafe { self.gpu.device.destroy_buffer(self.raw, None) };
        if let Some(a) = self.allocation.take() {
            let _ = self.gpu.allocator().free(a);
        }
    }
}

/// A 2D image (optionally an array) with one view over all its layers and mips.
pub struct Image {
    gpu: Arc<Gpu>,
    pub raw: vk::Image,
    pub view: vk::ImageView,
    pub format: vk::Format,
    pub extent: vk::Extent2D,
    pub layers: u32,
    pub mips: u32,
    allocation: Option<Allocation>,
}

/// What an [`Image`] is made of.
pub struct ImageDesc<'a> {
    pub name: &'a str,
    pub format: vk::Format,
    pub extent: vk::Extent2D,
    pub layers: u32,
    pub mips: u32,
    pub usage: vk::ImageUsageFlags,
    pub aspect: vk::ImageAspectFlags,
}

impl ImageDesc<'_> {
    /// A 2D image of this description, optimal tiling, one sample, `UNDEFINED` at first.
    fn create_info(&self) -> vk::ImageCreateInfo<'static> {
        vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(self.format)
            .extent(vk::Extent3D {
                width: self.extent.width,
                height: self.extent.height,
                depth: 1,
            })
            .mip_levels(self.mips)
            .array_layers(self.layers)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(self.usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED)
    }

    /// A view of every mip and layer of `image` (an array view where there are layers).
    fn view_info(&self, image: vk::Image) -> vk::ImageViewCreateInfo<'static> {
        let view_type = if self.layers > 1 {
            vk::ImageViewType::TYPE_2D_ARRAY
        } else {
            vk::ImageViewType::TYPE_2D
        };
        vk::ImageViewCreateInfo::default()
            .image(image)
            .view_type(view_type)
            .format(self.format)
            .subresource_range(vk::ImageSubresourceRange {
                aspect_mask: self.aspect,
                base_mip_level: 0,
                level_count: self.mips,
                base_array_layer: 0,
                layer_count: self.layers,
            })
    }
}

impl Image {
    pub fn new(gpu: &Arc<Gpu>, desc: &ImageDesc<'_>) -> Result<Self> {
        let d = &gpu.device;
        let raw = unsafe { d.create_image(&desc.create_info(), None) }.vk("vkCreateImage")?;
        let requirements = unsafe { d.get_image_memory_requirements(raw) };
        let allocation = match gpu.allocator().allocate(&AllocationCreateDesc {
            name: desc.name,
            requirements,
            location: MemoryLocation::GpuOnly,
            linear: false,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        }) {
            Ok(a) => a,
            Err(source) => {
                unsafe { d.destroy_image(raw, None) };
                return Err(Error::Allocation {
                    what: desc.name.to_string(),
                    source,
                });
            }
        };
        let cleanup = |allocation: Allocation| {
            unsafe { d.destroy_image(raw, None) };
            let _ = gpu.allocator().free(allocation);
        };
        if let Err(result) =
            unsafe { d.bind_image_memory(raw, allocation.memory(), allocation.offset()) }
        {
            cleanup(allocation);
            return Err(Error::Vulkan {
                call: "vkBindImageMemory",
                result,
            });
        }
        let view = match unsafe { d.create_image_view(&desc.view_info(raw), None) } {
            Ok(v) => v,
            Err(result) => {
                cleanup(allocation);
                return Err(Error::Vulkan {
                    call: "vkCreateImageView",
                    result,
                });
            }
        };
        Ok(Image {
            gpu: gpu.clone(),
            raw,
            view,
            format: desc.format,
            extent: desc.extent,
            layers: desc.layers,
            mips: desc.mips,
            allocation: Some(allocation),
        })
    }

    /// Creates a sampled 2D texture and fills mip 0 from `data` (tightly packed texels) through a
    /// staging buffer. Set-up time only.
    pub fn texture_with_data(
        gpu: &Arc<Gpu>,
        name: &str,
        format: vk::Format,
        extent: vk::Extent2D,
        data: &[u8],
    ) -> Result<Self> {
        Self::texture_with_mips(gpu, name, format, extent, &[data])
    }

    /// Creates a sampled 2D texture with `levels.len()` mips; level `k` is
    /// `max(1, width >> k)` x `max(1, height >> k)` tightly packed texels. Set-up time only.
    pub fn texture_with_mips(
        gpu: &Arc<Gpu>,
        name: &str,
        format: vk::Format,
        extent: vk::Extent2D,
        levels: &[&[u8]],
    ) -> Result<Self> {
        let image = Image::new(
            gpu,
            &ImageDesc {
                name,
                format,
                extent,
                layers: 1,
                mips: levels.len() as u32,
                usage: vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST,
                aspect: vk::ImageAspectFlags::COLOR,
            },
        )?;
        let total: usize = levels.iter().map(|l| l.len()).sum();
        let mut staging = Buffer::new(
            gpu,
            &format!("{name} staging"),
            total as u64,
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
        )?;
        staging.write(&levels.concat())?;
        let mut offset = 0u64;
        let regions: Vec<vk::BufferImageCopy> = levels
            .iter()
            .enumerate()
            .map(|(k, level)| {
                let region = vk::BufferImageCopy::default()
                    .buffer_offset(offset)
                    .image_subresource(vk::ImageSubresourceLayers {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        mip_level: k as u32,
                        base_array_layer: 0,
                        layer_count: 1,
                    })
                    .image_extent(vk::Extent3D {
                        width: (extent.width >> k).max(1),
                        height: (extent.height >> k).max(1),
                        depth: 1,
                    });
                offset += level.len() as u64;
                region
            })
            .collect();
        let range = super::barrier::color_range();
        gpu.one_shot(|cmd| {
            let b = super::barrier::Barriers::new(gpu);
            b.image(
                cmd,
                image.raw,
                range,
                super::barrier::ImageAccess::Undefined,
                super::barrier::ImageAccess::TransferDst,
            );
            unsafe {
                gpu.device.cmd_copy_buffer_to_image(
                    cmd,
                    staging.raw,
                    image.raw,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    &regions,
                )
            };
            b.image(
                cmd,
                image.raw,
                range,
                super::barrier::ImageAccess::TransferDst,
                super::barrier::ImageAccess::SampledAnyShader,
            );
        })?;
        Ok(image)
    }
}

impl Drop for Image {
    fn drop(&mut self) {
        unsafe {
            self.gpu.device.destroy_image_view(self.view, None);
            self.gpu.device.destroy_image(self.raw, None);
        }
        if let Some(a) = self.allocation.take() {
            let _ = self.gpu.allocator().free(a);
        }
    }
}

//! Host memory the GPU writes into directly (`VK_EXT_external_memory_host`): a buffer whose
//! memory is an existing, page-aligned host range (a ring slot's pixels), so a frame's readback
//! copy lands where consumers read it, with no host `memcpy` afterwards.

use std::sync::Arc;

use ash::vk;

use super::Gpu;
use crate::error::{Error, Result, VkResultExt};

/// A transfer-destination buffer over imported host memory. The host range must outlive it
/// (see [`HostBuffer::import`]); it never frees that memory, only the Vulkan objects.
pub struct HostBuffer {
    gpu: Arc<Gpu>,
    pub raw: vk::Buffer,
    memory: vk::DeviceMemory,
    pub size: u64,
}

impl HostBuffer {
    /// Why `ptr`/`len` cannot be imported on this device, if they cannot.
    pub fn unsupported_reason(gpu: &Gpu, ptr: *const u8, len: u64) -> Option<String> {
        if !gpu.enabled.external_memory_host {
            return Some("the device lacks VK_EXT_external_memory_host".into());
        }
        let a = gpu.info.host_pointer_alignment.max(1);
        if (ptr as u64) % a != 0 || len % a != 0 || len == 0 {
            return Some(format!(
                "the range ({len} bytes at {ptr:p}) is not aligned to the device's {a} bytes"
            ));
        }
        None
    }

    /// Imports `len` bytes at `ptr` as a `TRANSFER_DST` buffer in a host-coherent memory type.
    ///
    /// # Safety
    /// `ptr..ptr + len` must be a mapping that stays valid (not unmapped) until this buffer is
    /// dropped and until the GPU has finished every command that writes it.
    pub unsafe fn import(gpu: &Arc<Gpu>, name: &str, ptr: *mut u8, len: u64) -> Result<Self> {
        if let Some(reason) = Self::unsupported_reason(gpu, ptr, len) {
            return Err(Error::invalid(
                name,
                format!("cannot import host memory: {reason}"),
            ));
        }
        let d = &gpu.device;
        let handle_type = vk::ExternalMemoryHandleTypeFlags::HOST_ALLOCATION_EXT;
        // SAFETY: `ptr` is a valid host pointer (caller's contract).
        let host_types = unsafe { Self::host_pointer_types(gpu, ptr) }?;
        let mut external = vk::ExternalMemoryBufferCreateInfo::default().handle_types(handle_type);
        let raw = unsafe {
            d.create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(len)
                    .usage(vk::BufferUsageFlags::TRANSFER_DST)
                    .sharing_mode(vk::SharingMode::EXCLUSIVE)
                    .push_next(&mut external),
                None,
            )
        }
        .vk("vkCreateBuffer")?;
        let req = unsafe { d.get_buffer_memory_requirements(raw) };
        let Some(type_index) = coherent_type(gpu, host_types & req.memory_type_bits) else {
            unsafe { d.destroy_buffer(raw, None) };
            return Err(Error::invalid(
                name,
                "no host-coherent memory type accepts the imported pointer",
            ));
        };
        let mut import = vk::ImportMemoryHostPointerInfoEXT::default()
            .handle_type(handle_type)
            .host_pointer(ptr.cast());
        let memory = match unsafe {
            d.allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(len)
                    .memory_type_index(type_index)
                    .push_next(&mut import),
                None,
            )
        } {
            Ok(m) => m,
            Err(result) => {
                unsafe { d.destroy_buffer(raw, None) };
                return Err(Error::Vulkan {
                    call: "vkAllocateMemory (host pointer import)",
                    result,
                });
            }
        };
        if let Err(result) = unsafe { d.bind_buffer_memory(raw, memory, 0) } {
            unsafe {
                d.destroy_buffer(raw, None);
                d.free_memory(memory, None);
            }
            return Err(Error::Vulkan {
                call: "vkBindBufferMemory",
                result,
            });
        }
        Ok(HostBuffer {
            gpu: gpu.clone(),
            raw,
            memory,
            size: len,
        })
    }
}

impl HostBuffer {
    /// The memory types (bits) that can import host pointer `ptr`.
    ///
    /// # Safety
    /// `ptr` must be a valid host pointer.
    unsafe fn host_pointer_types(gpu: &Gpu, ptr: *mut u8) -> Result<u32> {
        let ext = ash::ext::external_memory_host::Device::new(&gpu.instance.raw, &gpu.device);
        let mut host_props = vk::MemoryHostPointerPropertiesEXT::default();
        // SAFETY: the function pointer was loaded for this device, which has the extension
        // enabled; `ptr` is valid (this function's contract).
        unsafe {
            (ext.fp().get_memory_host_pointer_properties_ext)(
                ext.device(),
                vk::ExternalMemoryHandleTypeFlags::HOST_ALLOCATION_EXT,
                ptr.cast(),
                &mut host_props,
            )
        }
        .result()
        .vk("vkGetMemoryHostPointerPropertiesEXT")?;
        Ok(host_props.memory_type_bits)
    }
}

/// The first memory type among `allowed` (bits) that is host-visible and coherent: the host
/// reads the pixels without vkInvalidateMappedMemoryRanges.
fn coherent_type(gpu: &Gpu, allowed: u32) -> Option<u32> {
    let types = &gpu.info.memory;
    let wanted = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
    (0..types.memory_type_count).find(|&i| {
        allowed & (1 << i) != 0
            && types.memory_types[i as usize]
                .property_flags
                .contains(wanted)
    })
}

impl Drop for HostBuffer {
    fn drop(&mut self) {
        unsafe {
            self.gpu.device.destroy_buffer(self.raw, None);
            self.gpu.device.free_memory(self.memory, None);
        }
    }
}

//! The driver layer: the one owner of the Vulkan instance, device, queue, memory and sync.
//!
//! Everything above this layer holds an `Arc<Gpu>` and the RAII wrappers of [`memory`] and
//! [`sync`]; nothing above it creates devices or allocates memory by hand.

pub mod barrier;
pub mod descriptors;
pub mod device;
pub mod host_memory;
pub mod instance;
pub mod memory;
pub mod pipeline;
#[cfg(feature = "test-support")]
pub mod probe;
pub mod sampler;
pub mod shaders;
pub mod sync;

use std::mem::ManuallyDrop;
use std::sync::{Arc, Mutex};

use ash::vk;

pub use device::{Capabilities, DeviceInfo, Feature};
pub use instance::ValidationLog;

use crate::error::{Error, Result, VkResultExt};

/// Environment variable that turns the validation layers on (`1`/`true`) for any command.
pub const VALIDATION_ENV: &str = "VKTERRAIN_VALIDATION";

/// Environment variable listing optional device features to treat as absent (comma-separated
/// Vulkan names, e.g. `tessellationShader,meshShader`): tests of the one-line "missing
/// feature" errors, and a desktop GPU standing in for a board without them (TI TDA4VH).
pub const MASK_FEATURES_ENV: &str = "VKTERRAIN_MASK_FEATURES";

/// How to create the GPU context (config `[device]`).
#[derive(Clone, Debug, Default, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GpuOptions {
    /// Device override: index or case-insensitive name substring. `VKTERRAIN_DEVICE` wins.
    pub select: Option<String>,
    /// Enable `VK_LAYER_KHRONOS_validation` with synchronization validation.
    pub validation: bool,
    /// Use classic render passes and `vkCmdPipelineBarrier` even where Vulkan 1.3's dynamic
    /// rendering and synchronization2 exist (keeps the fallback path tested).
    pub force_legacy: bool,
    /// Optional features to leave disabled as if the device lacked them (Vulkan names, see
    /// [`MASK_FEATURES_ENV`]; set from the environment only).
    #[serde(skip)]
    pub mask_features: Vec<String>,
    /// The frame block's variant (tests and measurements); None: `VKTERRAIN_FRAME_BLOCK`, else
    /// [`shaders::FrameBlock::for_device`].
    #[serde(skip)]
    pub frame_block: Option<shaders::FrameBlock>,
}

impl GpuOptions {
    /// Applies the environment overrides (`VKTERRAIN_DEVICE`, `VKTERRAIN_VALIDATION`).
    pub fn with_env(mut self) -> Self {
        if let Ok(v) = std::env::var(device::DEVICE_ENV)
            && !v.trim().is_empty()
        {
            self.select = Some(v);
        }
        if let Ok(v) = std::env::var(VALIDATION_ENV) {
            self.validation |= matches!(v.trim(), "1" | "true" | "yes" | "on");
        }
        if let Ok(v) = std::env::var(MASK_FEATURES_ENV) {
            self.mask_features.extend(
                v.split(',')
                    .map(str::trim)
                    .filter(|f| !f.is_empty())
                    .map(String::from),
            );
        }
        self
    }
}

/// The GPU context: instance, chosen device, its one queue, and the memory allocator.
pub struct Gpu {
    pub instance: instance::Instance,
    pub physical: vk::PhysicalDevice,
    pub info: DeviceInfo,
    pub device: ash::Device,
    pub queue: Mutex<vk::Queue>,
    pub queue_family: u32,
    /// Dynamic rendering + synchronization2 are in use (Vulkan 1.3 and not forced off).
    pub modern: bool,
    allocator: ManuallyDrop<Mutex<gpu_allocator::vulkan::Allocator>>,
    /// Enabled optional features (a subset of `info.caps`).
    pub enabled: Capabilities,
    /// Features the device offers but [`GpuOptions::mask_features`] left disabled.
    pub masked: Vec<Feature>,
    /// How every shader reads the frame's block (set 0 binding 0), for this device.
    pub frame_block: shaders::FrameBlock,
}

impl Gpu {
    pub fn new(options: &GpuOptions) -> Result<Arc<Gpu>> {
        let mask = options
            .mask_features
            .iter()
            .map(|name| Feature::parse(name))
            .collect::<Result<Vec<_>>>()?;
        let instance = instance::Instance::new(options.validation)?;
        let candidates = device::enumerate(&instance.raw)?;
        let (physical, info) = device::choose(&candidates, options.select.as_deref())?;
        let frame_block = match options.frame_block {
            Some(block) => block,
            None => match std::env::var(shaders::FRAME_BLOCK_ENV) {
                Ok(v) if !v.trim().is_empty() => shaders::FrameBlock::parse(&v)?,
                _ => shaders::FrameBlock::for_device(&info),
            },
        };
        let queue_family = info.universal_queue_family().expect("checked by choose");
        let mut offered = info.caps;
        let masked: Vec<Feature> = mask.into_iter().filter(|f| f.get(&offered)).collect();
        for f in &masked {
            f.clear(&mut offered);
        }
        let modern = offered.dynamic_rendering && offered.synchronization2 && !options.force_legacy;

        // Not on CPU devices: lavapipe (Mesa 22.3) filters anisotropically in software and some
        // frames then take seconds instead of milliseconds (measured: 7 s and 97 s frames at
        // 640x360 where the same frames take ~50 ms without it).
        let anisotropy =
            offered.sampler_anisotropy && info.device_type != vk::PhysicalDeviceType::CPU;
        let device = create_device(
            &instance.raw,
            (physical, queue_family),
            &info,
            &offered,
            modern,
            anisotropy,
        )?;
        let queue = unsafe { device.get_device_queue(queue_family, 0) };

        let allocator = create_allocator(&instance.raw, &device, physical)?;

        let enabled = Capabilities {
            dynamic_rendering: modern,
            synchronization2: modern,
            sampler_anisotropy: anisotropy,
            // Enabled only when a method needs it (none does yet).
            geometry_shader: false,
            // The rest as offered: external host memory (the zero-copy ring), mesh shaders, ...
            ..offered
        };
        Ok(Arc::new(Gpu {
            instance,
            physical,
            info,
            device,
            queue: Mutex::new(queue),
            queue_family,
            modern,
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            enabled,
            masked,
            frame_block,
        }))
    }

    /// `Ok` when `feature` is enabled, else the one-line error saying that `who` needs it and
    /// whether the device lacks it or it was masked.
    pub fn require(&self, feature: Feature, who: &str) -> Result<()> {
        if feature.get(&self.enabled) {
            return Ok(());
        }
        let reason = if self.masked.contains(&feature) {
            format!("is masked by {MASK_FEATURES_ENV}")
        } else {
            format!("is not offered by {}", self.info.name)
        };
        Err(Error::MissingFeature {
            who: who.to_string(),
            feature: feature.vulkan_name(),
            reason,
        })
    }

    /// Validation messages so far, when validation is on.
    pub fn validation(&self) -> Option<&ValidationLog> {
        self.instance.validation.as_deref()
    }

    pub(crate) fn allocator(&self) -> std::sync::MutexGuard<'_, gpu_allocator::vulkan::Allocator> {
        // A panic while holding the lock cannot leave the allocator half-updated in a way that
        // matters more than the panic itself; keep going with the inner value.
        self.allocator.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Bytes of device memory in live allocations (buffers and images this process made
    /// through the allocator), for memory budgets and tests.
    pub fn allocated_bytes(&self) -> u64 {
        self.allocator().generate_report().total_allocated_bytes
    }

    /// Submits to the one queue.
    pub fn submit(&self, submits: &[vk::SubmitInfo<'_>], fence: vk::Fence) -> Result<()> {
        let queue = self.queue.lock().unwrap_or_else(|p| p.into_inner());
        unsafe { self.device.queue_submit(*queue, submits, fence) }.vk("vkQueueSubmit")
    }

    /// Waits until the device is idle (shutdown and tests only).
    pub fn wait_idle(&self) -> Result<()> {
        unsafe { self.device.device_wait_idle() }.vk("vkDeviceWaitIdle")
    }

    /// Records and submits a one-shot command buffer and waits for it (set-up uploads only,
    /// never on the frame path).
    pub fn one_shot(&self, record: impl FnOnce(vk::CommandBuffer)) -> Result<()> {
        let d = &self.device;
        unsafe {
            let pool = d
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default()
                        .queue_family_index(self.queue_family)
                        .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                    None,
                )
                .vk("vkCreateCommandPool")?;
            let result = (|| {
                let cmd = d
                    .allocate_command_buffers(
                        &vk::CommandBufferAllocateInfo::default()
                            .command_pool(pool)
                            .command_buffer_count(1),
                    )
                    .vk("vkAllocateCommandBuffers")?[0];
                d.begin_command_buffer(
                    cmd,
                    &vk::CommandBufferBeginInfo::default()
                        .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .vk("vkBeginCommandBuffer")?;
                record(cmd);
                d.end_command_buffer(cmd).vk("vkEndCommandBuffer")?;
                let fence = d
                    .create_fence(&vk::FenceCreateInfo::default(), None)
                    .vk("vkCreateFence")?;
                let cmds = [cmd];
                let r = self
                    .submit(&[vk::SubmitInfo::default().command_buffers(&cmds)], fence)
                    .and_then(|_| {
                        d.wait_for_fences(&[fence], true, u64::MAX)
                            .vk("vkWaitForFences")
                    });
                d.destroy_fence(fence, None);
                r
            })();
            d.destroy_command_pool(pool, None);
            result
        }
    }
}

impl Drop for Gpu {
    fn drop(&mut self) {
        unsafe {
            let _ = self.device.device_wait_idle();
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
        }
        // `instance` drops after this, destroying the messenger and the instance.
    }
}

/// The logical device with one queue of the universal `queue_family` and the features `offered` (after masking)
/// that the renderer uses: dynamic rendering and synchronization2 when `modern`, mesh shaders
/// and host-memory import where offered.
fn create_device(
    instance: &ash::Instance,
    (physical, queue_family): (vk::PhysicalDevice, u32),
    info: &DeviceInfo,
    offered: &Capabilities,
    modern: bool,
    anisotropy: bool,
) -> Result<ash::Device> {
    let base = vk::PhysicalDeviceFeatures::default()
        .sampler_anisotropy(anisotropy)
        .multi_draw_indirect(offered.multi_draw_indirect)
        .draw_indirect_first_instance(offered.draw_indirect_first_instance)
        .pipeline_statistics_query(offered.pipeline_statistics_query)
        .tessellation_shader(offered.tessellation_shader);
    let mut f12 = vk::PhysicalDeviceVulkan12Features::default()
        .timeline_semaphore(true)
        .draw_indirect_count(offered.draw_indirect_count);
    let mut f13 = vk::PhysicalDeviceVulkan13Features::default()
        .dynamic_rendering(modern)
        .synchronization2(modern);
    let priorities = [1.0f32];
    let queues = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(queue_family)
        .queue_priorities(&priorities)];
    // Zero-copy ring publishing imports the ring's slots as buffers (host_memory.rs).
    let mut extensions = Vec::new();
    if offered.external_memory_host {
        extensions.push(ash::ext::external_memory_host::NAME.as_ptr());
    }
    // Task + mesh shaders (the chunked method's mesh path) where offered and not masked.
    let mut fmesh = vk::PhysicalDeviceMeshShaderFeaturesEXT::default()
        .task_shader(true)
        .mesh_shader(true);
    if offered.mesh_shader {
        extensions.push(ash::ext::mesh_shader::NAME.as_ptr());
    }
    let mut create = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queues)
        .enabled_extension_names(&extensions)
        .enabled_features(&base)
        .push_next(&mut f12);
    if info.api_version >= vk::API_VERSION_1_3 {
        create = create.push_next(&mut f13);
    }
    if offered.mesh_shader {
        create = create.push_next(&mut fmesh);
    }
    unsafe { instance.create_device(physical, &create, None) }.vk("vkCreateDevice")
}

/// gpu-allocator over `device`; destroys the device if it fails, as nothing else owns it yet.
fn create_allocator(
    instance: &ash::Instance,
    device: &ash::Device,
    physical: vk::PhysicalDevice,
) -> Result<gpu_allocator::vulkan::Allocator> {
    gpu_allocator::vulkan::Allocator::new(&gpu_allocator::vulkan::AllocatorCreateDesc {
        instance: instance.clone(),
        device: device.clone(),
        physical_device: physical,
        debug_settings: Default::default(),
        buffer_device_address: false,
        allocation_sizes: Default::default(),
    })
    .map_err(|source| {
        unsafe { device.destroy_device(None) };
        Error::Allocation {
            what: "allocator".into(),
            source,
        }
    })
}

//! Physical-device choice and the logical device.
//!
//! Choice: an explicit override (config `device.select`, or `VKTERRAIN_DEVICE`, by index or by a
//! case-insensitive name substring) wins; otherwise a real GPU (discrete, then integrated) is
//! preferred over virtual GPUs and CPU implementations such as lavapipe.

use std::ffi::CStr;

use ash::vk;

use crate::error::{Error, Result, VkResultExt};

/// Environment variable that overrides the device choice (index or name substring).
pub const DEVICE_ENV: &str = "VKTERRAIN_DEVICE";

/// What a physical device is and what it offers to the renderer.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    pub index: usize,
    pub name: String,
    pub device_type: vk::PhysicalDeviceType,
    pub api_version: u32,
    pub driver: String,
    /// `VkPhysicalDeviceDriverProperties::driverID`.
    pub driver_id: vk::DriverId,
    /// `VkPhysicalDeviceDriverProperties::driverInfo` (Mesa's drivers: `Mesa 22.3.6 ...`;
    /// lavapipe's `driverVersion` does not carry the release).
    pub driver_info: String,
    pub limits: vk::PhysicalDeviceLimits,
    pub memory: vk::PhysicalDeviceMemoryProperties,
    pub queue_families: Vec<vk::QueueFamilyProperties>,
    pub extensions: Vec<String>,
    pub caps: Capabilities,
    /// `minImportedHostPointerAlignment` of `VK_EXT_external_memory_host` (0 without it): host
    /// memory imported for zero-copy readback must start and end on this boundary.
    pub host_pointer_alignment: u64,
}

/// Optional features, as offered by the device (`offered`) and as enabled by vkterrain.
#[derive(Clone, Copy, Debug, Default)]
pub struct Capabilities {
    pub timeline_semaphore: bool,
    pub dynamic_rendering: bool,
    pub synchronization2: bool,
    pub sampler_anisotropy: bool,
    pub max_anisotropy: f32,
    pub multi_draw_indirect: bool,
    pub draw_indirect_first_instance: bool,
    pub draw_indirect_count: bool,
    pub pipeline_statistics_query: bool,
    pub timestamps: bool,
    pub timestamp_period_ns: f32,
    pub tessellation_shader: bool,
    pub geometry_shader: bool,
    pub mesh_shader: bool,
    pub external_memory_host: bool,
    pub texture_compression_bc: bool,
    pub texture_compression_etc2: bool,
    pub texture_compression_astc: bool,
    /// A memory type that is both DEVICE_LOCAL and HOST_VISIBLE (unified memory, e.g. Jetson,
    /// lavapipe): readback and uploads go there directly without a staging copy.
    pub unified_memory: bool,
}

/// Optional device features a method may need (and [`super::GpuOptions::mask_features`] may
/// hide), by their Vulkan names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Feature {
    /// `VkPhysicalDeviceFeatures::tessellationShader`.
    TessellationShader,
    /// `VkPhysicalDeviceFeatures::geometryShader`.
    GeometryShader,
    /// `VkPhysicalDeviceMeshShaderFeaturesEXT::meshShader` with `taskShader`
    /// (`VK_EXT_mesh_shader`).
    MeshShader,
    /// `VkPhysicalDeviceFeatures::multiDrawIndirect` (UDLOD draws its 81 draw masks in one
    /// call with it, else one call each).
    MultiDrawIndirect,
    /// `VkPhysicalDeviceVulkan12Features::drawIndirectCount` (UDLOD draws only the masks with
    /// tiles with it).
    DrawIndirectCount,
    /// `VkPhysicalDeviceFeatures::drawIndirectFirstInstance` (UDLOD needs it).
    DrawIndirectFirstInstance,
}

impl Feature {
    pub const ALL: &[Feature] = &[
        Feature::TessellationShader,
        Feature::GeometryShader,
        Feature::MeshShader,
        Feature::MultiDrawIndirect,
        Feature::DrawIndirectCount,
        Feature::DrawIndirectFirstInstance,
    ];

    pub fn vulkan_name(self) -> &'static str {
        match self {
            Feature::TessellationShader => "tessellationShader",
            Feature::GeometryShader => "geometryShader",
            Feature::MeshShader => "meshShader",
            Feature::MultiDrawIndirect => "multiDrawIndirect",
            Feature::DrawIndirectCount => "drawIndirectCount",
            Feature::DrawIndirectFirstInstance => "drawIndirectFirstInstance",
        }
    }

    /// The feature named `name` (its Vulkan name, case-insensitive).
    pub fn parse(name: &str) -> Result<Feature> {
        Self::ALL
            .iter()
            .copied()
            .find(|f| f.vulkan_name().eq_ignore_ascii_case(name.trim()))
            .ok_or_else(|| {
                let names: Vec<_> = Self::ALL.iter().map(|f| f.vulkan_name()).collect();
                Error::invalid(
                    "feature mask",
                    format!("unknown feature {name:?} (known: {})", names.join(", ")),
                )
            })
    }

    /// Whether `caps` has it.
    pub fn get(self, caps: &Capabilities) -> bool {
        match self {
            Feature::TessellationShader => caps.tessellation_shader,
            Feature::GeometryShader => caps.geometry_shader,
            Feature::MeshShader => caps.mesh_shader,
            Feature::MultiDrawIndirect => caps.multi_draw_indirect,
            Feature::DrawIndirectCount => caps.draw_indirect_count,
            Feature::DrawIndirectFirstInstance => caps.draw_indirect_first_instance,
        }
    }

    /// Removes it from `caps`.
    pub fn clear(self, caps: &mut Capabilities) {
        match self {
            Feature::TessellationShader => caps.tessellation_shader = false,
            Feature::GeometryShader => caps.geometry_shader = false,
            Feature::MeshShader => caps.mesh_shader = false,
            Feature::MultiDrawIndirect => caps.multi_draw_indirect = false,
            Feature::DrawIndirectCount => caps.draw_indirect_count = false,
            Feature::DrawIndirectFirstInstance => caps.draw_indirect_first_instance = false,
        }
    }
}

impl DeviceInfo {
    pub fn type_name(&self) -> &'static str {
        match self.device_type {
            vk::PhysicalDeviceType::DISCRETE_GPU => "discrete GPU",
            vk::PhysicalDeviceType::INTEGRATED_GPU => "integrated GPU",
            vk::PhysicalDeviceType::VIRTUAL_GPU => "virtual GPU",
            vk::PhysicalDeviceType::CPU => "CPU (software)",
            _ => "other",
        }
    }

    /// Preference when nothing is overridden: real GPUs first.
    fn preference(&self) -> u32 {
        match self.device_type {
            vk::PhysicalDeviceType::DISCRETE_GPU => 4,
            vk::PhysicalDeviceType::INTEGRATED_GPU => 3,
            vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
            vk::PhysicalDeviceType::CPU => 1,
            _ => 0,
        }
    }

    /// The queue family used for everything: graphics + compute (transfer is implied).
    pub fn universal_queue_family(&self) -> Option<u32> {
        let want = vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE;
        self.queue_families
            .iter()
            .position(|f| f.queue_flags.contains(want) && f.queue_count > 0)
            .map(|i| i as u32)
    }

    /// A family that only transfers (a DMA engine), if the device has one.
    pub fn dedicated_transfer_family(&self) -> Option<u32> {
        self.queue_families
            .iter()
            .position(|f| {
                f.queue_flags.contains(vk::QueueFlags::TRANSFER)
                    && !f
                        .queue_flags
                        .intersects(vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE)
            })
            .map(|i| i as u32)
    }

    pub fn api_version_string(&self) -> String {
        format!(
            "{}.{}.{}",
            vk::api_version_major(self.api_version),
            vk::api_version_minor(self.api_version),
            vk::api_version_patch(self.api_version)
        )
    }

    /// Why this device cannot run vkterrain, if it cannot.
    pub fn unsuitable_reason(&self) -> Option<String> {
        if self.api_version < vk::API_VERSION_1_2 {
            return Some(format!("Vulkan {} < 1.2", self.api_version_string()));
        }
        if !self.caps.timeline_semaphore {
            return Some("no timeline semaphores".into());
        }
        if self.universal_queue_family().is_none() {
            return Some("no queue family with graphics + compute".into());
        }
        None
    }
}

/// A memory type both DEVICE_LOCAL and HOST_VISIBLE on an integrated or CPU device
/// ([`Capabilities::unified_memory`]).
fn unified_memory(
    memory: &vk::PhysicalDeviceMemoryProperties,
    kind: vk::PhysicalDeviceType,
) -> bool {
    memory.memory_types[..memory.memory_type_count as usize]
        .iter()
        .any(|t| {
            t.property_flags.contains(
                vk::MemoryPropertyFlags::DEVICE_LOCAL | vk::MemoryPropertyFlags::HOST_VISIBLE,
            )
        })
        && matches!(
            kind,
            vk::PhysicalDeviceType::INTEGRATED_GPU | vk::PhysicalDeviceType::CPU
        )
}

pub(crate) fn describe(
    instance: &ash::Instance,
    index: usize,
    pd: vk::PhysicalDevice,
) -> Result<DeviceInfo> {
    unsafe {
        let extensions: Vec<String> = instance
            .enumerate_device_extension_properties(pd)
            .vk("vkEnumerateDeviceExtensionProperties")?
            .iter()
            .filter_map(|e| {
                e.extension_name_as_c_str()
                    .ok()
                    .map(|s| s.to_string_lossy().into_owned())
            })
            .collect();
        let host_ext = ash::ext::external_memory_host::NAME.to_string_lossy();
        let has_host_ext = extensions.iter().any(|e| *e == host_ext);
        let mut driver_props = vk::PhysicalDeviceDriverProperties::default();
        let mut host_props = vk::PhysicalDeviceExternalMemoryHostPropertiesEXT::default();
        let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut driver_props);
        if has_host_ext {
            props2 = props2.push_next(&mut host_props);
        }
        instance.get_physical_device_properties2(pd, &mut props2);
        let props = props2.properties;
        let host_pointer_alignment = if has_host_ext {
            host_props.min_imported_host_pointer_alignment
        } else {
            0
        };
        let memory = instance.get_physical_device_memory_properties(pd);
        let queue_families = instance.get_physical_device_queue_family_properties(pd);

        let name = props
            .device_name_as_c_str()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|_| "(unnamed)".into());
        let text = |s: std::result::Result<&CStr, _>| {
            s.map(|s: &CStr| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        };
        let driver_info = text(driver_props.driver_info_as_c_str());
        let driver = format!(
            "{} {driver_info}",
            text(driver_props.driver_name_as_c_str())
        );
        let unified_memory = unified_memory(&memory, props.device_type);
        let mut info = DeviceInfo {
            index,
            name,
            device_type: props.device_type,
            api_version: props.api_version,
            driver: driver.trim().to_string(),
            driver_id: driver_props.driver_id,
            driver_info,
            limits: props.limits,
            memory,
            queue_families,
            extensions,
            caps: Capabilities::default(),
            host_pointer_alignment,
        };
        info.caps = capabilities(instance, pd, &props, &info.extensions, unified_memory);
        Ok(info)
    }
}

/// Lists every physical device the loader reports.
pub fn enumerate(instance: &ash::Instance) -> Result<Vec<(vk::PhysicalDevice, DeviceInfo)>> {
    let devices =
        unsafe { instance.enumerate_physical_devices() }.map_err(|result| match result {
            vk::Result::ERROR_INITIALIZATION_FAILED => Error::NoDevice,
            result => Error::Vulkan {
                call: "vkEnumeratePhysicalDevices",
                result,
            },
        })?;
    if devices.is_empty() {
        return Err(Error::NoDevice);
    }
    devices
        .into_iter()
        .enumerate()
        .map(|(i, pd)| Ok((pd, describe(instance, i, pd)?)))
        .collect()
}

/// Chooses the device: `select` (index or name substring) if given, else the most preferred
/// suitable one.
pub fn choose(
    candidates: &[(vk::PhysicalDevice, DeviceInfo)],
    select: Option<&str>,
) -> Result<(vk::PhysicalDevice, DeviceInfo)> {
    let available = || {
        candidates
            .iter()
            .map(|(_, d)| format!("[{}] {} ({})", d.index, d.name, d.type_name()))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Some(wanted) = select.map(str::trim).filter(|s| !s.is_empty()) {
        let found = if let Ok(index) = wanted.parse::<usize>() {
            candidates.iter().find(|(_, d)| d.index == index)
        } else {
            let lower = wanted.to_lowercase();
            candidates
                .iter()
                .find(|(_, d)| d.name.to_lowercase().contains(&lower))
        };
        let Some((pd, info)) = found else {
            return Err(Error::UnknownDevice {
                wanted: wanted.to_string(),
                available: available(),
            });
        };
        if let Some(reason) = info.unsuitable_reason() {
            return Err(Error::UnsuitableDevice {
                name: info.name.clone(),
                reason,
            });
        }
        return Ok((*pd, info.clone()));
    }
    candidates
        .iter()
        .filter(|(_, d)| d.unsuitable_reason().is_none())
        .max_by_key(|(_, d)| (d.preference(), std::cmp::Reverse(d.index)))
        .map(|(pd, d)| (*pd, d.clone()))
        .ok_or_else(|| Error::UnsuitableDevice {
            name: available(),
            reason: "none offers Vulkan 1.2 with timeline semaphores and a graphics+compute queue"
                .into(),
        })
}

/// What the device offers of what vkterrain can use: Vulkan 1.2/1.3 and core features, mesh
/// shaders, host-memory import, timestamps, compressed textures.
fn capabilities(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    props: &vk::PhysicalDeviceProperties,
    extensions: &[String],
    unified_memory: bool,
) -> Capabilities {
    let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut f13 = vk::PhysicalDeviceVulkan13Features::default();
    let mut fmesh = vk::PhysicalDeviceMeshShaderFeaturesEXT::default();
    let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut f12);
    let is_13 = props.api_version >= vk::API_VERSION_1_3;
    if is_13 {
        f2 = f2.push_next(&mut f13);
    }
    let has = |name: &CStr| {
        let name = name.to_string_lossy();
        extensions.iter().any(|e| *e == name)
    };
    let has_mesh_ext = has(ash::ext::mesh_shader::NAME);
    if has_mesh_ext {
        f2 = f2.push_next(&mut fmesh);
    }
    unsafe { instance.get_physical_device_features2(pd, &mut f2) };
    let f = f2.features;
    // Task and mesh stages both (the chunked method's mesh path uses the two).
    let mesh_shader =
        has_mesh_ext && fmesh.task_shader == vk::TRUE && fmesh.mesh_shader == vk::TRUE;

    Capabilities {
        timeline_semaphore: f12.timeline_semaphore == vk::TRUE,
        dynamic_rendering: is_13 && f13.dynamic_rendering == vk::TRUE,
        synchronization2: is_13 && f13.synchronization2 == vk::TRUE,
        sampler_anisotropy: f.sampler_anisotropy == vk::TRUE,
        max_anisotropy: props.limits.max_sampler_anisotropy,
        multi_draw_indirect: f.multi_draw_indirect == vk::TRUE,
        draw_indirect_first_instance: f.draw_indirect_first_instance == vk::TRUE,
        draw_indirect_count: f12.draw_indirect_count == vk::TRUE,
        pipeline_statistics_query: f.pipeline_statistics_query == vk::TRUE,
        timestamps: props.limits.timestamp_compute_and_graphics == vk::TRUE,
        timestamp_period_ns: props.limits.timestamp_period,
        tessellation_shader: f.tessellation_shader == vk::TRUE,
        geometry_shader: f.geometry_shader == vk::TRUE,
        mesh_shader,
        external_memory_host: has(ash::ext::external_memory_host::NAME),
        texture_compression_bc: f.texture_compression_bc == vk::TRUE,
        texture_compression_etc2: f.texture_compression_etc2 == vk::TRUE,
        texture_compression_astc: f.texture_compression_astc_ldr == vk::TRUE,
        unified_memory,
    }
}

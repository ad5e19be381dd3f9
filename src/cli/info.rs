//! `vkterrain info`: what the device is and offers.

use std::fmt::Write;
use std::path::Path;

use crate::config::Config;
use crate::driver::shaders::{FRAME_BLOCK_ENV, FrameBlock};
use crate::driver::{Capabilities, DeviceInfo, Gpu};

pub fn run(config: Option<&Path>, device: Option<String>) -> anyhow::Result<()> {
    let mut config = Config::load(config)?;
    if device.is_some() {
        config.device.select = device;
    }
    let gpu = config.open_gpu()?;
    print!("{}", describe(&gpu));
    Ok(())
}

fn yes(b: bool) -> &'static str {
    if b { "yes" } else { "no" }
}

/// The report `vkterrain info` prints.
pub fn describe(gpu: &Gpu) -> String {
    let mut s = String::new();
    write_device(&mut s, gpu);
    write_memory(&mut s, &gpu.info);
    write_features(&mut s, &gpu.info.caps, &gpu.enabled);
    write_limits(&mut s, gpu);
    s
}

/// The device, its driver and the queues vkterrain uses.
fn write_device(s: &mut String, gpu: &Gpu) {
    let i = &gpu.info;
    let _ = writeln!(
        s,
        "device:        [{}] {} ({})",
        i.index,
        i.name,
        i.type_name()
    );
    let _ = writeln!(s, "driver:        {}", i.driver);
    let _ = writeln!(s, "vulkan:        {}", i.api_version_string());
    let _ = writeln!(
        s,
        "frame block:   {} ({})",
        match gpu.frame_block {
            FrameBlock::Uniform => "uniform buffer",
            FrameBlock::Storage => "read-only storage buffer",
        },
        frame_block_reason(gpu)
    );
    let _ = writeln!(
        s,
        "queue:         family {} (graphics+compute), 1 queue; dedicated transfer family: {}",
        gpu.queue_family,
        match i.dedicated_transfer_family() {
            Some(f) =>
                format!("{f} (unused: readback is one small copy per frame on the main queue)"),
            None => "none".into(),
        }
    );
}

/// Why the device reads the frame's block as it does.
fn frame_block_reason(gpu: &Gpu) -> String {
    if gpu.frame_block != FrameBlock::for_device(&gpu.info) {
        format!("set by {FRAME_BLOCK_ENV}")
    } else if gpu.frame_block == FrameBlock::Storage {
        "lavapipe before Mesa 24 rebuilds shaders whose uniforms steer branches".into()
    } else {
        "the driver's default".into()
    }
}

/// The memory heaps and types, and where readback copies land.
fn write_memory(s: &mut String, i: &DeviceInfo) {
    let _ = writeln!(s, "memory heaps:");
    for (h, heap) in i.memory.memory_heaps[..i.memory.memory_heap_count as usize]
        .iter()
        .enumerate()
    {
        let _ = writeln!(
            s,
            "  heap {h}: {:.1} GiB {:?}",
            heap.size as f64 / (1u64 << 30) as f64,
            heap.flags
        );
    }
    let _ = writeln!(s, "memory types:");
    for (t, ty) in i.memory.memory_types[..i.memory.memory_type_count as usize]
        .iter()
        .enumerate()
    {
        let _ = writeln!(
            s,
            "  type {t}: heap {} {:?}",
            ty.heap_index, ty.property_flags
        );
    }
    let _ = writeln!(
        s,
        "readback:      {}",
        if i.caps.unified_memory {
            "unified memory (DEVICE_LOCAL|HOST_VISIBLE): copies land where the host reads, no staging"
        } else {
            "host-visible system memory (GPU copies over the bus)"
        }
    );
}

/// One row of the features table: name, offered, used by vkterrain, what for.
type FeatureRow = (&'static str, bool, bool, &'static str);

/// The features table: what the device offers against what vkterrain turned on.
fn write_features(s: &mut String, c: &Capabilities, e: &Capabilities) {
    let _ = writeln!(s, "features (offered / used by vkterrain):");
    for (name, offered, used, note) in frame_and_draw_features(c, e)
        .into_iter()
        .chain(other_features(c, e))
    {
        let extra = if name.starts_with("BC") {
            format!(
                "BC {} ETC2 {} ASTC {}",
                yes(c.texture_compression_bc),
                yes(c.texture_compression_etc2),
                yes(c.texture_compression_astc)
            )
        } else {
            note.to_string()
        };
        let _ = writeln!(
            s,
            "  {name:<28} {:>3} / {:<3}  {extra}",
            yes(offered),
            yes(used)
        );
    }
}

/// The table's first rows: synchronisation, rendering and indirect drawing.
fn frame_and_draw_features(c: &Capabilities, e: &Capabilities) -> [FeatureRow; 7] {
    [
        (
            "timeline semaphores",
            c.timeline_semaphore,
            e.timeline_semaphore,
            "frame ordering",
        ),
        (
            "dynamic rendering",
            c.dynamic_rendering,
            e.dynamic_rendering,
            "render pass fallback otherwise",
        ),
        (
            "synchronization2",
            c.synchronization2,
            e.synchronization2,
            "classic barriers otherwise",
        ),
        (
            "sampler anisotropy",
            c.sampler_anisotropy,
            e.sampler_anisotropy,
            "fragment texturing (off on CPU devices: too slow)",
        ),
        (
            "multiDrawIndirect",
            c.multi_draw_indirect,
            e.multi_draw_indirect,
            "GPU-driven draws",
        ),
        (
            "drawIndirectFirstInstance",
            c.draw_indirect_first_instance,
            e.draw_indirect_first_instance,
            "",
        ),
        (
            "drawIndirectCount",
            c.draw_indirect_count,
            e.draw_indirect_count,
            "",
        ),
    ]
}

/// The table's last rows: queries, shader stages vkterrain leaves out, host memory import and
/// compressed formats.
fn other_features(c: &Capabilities, e: &Capabilities) -> [FeatureRow; 7] {
    [
        (
            "pipeline statistics",
            c.pipeline_statistics_query,
            e.pipeline_statistics_query,
            "",
        ),
        (
            "timestamps",
            c.timestamps,
            c.timestamps,
            "GPU time per pass",
        ),
        (
            "tessellation shader",
            c.tessellation_shader,
            false,
            "not used on purpose",
        ),
        (
            "geometry shader",
            c.geometry_shader,
            false,
            "not used on purpose",
        ),
        ("mesh shader (EXT)", c.mesh_shader, false, ""),
        (
            "external memory host",
            c.external_memory_host,
            e.external_memory_host,
            "zero-copy ring publishing (GPU writes into the ring slot)",
        ),
        ("BC / ETC2 / ASTC", c.texture_compression_bc, false, ""),
    ]
}

/// The device limits that bound the renderer, and whether validation is on.
fn write_limits(s: &mut String, gpu: &Gpu) {
    let l = &gpu.info.limits;
    let _ = writeln!(
        s,
        "limits:        max 2D image {}, max framebuffer {}x{}, max anisotropy {}, timestamp period {} ns, max storage buffer {} MiB",
        l.max_image_dimension2_d,
        l.max_framebuffer_width,
        l.max_framebuffer_height,
        l.max_sampler_anisotropy,
        l.timestamp_period,
        l.max_storage_buffer_range >> 20
    );
    let _ = writeln!(
        s,
        "validation:    {}",
        if gpu.validation().is_some() {
            "on (with synchronization validation)"
        } else {
            "off"
        }
    );
}

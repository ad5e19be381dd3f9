//! Zero-copy publishing: every slot's pixel region imported as a GPU buffer
//! (`VK_EXT_external_memory_host`), so the readback copy writes the frame straight into the
//! ring. The seqlock marks the slot as being written from the moment the frame is recorded until
//! the GPU has finished it (docs/ring.md, "Zero-copy").

use std::sync::Arc;

use super::layout::Layout;
use super::sys::Mapping;
use crate::driver::Gpu;
use crate::driver::host_memory::HostBuffer;

/// Asks the producer to let `gpu` write frames into the slots.
#[derive(Clone)]
pub struct ZeroCopyRequest {
    pub gpu: Arc<Gpu>,
    /// The renderer's frames in flight: that many slots can be being written at once, so the
    /// ring needs more slots than that to always hold a complete newest frame.
    pub frames_in_flight: usize,
}

impl std::fmt::Debug for ZeroCopyRequest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZeroCopyRequest")
            .field("device", &self.gpu.info.name)
            .field("frames_in_flight", &self.frames_in_flight)
            .finish()
    }
}

/// The imported slots. Dropping waits for the GPU first: no frame may still be writing into the
/// mapping when the buffers and then the mapping go away.
pub(super) struct ZeroCopySlots {
    gpu: Arc<Gpu>,
    pub buffers: Vec<HostBuffer>,
}

impl Drop for ZeroCopySlots {
    fn drop(&mut self) {
        let _ = self.gpu.wait_idle();
    }
}

/// The byte range of slot `i`'s pixels that is imported: from the (aligned) pixel offset to the
/// next alignment boundary, which [`Layout::of`] keeps inside the slot.
fn pixel_range(layout: &Layout, i: u64) -> (u64, u64) {
    let g = layout.geometry;
    let start = layout.slot_offset(i) + layout.pixels_offset;
    let len = g.pixel_bytes().div_ceil(g.align as u64) * g.align as u64;
    (start, len)
}

/// Imports every slot of `map`, or says why zero-copy cannot be used (the caller falls back to
/// copying).
pub(super) fn import_slots(
    request: &ZeroCopyRequest,
    map: &Mapping,
    layout: &Layout,
) -> Result<ZeroCopySlots, String> {
    let g = layout.geometry;
    if g.slot_count as usize <= request.frames_in_flight {
        return Err(format!(
            "{} slots for {} frames in flight: zero-copy needs more slots than frames in flight",
            g.slot_count, request.frames_in_flight
        ));
    }
    let device_align = request.gpu.info.host_pointer_alignment;
    if device_align > g.align as u64 {
        return Err(format!(
            "the device needs {device_align}-byte aligned host memory, the ring has {}",
            g.align
        ));
    }
    let mut buffers = Vec::with_capacity(g.slot_count as usize);
    for i in 0..g.slot_count as u64 {
        let (start, len) = pixel_range(layout, i);
        if start + len > map.len() as u64 || start + len > layout.slot_offset(i) + layout.slot_size
        {
            return Err("the pixel range leaves its slot".into());
        }
        // SAFETY: `start..start + len` lies inside `map`, which the producer keeps alive longer
        // than these buffers (field order), and `ZeroCopySlots::drop` waits for the GPU first.
        let ptr = unsafe { map.ptr().add(start as usize) };
        let b = unsafe { HostBuffer::import(&request.gpu, &format!("ring slot {i}"), ptr, len) }
            .map_err(|e| e.to_string())?;
        buffers.push(b);
    }
    Ok(ZeroCopySlots {
        gpu: request.gpu.clone(),
        buffers,
    })
}

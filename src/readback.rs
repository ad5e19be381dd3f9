//! How a finished frame leaves the renderer: one small interface, [`FrameSink`].
//!
//! The renderer calls [`FrameSink::frame`] once per frame, in frame order, as soon as the GPU
//! has finished it, with a [`FrameView`] that borrows the mapped readback memory (no copy).
//! Sinks that need the pixels later copy them ([`OwnedFrame`]); the PNG writer and the
//! shared-memory ring are sinks.

use crate::error::Result;
use crate::scene::Camera;

/// GPU and CPU times of one frame, in milliseconds.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct FrameTimings {
    /// GPU time of the LOD prepass (compute), from timestamps.
    pub gpu_prepass_ms: f64,
    /// GPU time of the terrain pass (clear + draw), from timestamps.
    pub gpu_terrain_ms: f64,
    /// GPU time of the readback copy, from timestamps.
    pub gpu_readback_ms: f64,
    /// Host time to update, record and submit the frame.
    pub cpu_record_ms: f64,
    /// Host time blocked waiting for this frame's GPU work.
    pub cpu_wait_ms: f64,
}

impl FrameTimings {
    pub fn gpu_total_ms(&self) -> f64 {
        self.gpu_prepass_ms + self.gpu_terrain_ms + self.gpu_readback_ms
    }
}

/// A finished frame, borrowed from the readback buffer of its slot.
pub struct FrameView<'a> {
    pub index: u64,
    pub width: u32,
    pub height: u32,
    /// Bytes per row of `rgba` (rows are tightly packed: `4 * width`).
    pub row_stride: usize,
    /// sRGB-encoded RGBA8 pixels, row 0 at the top.
    pub rgba: &'a [u8],
    /// Reversed-Z depth (1 = near plane, 0 = far/sky) when depth readback is on.
    pub depth: Option<&'a [f32]>,
    pub camera: Camera,
    /// The camera on the earth, when the world frame is (`Renderer::world`).
    pub geo: Option<GeoFix>,
    pub timings: FrameTimings,
    /// Triangles submitted for this frame.
    pub triangles: u64,
    /// Tiles the LOD method wanted but its fixed budget could not hold, over the frame's
    /// views ([`crate::lod::LodMethod::budget_overflow`]; 0: none).
    pub budget_overflow: u64,
    /// Tiles the LOD method drew over the frame's views ([`crate::lod::LodMethod::tiles`],
    /// read once the frame completed; None: a method without tiles).
    pub tiles: Option<u64>,
}

/// A camera's WGS84 pose and the datum its height is measured from (the terrain's:
/// `output::ring::layout::DATUM_*`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeoFix {
    pub pose: crate::geo::GeoPose,
    pub height_datum: u32,
}

/// A buffer the GPU copies a frame's colour into directly instead of the renderer's readback
/// buffer (zero-copy sinks: a ring slot imported with `VK_EXT_external_memory_host`). The
/// renderer then delivers that frame with [`FrameView::rgba`] borrowing this memory.
#[derive(Clone, Copy, Debug)]
pub struct DirectTarget {
    /// A `TRANSFER_DST` buffer of at least the frame's `4 * width * height` bytes.
    pub buffer: ash::vk::Buffer,
    ptr: *const u8,
    len: usize,
}

impl DirectTarget {
    /// # Safety
    /// `buffer`'s memory must be the host range `ptr..ptr + len`, and that range must stay
    /// mapped until the frame it is handed out for has been delivered to the sink.
    pub unsafe fn new(buffer: ash::vk::Buffer, ptr: *const u8, len: usize) -> Self {
        DirectTarget { buffer, ptr, len }
    }

    /// The host view of the target (what the GPU wrote, once the frame is complete).
    pub fn host_bytes(&self) -> &[u8] {
        // SAFETY: valid while the frame is pending or being delivered (constructor contract).
        unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
    }

    pub fn host_ptr(&self) -> *const u8 {
        self.ptr
    }
}

/// Receives frames in order.
pub trait FrameSink {
    fn frame(&mut self, frame: &FrameView<'_>) -> Result<()>;

    /// Called once per frame, in frame order, before frame `index` (`bytes` colour bytes) is
    /// recorded: a sink may return a buffer for the GPU to write the colour into directly
    /// (zero-copy). Default: none, the frame comes from the renderer's readback buffer.
    fn direct_target(&mut self, _index: u64, _bytes: u64) -> Option<DirectTarget> {
        None
    }
}

impl<F: FnMut(&FrameView<'_>) -> Result<()>> FrameSink for F {
    fn frame(&mut self, frame: &FrameView<'_>) -> Result<()> {
        self(frame)
    }
}

/// An owned copy of a frame, e.g. to hand to another thread through a channel.
#[derive(Clone, Debug)]
pub struct OwnedFrame {
    pub index: u64,
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
    pub depth: Option<Vec<f32>>,
    pub camera: Camera,
    pub timings: FrameTimings,
    pub triangles: u64,
}

impl OwnedFrame {
    pub fn copy_of(frame: &FrameView<'_>) -> Self {
        OwnedFrame {
            index: frame.index,
            width: frame.width,
            height: frame.height,
            rgba: frame.rgba.to_vec(),
            depth: frame.depth.map(<[f32]>::to_vec),
            camera: frame.camera,
            timings: frame.timings,
            triangles: frame.triangles,
        }
    }

    /// RGBA of pixel `(x, y)` (y down from the top).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = (y as usize * self.width as usize + x as usize) * 4;
        [
            self.rgba[i],
            self.rgba[i + 1],
            self.rgba[i + 2],
            self.rgba[i + 3],
        ]
    }

    /// Reversed-Z depth of pixel `(x, y)`, if depth was read back.
    pub fn depth_at(&self, x: u32, y: u32) -> Option<f32> {
        self.depth
            .as_ref()
            .map(|d| d[y as usize * self.width as usize + x as usize])
    }
}

/// A sink that keeps a copy of every frame (tests, evaluation).
#[derive(Default)]
pub struct CollectSink {
    pub frames: Vec<OwnedFrame>,
}

impl FrameSink for CollectSink {
    fn frame(&mut self, frame: &FrameView<'_>) -> Result<()> {
        self.frames.push(OwnedFrame::copy_of(frame));
        Ok(())
    }
}

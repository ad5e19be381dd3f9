//! The producer side: creates the segment, publishes frames with the seqlock protocol, never
//! waits for a consumer, and marks the ring closed on shutdown.

use std::os::fd::OwnedFd;
use std::sync::atomic::{Ordering, fence};

use super::layout::{
    DEPTH_F32_REVERSED_Z, DEPTH_NONE, FORMAT_RGBA8_SRGB, FrameMeta, Geometry, LAYOUT_VERSION,
    MAGIC, NO_FRAME, PIXELS_OFFSET, RingHeader, STATE_CLOSED, STATE_LIVE, STATE_REPLACED,
    SlotHeader, validate_name,
};
use super::sys::{self, Mapping};
use crate::error::{Error, Result};
use crate::readback::{FrameSink, FrameView};

/// How the segment is created.
#[derive(Clone, Debug, Default)]
pub struct ProducerOptions {
    /// Group (id) allowed to read the ring: mode 0640 and this group; none: mode 0600.
    pub group: Option<u32>,
    /// Leave the segment (marked closed) under its name after shutdown.
    pub keep_segment: bool,
}

/// Publishes frames into a shared-memory ring; see `docs/ring.md` for the protocol.
pub struct RingProducer {
    name: String,
    geometry: Geometry,
    map: Mapping,
    fd: OwnedFd,
    keep: bool,
    next: u64,
    closed: bool,
    generation: u64,
}

fn io_err(what: &str, name: &str, e: std::io::Error) -> Error {
    Error::io(
        sys::shm_path(name),
        std::io::Error::new(e.kind(), format!("{what}: {e}")),
    )
}

impl RingProducer {
    /// Creates (or safely replaces) the segment `name`. A segment whose producer is still alive
    /// is refused; a stale one (crashed or closed producer) is replaced atomically and marked
    /// [`STATE_REPLACED`], which wakes its waiting consumers so they re-open the name.
    pub fn create(name: &str, geometry: Geometry, options: &ProducerOptions) -> Result<Self> {
        validate_name(name)?;
        geometry.validate()?;
        let own_pid = std::process::id();

        // An existing segment: refuse a live foreign producer, else remember it to retire it.
        let old = match sys::shm_open(name, libc::O_RDWR, 0) {
            Ok(fd) => {
                let (_, _, size) = sys::fstat(&fd).map_err(|e| io_err("stat", name, e))?;
                if size >= size_of::<RingHeader>() as u64 {
                    let map = Mapping::new(&fd, size_of::<RingHeader>(), true)
                        .map_err(|e| io_err("mmap", name, e))?;
                    // SAFETY: the mapping is at least one header long and page aligned.
                    let h = unsafe { &*(map.ptr() as *const RingHeader) };
                    let pid = h.producer_pid;
                    if h.magic == MAGIC
                        && h.state.load(Ordering::Acquire) == STATE_LIVE
                        && pid != own_pid
                        && sys::pid_alive(pid)
                    {
                        return Err(Error::invalid(
                            "ring name",
                            format!("{name:?} is in use by a live producer (pid {pid})"),
                        ));
                    }
                    Some((map, h.magic == MAGIC, h.generation))
                } else {
                    None
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(io_err("open existing segment", name, e)),
        };
        let old_generation = old.as_ref().filter(|o| o.1).map(|o| o.2).unwrap_or(0);

        // Build the new segment under a temporary name, then rename it over `name`: consumers
        // never see a half-initialised header.
        let tmp = format!("{name}.new{own_pid}");
        let _ = sys::shm_unlink(&tmp);
        let mode = if options.group.is_some() {
            0o640
        } else {
            0o600
        };
        let fd = sys::shm_open(&tmp, libc::O_RDWR | libc::O_CREAT | libc::O_EXCL, mode)
            .map_err(|e| io_err("create", &tmp, e))?;
        let cleanup = |e: Error| {
            let _ = sys::shm_unlink(&tmp);
            e
        };
        // The umask can only remove bits; set the exact mode (never world-accessible).
        sys::fchmod(&fd, mode).map_err(|e| cleanup(io_err("chmod", &tmp, e)))?;
        if let Some(gid) = options.group {
            sys::fchown_group(&fd, gid).map_err(|e| cleanup(io_err("chown", &tmp, e)))?;
        }
        let size = geometry.segment_size();
        sys::ftruncate(&fd, size).map_err(|e| cleanup(io_err("resize", &tmp, e)))?;
        let map =
            Mapping::new(&fd, size as usize, true).map_err(|e| cleanup(io_err("mmap", &tmp, e)))?;
        let generation = sys::realtime_ns().max(old_generation + 1);
        // SAFETY: fresh zero-filled mapping of the full segment, page aligned; nobody else has
        // it yet.
        unsafe {
            let h = &mut *(map.ptr() as *mut RingHeader);
            h.magic = MAGIC;
            h.layout_version = LAYOUT_VERSION;
            h.header_size = size_of::<RingHeader>() as u32;
            h.generation = generation;
            h.width = geometry.width;
            h.height = geometry.height;
            h.pixel_format = FORMAT_RGBA8_SRGB;
            h.row_stride = geometry.row_stride();
            h.slot_count = geometry.slot_count;
            h.depth_format = if geometry.depth {
                DEPTH_F32_REVERSED_Z
            } else {
                DEPTH_NONE
            };
            h.slot_size = geometry.slot_size() as u32;
            h.pixels_offset = PIXELS_OFFSET as u32;
            h.depth_offset = geometry.depth_offset() as u32;
            h.producer_pid = own_pid;
            h.latest.store(NO_FRAME, Ordering::Relaxed);
            h.state.store(STATE_LIVE, Ordering::Release);
        }
        let from = sys::shm_path(&tmp);
        let to = sys::shm_path(name);
        std::fs::rename(&from, &to).map_err(|e| cleanup(Error::io(&to, e)))?;

        if let Some((old_map, true, _)) = old {
            // SAFETY: header-sized mapping of the old segment.
            let h = unsafe { &*(old_map.ptr() as *const RingHeader) };
            h.state.store(STATE_REPLACED, Ordering::Release);
            h.wake.fetch_add(1, Ordering::Release);
            sys::futex_wake_all(&h.wake);
        }
        tracing::info!(name, generation, size, "ring created");
        Ok(RingProducer {
            name: name.to_string(),
            geometry,
            map,
            fd,
            keep: options.keep_segment,
            next: 0,
            closed: false,
            generation,
        })
    }

    pub fn name(&self) -> &str {
        &self.name
    }
    pub fn geometry(&self) -> Geometry {
        self.geometry
    }
    pub fn generation(&self) -> u64 {
        self.generation
    }
    /// Frames published so far.
    pub fn published(&self) -> u64 {
        self.next
    }

    fn header(&self) -> &RingHeader {
        // SAFETY: the mapping starts with an initialised header.
        unsafe { &*(self.map.ptr() as *const RingHeader) }
    }

    fn slot_ptr(&self, frame: u64) -> *mut u8 {
        let i = frame % self.geometry.slot_count as u64;
        let off = size_of::<RingHeader>() as u64 + i * self.geometry.slot_size();
        // SAFETY: `off` is inside the mapping (i < slot_count).
        unsafe { self.map.ptr().add(off as usize) }
    }

    /// Publishes one frame: `pixels` must be `row_stride * height` bytes, `depth` (when the
    /// ring has depth) `width * height` floats. `meta.frame` and `publish_ns` are filled in.
    /// Never blocks on consumers.
    pub fn publish(
        &mut self,
        meta: &FrameMeta,
        pixels: &[u8],
        depth: Option<&[f32]>,
    ) -> Result<u64> {
        if self.closed {
            return Err(Error::invalid("ring", "publish after close"));
        }
        let g = self.geometry;
        if pixels.len() as u64 != g.pixel_bytes()
            || meta.width != g.width
            || meta.height != g.height
        {
            return Err(Error::invalid(
                "ring frame",
                format!(
                    "{}x{} ({} bytes) does not match the ring's {}x{}",
                    meta.width,
                    meta.height,
                    pixels.len(),
                    g.width,
                    g.height
                ),
            ));
        }
        let depth = match (g.depth, depth) {
            (true, Some(d)) if d.len() as u64 == g.width as u64 * g.height as u64 => Some(d),
            (true, _) => {
                return Err(Error::invalid(
                    "ring frame",
                    "the ring expects depth of the frame's size",
                ));
            }
            (false, _) => None,
        };
        let n = self.next;
        let slot = self.slot_ptr(n);
        // SAFETY: `slot` points at a SlotHeader inside our mapping.
        let sh = unsafe { &*(slot as *const SlotHeader) };
        // Seqlock write: odd first, a release fence so that no data write below becomes
        // visible before the odd value, then the data, then the even value with release.
        sh.seq.store(2 * n + 1, Ordering::Relaxed);
        fence(Ordering::Release);
        let mut m = *meta;
        m.frame = n;
        m.row_stride = g.row_stride();
        // SAFETY: meta, pixels and depth regions lie inside this slot (see Geometry); readers
        // only ever copy these bytes and discard the copy unless `seq` is unchanged.
        unsafe {
            let meta_ptr = slot.add(std::mem::offset_of!(SlotHeader, meta)) as *mut FrameMeta;
            std::ptr::copy_nonoverlapping(pixels.as_ptr(), slot.add(PIXELS_OFFSET), pixels.len());
            if let Some(d) = depth {
                std::ptr::copy_nonoverlapping(
                    d.as_ptr().cast::<u8>(),
                    slot.add(g.depth_offset() as usize),
                    d.len() * 4,
                );
            }
            m.publish_ns = sys::monotonic_ns();
            std::ptr::write_volatile(meta_ptr, m);
        }
        sh.seq.store(2 * n + 2, Ordering::Release);
        let h = self.header();
        h.latest.store(n, Ordering::Release);
        h.published.store(n + 1, Ordering::Release);
        h.wake.fetch_add(1, Ordering::Release);
        sys::futex_wake_all(&h.wake);
        self.next = n + 1;
        Ok(n)
    }

    /// Marks the ring closed and wakes every consumer; removes the name unless configured to
    /// keep it (and only if the name still refers to this segment).
    pub fn close(&mut self) {
        if self.closed {
            return;
        }
        self.closed = true;
        let h = self.header();
        // A newer producer may have replaced us already: leave its state alone.
        let _ = h.state.compare_exchange(
            STATE_LIVE,
            STATE_CLOSED,
            Ordering::AcqRel,
            Ordering::Acquire,
        );
        h.wake.fetch_add(1, Ordering::Release);
        sys::futex_wake_all(&h.wake);
        if !self.keep && self.name_is_ours() {
            let _ = sys::shm_unlink(&self.name);
        }
        tracing::info!(name = self.name, frames = self.next, "ring closed");
    }

    /// Whether `/dev/shm/<name>` is still this segment.
    fn name_is_ours(&self) -> bool {
        use std::os::unix::fs::MetadataExt;
        match (
            sys::fstat(&self.fd),
            std::fs::metadata(sys::shm_path(&self.name)),
        ) {
            (Ok((dev, ino, _)), Ok(m)) => m.dev() == dev && m.ino() == ino,
            _ => false,
        }
    }
}

impl Drop for RingProducer {
    fn drop(&mut self) {
        self.close();
    }
}

/// Metadata of a rendered frame as the ring stores it.
pub fn meta_of(frame: &FrameView<'_>, capture_ns: u64) -> FrameMeta {
    let c = &frame.camera;
    let f = c.focal_px(frame.height);
    let t = &frame.timings;
    FrameMeta {
        frame: frame.index,
        capture_ns,
        publish_ns: 0,
        width: frame.width,
        height: frame.height,
        row_stride: frame.row_stride as u32,
        _reserved0: 0,
        position: c.position.to_array(),
        yaw_deg: c.yaw_deg,
        pitch_deg: c.pitch_deg,
        roll_deg: c.roll_deg,
        vfov_deg: c.vfov_deg,
        near: c.near,
        far: c.far,
        fx: f,
        fy: f,
        cx: frame.width as f64 / 2.0,
        cy: frame.height as f64 / 2.0,
        gpu_prepass_ms: t.gpu_prepass_ms,
        gpu_terrain_ms: t.gpu_terrain_ms,
        gpu_readback_ms: t.gpu_readback_ms,
        cpu_record_ms: t.cpu_record_ms,
        cpu_wait_ms: t.cpu_wait_ms,
        triangles: frame.triangles,
    }
}

impl FrameSink for RingProducer {
    fn frame(&mut self, frame: &FrameView<'_>) -> Result<()> {
        let meta = meta_of(frame, sys::monotonic_ns());
        self.publish(&meta, frame.rgba, frame.depth)?;
        Ok(())
    }
}

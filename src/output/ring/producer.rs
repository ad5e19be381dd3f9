//! The producer side: creates the segment, publishes frames with the seqlock protocol, never
//! waits for a consumer, and marks the ring closed on shutdown.

use std::collections::VecDeque;
use std::os::fd::OwnedFd;
use std::sync::atomic::{Ordering, fence};

use super::layout::{
    DEPTH_F32_REVERSED_Z, DEPTH_NONE, FLAG_ZERO_COPY, FORMAT_RGBA8_SRGB, FrameMeta, Geometry,
    LAYOUT_VERSION, Layout, MAGIC, NO_FRAME, RingHeader, STATE_CLOSED, STATE_LIVE, STATE_REPLACED,
    SlotHeader,
};
use super::location::{RingLocation, prepare_dir};
use super::sys::{self, Mapping};
use super::zero_copy::{ZeroCopyRequest, ZeroCopySlots, import_slots};
use crate::error::{Error, Result};
use crate::output::lock::PathLock;
use crate::readback::{DirectTarget, FrameSink, FrameView};

/// How the segment is created.
#[derive(Clone, Debug, Default)]
pub struct ProducerOptions {
    /// Group (id) allowed to read the ring: mode 0640 and this group; none: mode 0600.
    pub group: Option<u32>,
    /// Leave the segment (marked closed) under its name after shutdown.
    pub keep_segment: bool,
    /// Let this GPU write frames straight into the slots, where it can (else: copy).
    pub zero_copy: Option<ZeroCopyRequest>,
}

/// A frame number handed out before the frame is delivered (zero-copy sinks number frames when
/// they are recorded).
struct Reservation {
    /// The renderer's frame index.
    index: u64,
    /// The ring's frame number.
    n: u64,
    /// The GPU writes the pixels into the slot (it is already marked as being written).
    direct: bool,
}

/// Publishes frames into a shared-memory ring; see `docs/ring.md` for the protocol.
pub struct RingProducer {
    location: RingLocation,
    layout: Layout,
    /// Declared before `map`: dropped (after waiting for the GPU) while the mapping still exists.
    zero_copy: Option<ZeroCopySlots>,
    /// Why zero-copy was requested but is not in use.
    zero_copy_note: Option<String>,
    reserved: VecDeque<Reservation>,
    map: Mapping,
    /// The segment, holding the write lock that tells readers a producer is alive.
    fd: OwnedFd,
    keep: bool,
    next: u64,
    closed: bool,
    generation: u64,
    /// The ring name, ours while we live (removed last, after the segment).
    /// Taken over by the producer that [`RingProducer::replace`]s this one.
    name_lock: Option<PathLock>,
}

fn io_err(what: &str, path: &std::path::Path, e: std::io::Error) -> Error {
    Error::io(path, std::io::Error::new(e.kind(), format!("{what}: {e}")))
}

/// A previous segment under the name (crashed or closed producer), to be marked replaced.
/// The ring's slots imported as GPU memory where `options` ask for zero-copy and the device
/// can (else None and why, logged: frames are copied instead).
fn zero_copy_slots(
    options: &ProducerOptions,
    map: &Mapping,
    layout: &Layout,
    location: &RingLocation,
) -> (Option<ZeroCopySlots>, Option<String>) {
    let Some(request) = &options.zero_copy else {
        return (None, None);
    };
    match import_slots(request, map, layout) {
        Ok(slots) => (Some(slots), None),
        Err(reason) => {
            tracing::warn!(ring = %location, "zero-copy off, copying frames: {reason}");
            (None, Some(reason))
        }
    }
}

/// Tells the readers of the old segment (`old_map`, its header mapped) that a new one
/// replaced it, and wakes those waiting.
fn mark_replaced(old_map: &Mapping) {
    // SAFETY: header-sized mapping of the old segment.
    let h = unsafe { &*(old_map.ptr() as *const RingHeader) };
    h.state.store(STATE_REPLACED, Ordering::Release);
    h.wake.fetch_add(1, Ordering::Release);
    sys::futex_wake_all(&h.wake);
}

fn previous_segment(path: &std::path::Path) -> Result<Option<(Mapping, u64)>> {
    let fd = match sys::open(path, libc::O_RDWR, 0) {
        Ok(fd) => fd,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io_err("open existing segment", path, e)),
    };
    let st = sys::fstat(&fd).map_err(|e| io_err("stat", path, e))?;
    if st.st_mode & libc::S_IFMT != libc::S_IFREG
        || (st.st_size as u64) < size_of::<RingHeader>() as u64
    {
        return Ok(None);
    }
    let map =
        Mapping::new(&fd, size_of::<RingHeader>(), true).map_err(|e| io_err("mmap", path, e))?;
    // SAFETY: the mapping is one header long and page aligned.
    let h = unsafe { &*(map.ptr() as *const RingHeader) };
    if h.magic != MAGIC {
        return Ok(None);
    }
    let generation = h.generation;
    Ok(Some((map, generation)))
}

impl RingProducer {
    /// Creates the ring `location` (or replaces a stale one). The directory must be ours and
    /// writable by nobody else ([`prepare_dir`]); the name is ours while we live (an exclusive
    /// lock, so of two producers started at once exactly one runs, and a crashed one never
    /// blocks its successor). The segment is built under a temporary name and renamed over the
    /// name, so readers never see a half-written header; a previous segment is marked
    /// [`STATE_REPLACED`], which wakes its consumers so they re-open the name.
    pub fn create(
        location: &RingLocation,
        geometry: Geometry,
        options: &ProducerOptions,
    ) -> Result<Self> {
        geometry.validate()?;
        let dir = prepare_dir(&location.dir, options.group)?;
        let location = RingLocation::new(dir, &location.name)?;
        let name_lock =
            PathLock::acquire(&location.lock_path(), &format!("ring {:?}", location.name))?;
        Self::build(location, geometry, options, name_lock)
    }

    /// A new generation of this ring with another geometry (a resolution change): the name
    /// stays ours throughout; this segment is marked replaced, so its readers re-open the name.
    /// Deliver every frame in flight first.
    pub fn replace(&mut self, geometry: Geometry, options: &ProducerOptions) -> Result<()> {
        geometry.validate()?;
        let lock = self
            .name_lock
            .take()
            .ok_or_else(|| Error::invalid("ring", "lost its name"))?;
        let fresh = Self::build(self.location.clone(), geometry, options, lock)?;
        // The old segment (already marked replaced) closes without touching the name.
        drop(std::mem::replace(self, fresh));
        Ok(())
    }

    /// Creates the segment of a ring whose name we hold.
    fn build(
        location: RingLocation,
        geometry: Geometry,
        options: &ProducerOptions,
        name_lock: PathLock,
    ) -> Result<Self> {
        let path = location.segment_path();
        let old = previous_segment(&path)?;
        let old_generation = old.as_ref().map(|o| o.1).unwrap_or(0);

        let tmp = location.temp_path();
        let _ = std::fs::remove_file(&tmp);
        let fd = sys::open(&tmp, libc::O_RDWR | libc::O_CREAT | libc::O_EXCL, 0o600)
            .map_err(|e| io_err("create", &tmp, e))?;
        let cleanup = |e: Error| {
            let _ = std::fs::remove_file(&tmp);
            e
        };
        // Liveness for readers: held until we exit, taken while only we can open the file.
        if !sys::ofd_try_lock(&fd, libc::F_WRLCK).map_err(|e| cleanup(io_err("lock", &tmp, e)))? {
            return Err(cleanup(Error::invalid(
                "ring",
                "cannot lock a fresh segment",
            )));
        }
        let mode = if options.group.is_some() {
            0o640
        } else {
            0o600
        };
        if let Some(gid) = options.group {
            sys::fchown_group(&fd, gid).map_err(|e| cleanup(io_err("chown", &tmp, e)))?;
        }
        let layout = Layout::of(geometry);
        let size = layout.segment_size();
        sys::ftruncate(&fd, size).map_err(|e| cleanup(io_err("resize", &tmp, e)))?;
        let map =
            Mapping::new(&fd, size as usize, true).map_err(|e| cleanup(io_err("mmap", &tmp, e)))?;
        let generation = sys::realtime_ns().max(old_generation + 1);
        let (zero_copy, zero_copy_note) = zero_copy_slots(options, &map, &layout, &location);
        let flags = if zero_copy.is_some() {
            FLAG_ZERO_COPY
        } else {
            0
        };
        write_header(&map, &layout, generation, flags);
        // The umask can only remove bits; set the exact mode (never world-accessible).
        sys::fchmod(&fd, mode).map_err(|e| cleanup(io_err("chmod", &tmp, e)))?;
        std::fs::rename(&tmp, &path).map_err(|e| cleanup(Error::io(&path, e)))?;

        if let Some((old_map, _)) = old {
            mark_replaced(&old_map);
        }
        tracing::info!(ring = %location, generation, size, "ring created");
        Ok(RingProducer {
            location,
            layout,
            zero_copy,
            zero_copy_note,
            reserved: VecDeque::new(),
            map,
            fd,
            keep: options.keep_segment,
            next: 0,
            closed: false,
            generation,
            name_lock: Some(name_lock),
        })
    }

    pub fn name(&self) -> &str {
        &self.location.name
    }
    pub fn location(&self) -> &RingLocation {
        &self.location
    }
    pub fn geometry(&self) -> Geometry {
        self.layout.geometry
    }
    pub fn layout(&self) -> Layout {
        self.layout
    }
    pub fn generation(&self) -> u64 {
        self.generation
    }
    /// Frames published so far.
    pub fn published(&self) -> u64 {
        self.next
    }
    /// Whether the GPU writes frames straight into the slots.
    pub fn zero_copy(&self) -> bool {
        self.zero_copy.is_some()
    }
    /// Why zero-copy was asked for but is not in use.
    pub fn zero_copy_note(&self) -> Option<&str> {
        self.zero_copy_note.as_deref()
    }

    fn pixels_ptr(&self, frame: u64) -> *mut u8 {
        // SAFETY: the pixel region lies inside the slot (Layout).
        unsafe { self.slot_ptr(frame).add(self.layout.pixels_offset as usize) }
    }

    fn header(&self) -> &RingHeader {
        // SAFETY: the mapping starts with an initialised header.
        unsafe { &*(self.map.ptr() as *const RingHeader) }
    }

    fn slot_ptr(&self, frame: u64) -> *mut u8 {
        // SAFETY: `slot_offset` is inside the mapping (frame % slot_count < slot_count).
        unsafe { self.map.ptr().add(self.layout.slot_offset(frame) as usize) }
    }

    fn slot_header(&self, frame: u64) -> &SlotHeader {
        // SAFETY: a SlotHeader at the start of a slot inside our mapping.
        unsafe { &*(self.slot_ptr(frame) as *const SlotHeader) }
    }

    /// Seqlock write, first half: marks the slot of frame `n` as being written (odd), with a
    /// release fence so that no write of the frame becomes visible before the odd value.
    fn begin_slot(&self, n: u64) {
        self.slot_header(n).seq.store(2 * n + 1, Ordering::Relaxed);
        fence(Ordering::Release);
    }

    /// Seqlock write, second half: metadata, the even value (release), then `latest`, the
    /// counter and the wake-up of every waiting consumer.
    fn end_slot(&mut self, n: u64, meta: &FrameMeta) {
        let g = self.layout.geometry;
        let mut m = *meta;
        m.frame = n;
        m.width = g.width;
        m.height = g.height;
        m.row_stride = g.row_stride();
        m.publish_ns = sys::monotonic_ns();
        let slot = self.slot_ptr(n);
        // SAFETY: the metadata lies inside this slot; readers copy it and discard the copy
        // unless `seq` is unchanged.
        unsafe {
            let meta_ptr = slot.add(std::mem::offset_of!(SlotHeader, meta)) as *mut FrameMeta;
            std::ptr::write_volatile(meta_ptr, m);
        }
        self.slot_header(n).seq.store(2 * n + 2, Ordering::Release);
        let h = self.header();
        h.latest.store(n, Ordering::Release);
        h.published.store(n + 1, Ordering::Release);
        h.wake.fetch_add(1, Ordering::Release);
        sys::futex_wake_all(&h.wake);
        self.next = n + 1;
    }

    fn check_frame(&self, meta: &FrameMeta, pixels: usize, depth: Option<&[f32]>) -> Result<()> {
        if self.closed {
            return Err(Error::invalid("ring", "publish after close"));
        }
        let g = self.layout.geometry;
        if pixels as u64 != g.pixel_bytes() || meta.width != g.width || meta.height != g.height {
            return Err(Error::invalid(
                "ring frame",
                format!(
                    "{}x{} ({} bytes) does not match the ring's {}x{}",
                    meta.width, meta.height, pixels, g.width, g.height
                ),
            ));
        }
        match (g.depth, depth) {
            (true, Some(d)) if d.len() as u64 == g.width as u64 * g.height as u64 => Ok(()),
            (true, _) => Err(Error::invalid(
                "ring frame",
                "the ring expects depth of the frame's size",
            )),
            (false, _) => Ok(()),
        }
    }

    fn copy_depth(&self, n: u64, depth: Option<&[f32]>) {
        if let (true, Some(d)) = (self.layout.geometry.depth, depth) {
            // SAFETY: the depth region lies inside the slot (Layout); the slot is odd.
            unsafe {
                std::ptr::copy_nonoverlapping(
                    d.as_ptr().cast::<u8>(),
                    self.slot_ptr(n).add(self.layout.depth_offset as usize),
                    d.len() * 4,
                );
            }
        }
    }

    /// Publishes one frame by copying it into its slot: `pixels` must be `row_stride * height`
    /// bytes, `depth` (when the ring has depth) `width * height` floats. `meta.frame` and
    /// `publish_ns` are filled in. Never blocks on consumers.
    pub fn publish(
        &mut self,
        meta: &FrameMeta,
        pixels: &[u8],
        depth: Option<&[f32]>,
    ) -> Result<u64> {
        self.check_frame(meta, pixels.len(), depth)?;
        if !self.reserved.is_empty() {
            return Err(Error::invalid(
                "ring",
                "publish while reserved (zero-copy) frames are pending",
            ));
        }
        let n = self.next;
        self.begin_slot(n);
        // SAFETY: the pixel region lies inside the slot (Layout); readers only copy these bytes
        // and discard the copy unless `seq` is unchanged.
        unsafe { std::ptr::copy_nonoverlapping(pixels.as_ptr(), self.pixels_ptr(n), pixels.len()) };
        self.copy_depth(n, depth);
        self.end_slot(n, meta);
        Ok(n)
    }

    /// Completes a frame numbered when it was recorded: the GPU already wrote the pixels into
    /// the slot (direct), or they are copied now.
    fn complete(&mut self, r: Reservation, frame: &FrameView<'_>) -> Result<()> {
        let meta = meta_of(frame, sys::monotonic_ns());
        self.check_frame(&meta, frame.rgba.len(), frame.depth)?;
        debug_assert_eq!(r.n, self.next);
        let in_place = r.direct && std::ptr::eq(frame.rgba.as_ptr(), self.pixels_ptr(r.n));
        if !r.direct {
            self.begin_slot(r.n);
        }
        if !in_place {
            // SAFETY: as in `publish`; the slot is marked as being written.
            unsafe {
                std::ptr::copy_nonoverlapping(
                    frame.rgba.as_ptr(),
                    self.pixels_ptr(r.n),
                    frame.rgba.len(),
                )
            };
        }
        self.copy_depth(r.n, frame.depth);
        self.end_slot(r.n, &meta);
        Ok(())
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
        let path = self.location.segment_path();
        if !self.keep && sys::same_file(&self.fd, &path) {
            let _ = std::fs::remove_file(&path);
        }
        tracing::info!(ring = %self.location, frames = self.next, "ring closed");
    }
}

/// Writes the header of a fresh (zero-filled, unnamed) segment.
fn write_header(map: &Mapping, layout: &Layout, generation: u64, flags: u32) {
    let g = layout.geometry;
    // SAFETY: fresh zero-filled mapping of the full segment, page aligned; nobody else has it.
    let h = unsafe { &mut *(map.ptr() as *mut RingHeader) };
    h.magic = MAGIC;
    h.layout_version = LAYOUT_VERSION;
    h.header_size = layout.header_size as u32;
    h.generation = generation;
    h.width = g.width;
    h.height = g.height;
    h.pixel_format = FORMAT_RGBA8_SRGB;
    h.row_stride = g.row_stride();
    h.slot_count = g.slot_count;
    h.depth_format = if g.depth {
        DEPTH_F32_REVERSED_Z
    } else {
        DEPTH_NONE
    };
    h.slot_size = layout.slot_size as u32;
    h.pixels_offset = layout.pixels_offset as u32;
    h.depth_offset = layout.depth_offset as u32;
    h.producer_pid = std::process::id();
    h.flags = flags;
    h.latest.store(NO_FRAME, Ordering::Relaxed);
    h.state.store(STATE_LIVE, Ordering::Release);
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
        height_datum: frame
            .geo
            .map_or(super::layout::DATUM_NONE, |g| g.height_datum),
        _reserved1: 0,
        lat_deg: frame.geo.map_or(f64::NAN, |g| g.pose.lat_deg),
        lon_deg: frame.geo.map_or(f64::NAN, |g| g.pose.lon_deg),
        height_m: frame.geo.map_or(f64::NAN, |g| g.pose.height_m),
        heading_deg: frame.geo.map_or(f64::NAN, |g| g.pose.heading_deg),
        local_pitch_deg: frame.geo.map_or(f64::NAN, |g| g.pose.pitch_deg),
        local_roll_deg: frame.geo.map_or(f64::NAN, |g| g.pose.roll_deg),
        _reserved2: 0,
    }
}

impl FrameSink for RingProducer {
    fn frame(&mut self, frame: &FrameView<'_>) -> Result<()> {
        match self.reserved.pop_front() {
            Some(r) if r.index == frame.index => self.complete(r, frame),
            Some(r) => Err(Error::invalid(
                "ring",
                format!(
                    "frame {} delivered while frame {} was recorded first",
                    frame.index, r.index
                ),
            )),
            None => {
                let meta = meta_of(frame, sys::monotonic_ns());
                self.publish(&meta, frame.rgba, frame.depth).map(|_| ())
            }
        }
    }

    /// With zero-copy on: numbers frame `index` now and, while fewer than `slot_count - 1`
    /// frames are pending (so the newest complete frame is never the one being overwritten),
    /// marks its slot as being written and hands the GPU the slot's imported buffer.
    fn direct_target(&mut self, index: u64, bytes: u64) -> Option<DirectTarget> {
        let zc = self.zero_copy.as_ref()?;
        let g = self.layout.geometry;
        let n = self.next + self.reserved.len() as u64;
        let direct = !self.closed
            && bytes == g.pixel_bytes()
            && (self.reserved.len() as u32 + 1) < g.slot_count;
        let buffer = zc.buffers[(n % g.slot_count as u64) as usize].raw;
        self.reserved.push_back(Reservation { index, n, direct });
        if !direct {
            return None;
        }
        self.begin_slot(n);
        // The odd value is visible to every CPU before the GPU is even given the work.
        fence(Ordering::SeqCst);
        // SAFETY: the buffer is the slot's imported pixel range, mapped as long as we live;
        // the renderer delivers the frame to us (or we are dropped after waiting for the GPU).
        Some(unsafe { DirectTarget::new(buffer, self.pixels_ptr(n), bytes as usize) })
    }
}

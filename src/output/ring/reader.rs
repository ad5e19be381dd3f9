//! The Rust consumer API: open a ring read-only, block until a new frame (futex, with a
//! timeout), copy it with seqlock verification or look at it in place, count what was missed,
//! and follow producer restarts.

use std::os::fd::OwnedFd;
use std::os::unix::fs::MetadataExt;
use std::sync::atomic::{Ordering, fence};
use std::time::{Duration, Instant};

use super::layout::{
    FrameMeta, Geometry, LAYOUT_VERSION, MAGIC, NO_FRAME, PIXELS_OFFSET, RingHeader, STATE_CLOSED,
    STATE_LIVE, SlotHeader, validate_name,
};
use super::sys::{self, Mapping};
use crate::error::{Error, Result};

/// How often a waiting reader checks whether the name now refers to a new segment (a producer
/// that crashed and was restarted without anyone marking the old segment).
const REOPEN_POLL: Duration = Duration::from_millis(100);

/// What [`RingReader::wait_next`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Next {
    /// A frame newer than the last one returned; its pixels are in [`RingReader::pixels`].
    Frame(FrameMeta),
    /// No new frame within the timeout.
    Timeout,
    /// The producer shut down (and no newer one has appeared yet).
    Closed,
    /// A new producer generation was mapped; frame numbers start again.
    Restarted { generation: u64 },
}

/// Counters of one reader.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ReaderStats {
    /// Frames accepted (copied and verified).
    pub received: u64,
    /// Frames skipped between accepted ones (counted within a generation).
    pub lost: u64,
    /// Copies discarded because the producer overwrote the slot meanwhile.
    pub torn_retries: u64,
    /// New generations followed.
    pub restarts: u64,
}

/// A read-only view of one ring segment.
pub struct RingReader {
    name: String,
    map: Mapping,
    fd: OwnedFd,
    geometry: Geometry,
    generation: u64,
    slot_size: u64,
    depth_offset: u64,
    last: Option<u64>,
    pixels: Vec<u8>,
    depth: Vec<f32>,
    stats: ReaderStats,
    /// Copy pixels in `wait_next` (default true); off: only metadata is verified and the
    /// pixels are read in place with [`RingReader::view`].
    pub copy_pixels: bool,
}

/// A zero-copy look at a complete frame inside the ring. The producer may overwrite the slot at
/// any time; check [`FrameRef::is_valid`] after using the pixels and discard the result if it
/// turned false.
pub struct FrameRef<'a> {
    pub meta: FrameMeta,
    seq: u64,
    slot: &'a SlotHeader,
    pixels: *const u8,
    len: usize,
}

impl FrameRef<'_> {
    /// The frame's pixels in place (`row_stride * height` bytes).
    pub fn pixels(&self) -> &[u8] {
        // SAFETY: the range lies inside the reader's mapping, which outlives `self`. Bytes may
        // change under us (another process writes them); any bit pattern is a valid u8.
        unsafe { std::slice::from_raw_parts(self.pixels, self.len) }
    }
    /// True while the slot still holds this frame (call after reading the pixels).
    pub fn is_valid(&self) -> bool {
        fence(Ordering::Acquire);
        self.slot.seq.load(Ordering::Relaxed) == self.seq
    }
}

enum Read {
    Ok(FrameMeta),
    /// The slot is being written or was overwritten during the copy.
    Torn,
    /// The slot holds nothing yet.
    Empty,
}

impl RingReader {
    /// Opens `name` read-only and checks its header.
    pub fn open(name: &str) -> Result<Self> {
        validate_name(name)?;
        let path = sys::shm_path(name);
        let fd = sys::shm_open(name, libc::O_RDONLY, 0).map_err(|e| Error::io(&path, e))?;
        let (_, _, size) = sys::fstat(&fd).map_err(|e| Error::io(&path, e))?;
        let bad = |m: String| Error::invalid("ring segment", format!("{}: {m}", path.display()));
        if size < size_of::<RingHeader>() as u64 {
            return Err(bad(format!("{size} bytes is smaller than a header")));
        }
        let map = Mapping::new(&fd, size as usize, false).map_err(|e| Error::io(&path, e))?;
        // SAFETY: at least a header long, page aligned; the constant line never changes after
        // the segment got its name.
        let h = unsafe { &*(map.ptr() as *const RingHeader) };
        if h.magic != MAGIC {
            return Err(bad("not a vkterrain ring (bad magic)".into()));
        }
        if h.layout_version != LAYOUT_VERSION || h.header_size as usize != size_of::<RingHeader>() {
            return Err(bad(format!(
                "layout version {} (header {} bytes) is not the supported {LAYOUT_VERSION}",
                h.layout_version, h.header_size
            )));
        }
        let geometry = Geometry {
            width: h.width,
            height: h.height,
            slot_count: h.slot_count,
            depth: h.depth_format != 0,
        };
        geometry.validate().map_err(|e| bad(e.to_string()))?;
        if geometry.segment_size() > size
            || h.slot_size as u64 != geometry.slot_size()
            || h.pixels_offset as usize != PIXELS_OFFSET
            || h.depth_offset as u64 != geometry.depth_offset()
            || h.row_stride != geometry.row_stride()
        {
            return Err(bad("header geometry does not match the segment".into()));
        }
        let mut r = RingReader {
            name: name.to_string(),
            generation: h.generation,
            slot_size: h.slot_size as u64,
            depth_offset: h.depth_offset as u64,
            map,
            fd,
            geometry,
            last: None,
            pixels: Vec::new(),
            depth: Vec::new(),
            stats: ReaderStats::default(),
            copy_pixels: true,
        };
        r.pixels.resize(geometry.pixel_bytes() as usize, 0);
        if geometry.depth {
            r.depth
                .resize(geometry.width as usize * geometry.height as usize, 0.0);
        }
        Ok(r)
    }

    /// Opens `name`, retrying until it exists or `timeout` passes.
    pub fn open_wait(name: &str, timeout: Duration) -> Result<Self> {
        let deadline = Instant::now() + timeout;
        loop {
            match Self::open(name) {
                Ok(r) => return Ok(r),
                Err(e) if Instant::now() >= deadline => return Err(e),
                Err(_) => std::thread::sleep(Duration::from_millis(10)),
            }
        }
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
    pub fn stats(&self) -> ReaderStats {
        self.stats
    }
    /// Pixels of the frame last returned by [`wait_next`](Self::wait_next) (when copying).
    pub fn pixels(&self) -> &[u8] {
        &self.pixels
    }
    /// Depth of the frame last returned, if the ring carries depth.
    pub fn depth(&self) -> Option<&[f32]> {
        self.geometry.depth.then_some(&self.depth[..])
    }

    fn header(&self) -> &RingHeader {
        // SAFETY: checked in `open`.
        unsafe { &*(self.map.ptr() as *const RingHeader) }
    }

    /// The producer's state word (live, closed, replaced).
    pub fn state(&self) -> u32 {
        self.header().state.load(Ordering::Acquire)
    }

    /// The newest published frame number, if any.
    pub fn latest(&self) -> Option<u64> {
        let l = self.header().latest.load(Ordering::Acquire);
        (l != NO_FRAME).then_some(l)
    }

    fn slot(&self, frame: u64) -> *const u8 {
        let i = frame % self.geometry.slot_count as u64;
        let off = size_of::<RingHeader>() as u64 + i * self.slot_size;
        // SAFETY: inside the mapping (checked geometry).
        unsafe { self.map.ptr().add(off as usize) }
    }

    /// Seqlock read of the slot that holds `frame`: copies metadata (and pixels/depth when
    /// `copy`), then re-checks the sequence. Accepts whatever complete frame the slot holds.
    fn read_slot(&mut self, frame: u64, copy: bool) -> Read {
        let slot = self.slot(frame);
        // SAFETY: a SlotHeader inside the mapping.
        let sh = unsafe { &*(slot as *const SlotHeader) };
        let s1 = sh.seq.load(Ordering::Acquire);
        if s1 == 0 {
            return Read::Empty;
        }
        if s1 & 1 == 1 {
            return Read::Torn;
        }
        // SAFETY: the ranges are inside the slot; a racing writer can only make the copy
        // inconsistent, which the sequence check below detects (the bytes are not interpreted
        // before that check).
        let meta = unsafe {
            let m = std::ptr::read_volatile(
                slot.add(std::mem::offset_of!(SlotHeader, meta)) as *const FrameMeta
            );
            if copy {
                std::ptr::copy_nonoverlapping(
                    slot.add(PIXELS_OFFSET),
                    self.pixels.as_mut_ptr(),
                    self.pixels.len(),
                );
                if self.geometry.depth {
                    std::ptr::copy_nonoverlapping(
                        slot.add(self.depth_offset as usize),
                        self.depth.as_mut_ptr().cast::<u8>(),
                        self.depth.len() * 4,
                    );
                }
            }
            m
        };
        // Acquire fence: every load above completes before the re-check below, on weakly
        // ordered CPUs (aarch64: `dmb ishld`) as well as on x86.
        fence(Ordering::Acquire);
        let s2 = sh.seq.load(Ordering::Relaxed);
        if s1 != s2 || meta.frame != (s1 - 2) / 2 {
            return Read::Torn;
        }
        Read::Ok(meta)
    }

    /// A zero-copy view of the newest complete frame (metadata verified, pixels in place).
    pub fn view(&self) -> Option<FrameRef<'_>> {
        for _ in 0..16 {
            let latest = self.latest()?;
            let slot = self.slot(latest);
            // SAFETY: a SlotHeader inside the mapping.
            let sh = unsafe { &*(slot as *const SlotHeader) };
            let s1 = sh.seq.load(Ordering::Acquire);
            if s1 == 0 || s1 & 1 == 1 {
                continue;
            }
            // SAFETY: as in `read_slot`.
            let meta = unsafe {
                std::ptr::read_volatile(
                    slot.add(std::mem::offset_of!(SlotHeader, meta)) as *const FrameMeta
                )
            };
            fence(Ordering::Acquire);
            if sh.seq.load(Ordering::Relaxed) == s1 && meta.frame == (s1 - 2) / 2 {
                return Some(FrameRef {
                    meta,
                    seq: s1,
                    slot: sh,
                    // SAFETY: inside the slot.
                    pixels: unsafe { slot.add(PIXELS_OFFSET) },
                    len: self.pixels.len(),
                });
            }
        }
        None
    }

    /// Whether `/dev/shm/<name>` now refers to a different segment than ours.
    fn replaced_on_disk(&self) -> bool {
        match (
            sys::fstat(&self.fd),
            std::fs::metadata(sys::shm_path(&self.name)),
        ) {
            (Ok((dev, ino, _)), Ok(m)) => m.dev() != dev || m.ino() != ino,
            _ => false,
        }
    }

    /// Re-opens the name if it refers to a new generation; true if it did.
    fn try_reopen(&mut self) -> bool {
        if !self.replaced_on_disk() {
            return false;
        }
        match Self::open(&self.name) {
            Ok(mut fresh) if fresh.generation != self.generation => {
                fresh.stats = self.stats;
                fresh.stats.restarts += 1;
                fresh.copy_pixels = self.copy_pixels;
                tracing::info!(
                    name = self.name,
                    generation = fresh.generation,
                    "ring restarted"
                );
                *self = fresh;
                true
            }
            _ => false,
        }
    }

    /// Blocks (futex, no busy-waiting) until a frame newer than the last one returned is
    /// available, the ring closes or restarts, or `timeout` passes. Slow readers get the newest
    /// frame; the frames in between are counted in [`ReaderStats::lost`].
    pub fn wait_next(&mut self, timeout: Duration) -> Result<Next> {
        let deadline = Instant::now() + timeout;
        loop {
            // Load the wake word before checking for frames: a publish after the check changes
            // it, so the futex wait below returns at once instead of missing the wake-up.
            let wake = self.header().wake.load(Ordering::Acquire);
            if let Some(latest) = self.latest()
                && self.last.is_none_or(|l| latest > l)
            {
                let copy = self.copy_pixels;
                match self.read_slot(latest, copy) {
                    Read::Ok(meta) if self.last.is_none_or(|l| meta.frame > l) => {
                        if let Some(l) = self.last {
                            self.stats.lost += meta.frame - l - 1;
                        }
                        self.last = Some(meta.frame);
                        self.stats.received += 1;
                        return Ok(Next::Frame(meta));
                    }
                    Read::Torn => {
                        self.stats.torn_retries += 1;
                        continue;
                    }
                    _ => {}
                }
            }
            let state = self.state();
            if state != STATE_LIVE {
                if self.try_reopen() {
                    self.last = None;
                    return Ok(Next::Restarted {
                        generation: self.generation,
                    });
                }
                // Closed: say so at once; replaced: the new segment is already under the name
                // (renamed before the old one was marked), so retry until it opens.
                if state == STATE_CLOSED || Instant::now() >= deadline {
                    return Ok(Next::Closed);
                }
                std::thread::sleep(Duration::from_millis(10).min(deadline - Instant::now()));
                continue;
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(Next::Timeout);
            }
            sys::futex_wait(&self.header().wake, wake, (deadline - now).min(REOPEN_POLL));
            if self.header().wake.load(Ordering::Acquire) == wake && self.try_reopen() {
                self.last = None;
                return Ok(Next::Restarted {
                    generation: self.generation,
                });
            }
        }
    }
}

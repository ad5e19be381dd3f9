//! The Rust consumer API: open a ring read-only, block until a new frame (futex, with a
//! timeout), copy it with seqlock verification or look at it in place, count what was missed,
//! and follow producer restarts.

use std::os::fd::OwnedFd;
use std::sync::atomic::{Ordering, fence};
use std::time::{Duration, Instant};

use super::layout::{
    FrameMeta, Geometry, Layout, NO_FRAME, RingHeader, STATE_CLOSED, STATE_LIVE, SlotHeader,
};
use super::location::{RingLocation, check_segment, expected_owner, owner_from_env};
use super::sys::{self, Mapping};
use crate::error::{Error, Result};

/// How often a waiting reader checks whether the name now refers to a new segment (a producer
/// that crashed and was restarted without anyone marking the old segment).
const REOPEN_POLL: Duration = Duration::from_millis(100);

/// What [`RingReader::wait_next`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
// FrameMeta is the ring's 256-byte metadata record, returned by value once per frame: boxing it
// would add a heap allocation to every read for no gain.
#[allow(clippy::large_enum_variant)]
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
    /// Slots whose metadata disagreed with the header (never returned).
    pub bad_slots: u64,
    /// New generations followed.
    pub restarts: u64,
}

/// A read-only view of one ring segment.
pub struct RingReader {
    location: RingLocation,
    owner: u32,
    map: Mapping,
    fd: OwnedFd,
    layout: Layout,
    generation: u64,
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

#[allow(clippy::large_enum_variant)] // as `Next`
enum Read {
    Ok(FrameMeta),
    /// The slot is being written or was overwritten during the copy.
    Torn,
    /// The slot's metadata does not match the header.
    Bad,
    /// The slot holds nothing yet.
    Empty,
}

impl RingReader {
    /// Opens the ring `location` read-only and checks it: the segment must belong to
    /// `owner` (default: the owner of a ring directory nobody else can write, see
    /// [`expected_owner`]), be writable by nobody else, and every header field must fit the
    /// mapped size ([`Layout::from_header`]).
    pub fn open(location: &RingLocation, owner: Option<u32>) -> Result<Self> {
        let owner = expected_owner(&location.dir, owner)?;
        let path = location.segment_path();
        let fd = sys::open(&path, libc::O_RDONLY, 0).map_err(|e| Error::io(&path, e))?;
        let st = sys::fstat(&fd).map_err(|e| Error::io(&path, e))?;
        check_segment(&st, owner, &path)?;
        let size = st.st_size as u64;
        let bad = |m: String| Error::invalid("ring segment", format!("{}: {m}", path.display()));
        if size < size_of::<RingHeader>() as u64 {
            return Err(bad(format!("{size} bytes is smaller than a header")));
        }
        let map = Mapping::new(&fd, size as usize, false).map_err(|e| Error::io(&path, e))?;
        // SAFETY: at least a header long, page aligned. The constant line is read once, here;
        // everything later uses the checked copy in `layout`.
        let h = unsafe { &*(map.ptr() as *const RingHeader) };
        let layout = Layout::from_header(h, size).map_err(bad)?;
        let g = layout.geometry;
        let mut r = RingReader {
            location: location.clone(),
            owner,
            generation: h.generation,
            map,
            fd,
            layout,
            last: None,
            pixels: Vec::new(),
            depth: Vec::new(),
            stats: ReaderStats::default(),
            copy_pixels: true,
        };
        r.pixels.resize(g.pixel_bytes() as usize, 0);
        if g.depth {
            r.depth.resize(g.width as usize * g.height as usize, 0.0);
        }
        Ok(r)
    }

    /// [`RingReader::open`] of `name` in the default directory, with the owner from the
    /// environment (`VKTERRAIN_RING_DIR`, `VKTERRAIN_RING_OWNER`).
    pub fn open_named(name: &str) -> Result<Self> {
        Self::open(&RingLocation::named(name)?, owner_from_env()?)
    }

    /// Opens the ring, retrying until it exists or `timeout` passes.
    pub fn open_wait(
        location: &RingLocation,
        owner: Option<u32>,
        timeout: Duration,
    ) -> Result<Self> {
        let deadline = Instant::now() + timeout;
        loop {
            match Self::open(location, owner) {
                Ok(r) => return Ok(r),
                Err(e) if Instant::now() >= deadline => return Err(e),
                Err(_) => std::thread::sleep(Duration::from_millis(10)),
            }
        }
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
    /// Whether a producer process holds this segment (its lock; a crashed producer's segment
    /// still says "live" in its state word, this does not).
    pub fn producer_alive(&self) -> bool {
        sys::ofd_write_locked(&self.fd).unwrap_or(false)
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
        self.layout.geometry.depth.then_some(&self.depth[..])
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
        // SAFETY: inside the mapping (Layout::from_header checked every slot against the size).
        unsafe { self.map.ptr().add(self.layout.slot_offset(frame) as usize) }
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
                    slot.add(self.layout.pixels_offset as usize),
                    self.pixels.as_mut_ptr(),
                    self.pixels.len(),
                );
                if self.layout.geometry.depth {
                    std::ptr::copy_nonoverlapping(
                        slot.add(self.layout.depth_offset as usize),
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
        if !self.layout.meta_matches(&meta) {
            return Read::Bad;
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
            if sh.seq.load(Ordering::Relaxed) == s1
                && meta.frame == (s1 - 2) / 2
                && self.layout.meta_matches(&meta)
            {
                return Some(FrameRef {
                    meta,
                    seq: s1,
                    slot: sh,
                    // SAFETY: inside the slot.
                    pixels: unsafe { slot.add(self.layout.pixels_offset as usize) },
                    len: self.pixels.len(),
                });
            }
        }
        None
    }

    /// Whether the ring's name now refers to a different segment than ours.
    fn replaced_on_disk(&self) -> bool {
        let path = self.location.segment_path();
        std::fs::symlink_metadata(&path).is_ok() && !sys::same_file(&self.fd, &path)
    }

    /// Re-opens the name if it refers to a new generation; true if it did.
    fn try_reopen(&mut self) -> bool {
        if !self.replaced_on_disk() {
            return false;
        }
        match Self::open(&self.location, Some(self.owner)) {
            Ok(mut fresh) if fresh.generation != self.generation => {
                fresh.stats = self.stats;
                fresh.stats.restarts += 1;
                fresh.copy_pixels = self.copy_pixels;
                tracing::info!(
                    ring = %self.location,
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
        let mut torn = 0u64;
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
                        // Being written or overwritten: retry, but never past the deadline
                        // (a slot a crashed or hostile producer left odd stays odd).
                        self.stats.torn_retries += 1;
                        torn += 1;
                        if Instant::now() >= deadline {
                            return Ok(Next::Timeout);
                        }
                        if torn % 64 == 0 {
                            std::thread::sleep(Duration::from_micros(100));
                        }
                        continue;
                    }
                    Read::Bad => {
                        // A corrupt slot is skipped, never returned; wait for the next frame.
                        self.stats.bad_slots += 1;
                        self.last = Some(latest);
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

//! The ring's shared-memory layout, version 1: a [`RingHeader`] followed by `slot_count` slots,
//! each a [`SlotHeader`] followed by the pixels (and optionally depth). Everything is
//! little-endian with natural alignment; words written often (the latest frame number, the
//! wake-up word, each slot's sequence) sit alone on their 64-byte cache line. The same layout is
//! spelled out in `consumers/c/vkterrain_ring.h` and `docs/ring.md`; a test compiles the header
//! and compares every offset with this file.

use std::sync::atomic::{AtomicU32, AtomicU64};

/// `"VKTRING1"` read as a little-endian u64.
pub const MAGIC: u64 = u64::from_le_bytes(*b"VKTRING1");
/// Bumped on any incompatible change of this file.
pub const LAYOUT_VERSION: u32 = 1;
/// Cache-line size the hot words are separated by (and slot alignment).
pub const LINE: usize = 64;

/// `pixel_format`: sRGB-encoded RGBA8, row 0 at the top.
pub const FORMAT_RGBA8_SRGB: u32 = 1;
/// `depth_format`: no depth in the slots.
pub const DEPTH_NONE: u32 = 0;
/// `depth_format`: reversed-Z f32 depth (1 = near, 0 = far/sky), `width * 4` bytes per row.
pub const DEPTH_F32_REVERSED_Z: u32 = 1;

/// `state`: a producer is publishing into this segment.
pub const STATE_LIVE: u32 = 1;
/// `state`: the producer shut down cleanly; no more frames will come.
pub const STATE_CLOSED: u32 = 2;
/// `state`: a newer producer replaced this segment; re-open the name.
pub const STATE_REPLACED: u32 = 3;

/// `latest` before the first frame is published.
pub const NO_FRAME: u64 = u64::MAX;

/// At offset 0 of the segment. The first cache line is written once, before the segment is
/// published under its name, and never changes.
#[repr(C, align(64))]
pub struct RingHeader {
    /// [`MAGIC`].
    pub magic: u64,
    /// [`LAYOUT_VERSION`].
    pub layout_version: u32,
    /// `size_of::<RingHeader>()`: where slot 0 starts.
    pub header_size: u32,
    /// Changes every time a producer creates the segment (restart detection).
    pub generation: u64,
    pub width: u32,
    pub height: u32,
    /// [`FORMAT_RGBA8_SRGB`].
    pub pixel_format: u32,
    /// Bytes per pixel row (`4 * width`, rows tightly packed).
    pub row_stride: u32,
    pub slot_count: u32,
    /// [`DEPTH_NONE`] or [`DEPTH_F32_REVERSED_Z`].
    pub depth_format: u32,
    /// Bytes from one slot's start to the next (a multiple of 64).
    pub slot_size: u32,
    /// Offset of the pixels inside a slot.
    pub pixels_offset: u32,
    /// Offset of the depth inside a slot (0 without depth).
    pub depth_offset: u32,
    /// Process id of the producer (to refuse replacing a live one).
    pub producer_pid: u32,
    /// Hot line: the newest completely published frame number ([`NO_FRAME`] before the first).
    pub latest: AtomicU64,
    /// [`STATE_LIVE`], [`STATE_CLOSED`] or [`STATE_REPLACED`].
    pub state: AtomicU32,
    pub _pad1: [u8; 52],
    /// Futex word: incremented after every publish and on close; waiters `FUTEX_WAIT` on it.
    pub wake: AtomicU32,
    pub _pad2: [u8; 60],
    /// Frames published so far in this generation.
    pub published: AtomicU64,
    pub _pad3: [u8; 56],
}

/// At the start of every slot. `seq` is alone on its line; the metadata follows on the next.
#[repr(C, align(64))]
pub struct SlotHeader {
    /// Seqlock word: `2 * frame + 1` while frame `frame` is being written, `2 * frame + 2` once
    /// it is complete (0: never written).
    pub seq: AtomicU64,
    pub _pad0: [u8; 56],
    pub meta: FrameMeta,
}

/// Per-frame metadata, copied and verified together with the pixels.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameMeta {
    /// Frame number in this generation (0, 1, 2, ...), equal to `(seq - 2) / 2`.
    pub frame: u64,
    /// `CLOCK_MONOTONIC` nanoseconds when the frame left the GPU (readback complete).
    pub capture_ns: u64,
    /// `CLOCK_MONOTONIC` nanoseconds when the slot was complete (just before `seq` turned even).
    pub publish_ns: u64,
    pub width: u32,
    pub height: u32,
    pub row_stride: u32,
    pub _reserved0: u32,
    /// Camera position in metres (x east, y north, z up).
    pub position: [f64; 3],
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    pub vfov_deg: f64,
    pub near: f64,
    pub far: f64,
    /// Pinhole intrinsics in pixels (x right, y down, principal point at the image centre).
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub gpu_prepass_ms: f64,
    pub gpu_terrain_ms: f64,
    pub gpu_readback_ms: f64,
    pub cpu_record_ms: f64,
    pub cpu_wait_ms: f64,
    pub triangles: u64,
}

/// Offset of the pixels inside a slot.
pub const PIXELS_OFFSET: usize = size_of::<SlotHeader>();

const _: () = {
    assert!(size_of::<RingHeader>() == 256);
    assert!(size_of::<SlotHeader>() == 256);
    assert!(size_of::<FrameMeta>() == 192);
    assert!(std::mem::offset_of!(RingHeader, latest) == 64);
    assert!(std::mem::offset_of!(RingHeader, wake) == 128);
    assert!(std::mem::offset_of!(RingHeader, published) == 192);
    assert!(std::mem::offset_of!(SlotHeader, meta) == 64);
};

/// Geometry of a ring: everything the header's constant line says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Geometry {
    pub width: u32,
    pub height: u32,
    pub slot_count: u32,
    pub depth: bool,
}

/// Largest segment accepted (a sanity bound against absurd headers and configs).
pub const MAX_SEGMENT_BYTES: u64 = 16 << 30;

impl Geometry {
    pub fn row_stride(&self) -> u32 {
        self.width * 4
    }
    pub fn pixel_bytes(&self) -> u64 {
        self.row_stride() as u64 * self.height as u64
    }
    pub fn depth_offset(&self) -> u64 {
        if self.depth {
            round_up(PIXELS_OFFSET as u64 + self.pixel_bytes(), LINE as u64)
        } else {
            0
        }
    }
    pub fn slot_size(&self) -> u64 {
        let end = if self.depth {
            self.depth_offset() + self.width as u64 * self.height as u64 * 4
        } else {
            PIXELS_OFFSET as u64 + self.pixel_bytes()
        };
        round_up(end, LINE as u64)
    }
    pub fn segment_size(&self) -> u64 {
        size_of::<RingHeader>() as u64 + self.slot_size() * self.slot_count as u64
    }

    /// Rejects sizes that overflow the 32-bit offsets or exceed [`MAX_SEGMENT_BYTES`].
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |m: String| Err(crate::Error::invalid("ring geometry", m));
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            return bad(format!(
                "{}x{} is outside 1..=16384",
                self.width, self.height
            ));
        }
        if !(2..=64).contains(&self.slot_count) {
            return bad(format!("{} slots is outside 2..=64", self.slot_count));
        }
        if self.slot_size() > u32::MAX as u64 || self.segment_size() > MAX_SEGMENT_BYTES {
            return bad(format!(
                "{} bytes exceed the {} byte limit",
                self.segment_size(),
                MAX_SEGMENT_BYTES
            ));
        }
        Ok(())
    }
}

fn round_up(v: u64, to: u64) -> u64 {
    v.div_ceil(to) * to
}

/// Checks a segment name: 1..=200 characters from `[A-Za-z0-9._-]`, not starting with a dot
/// (no slashes, no `.`/`..`, nothing hidden).
pub fn validate_name(name: &str) -> crate::Result<()> {
    let ok = (1..=200).contains(&name.len())
        && !name.starts_with('.')
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-'));
    if ok {
        Ok(())
    } else {
        Err(crate::Error::invalid(
            "ring name",
            format!("{name:?}: use 1..=200 characters from [A-Za-z0-9._-], not starting with '.'"),
        ))
    }
}

//! The ring's shared-memory layout, version 3: a [`RingHeader`] on the segment's first
//! `header_size` bytes, followed by `slot_count` slots, each a [`SlotHeader`] followed (at
//! `pixels_offset`) by the pixels and optionally (at `depth_offset`) the depth. Everything is
//! little-endian with natural alignment; words written often (the latest frame number, the
//! wake-up word, each slot's sequence) sit alone on their 64-byte cache line. Slots and the pixels
//! inside them start on [`Geometry::align`] boundaries (a page) so that the GPU can write a
//! frame straight into its slot (`VK_EXT_external_memory_host`, docs/ring.md). The same layout is
//! spelled out in `consumers/c/vkterrain_ring.h` and `docs/ring.md`; a test compiles the header
//! and compares every offset with this file.
//!
//! Readers never trust the header: [`Layout::from_header`] checks every field against the mapped
//! size before any offset is used, and every slot's metadata is checked against the header.

use std::sync::atomic::{AtomicU32, AtomicU64};

/// `"VKTRING1"` read as a little-endian u64.
pub const MAGIC: u64 = u64::from_le_bytes(*b"VKTRING1");
/// Bumped on any incompatible change of this file (2: page-aligned slots and pixels, `flags`;
/// 3: the camera's WGS84 pose in [`FrameMeta`]).
pub const LAYOUT_VERSION: u32 = 3;
/// Default alignment of slots and pixels: a page, what `VK_EXT_external_memory_host` needs.
pub const SLOT_ALIGN: u32 = 4096;
/// Largest alignment accepted (64 KiB pages exist on some aarch64 kernels).
pub const MAX_ALIGN: u32 = 1 << 16;
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

/// `flags` bit: the GPU writes the pixels straight into the slot (zero-copy publishing).
pub const FLAG_ZERO_COPY: u32 = 1;

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
    /// Where slot 0 starts: [`Geometry::align`] (at least `size_of::<RingHeader>()`).
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
    /// Process id of the producer (informational: liveness is the producer's lock, docs/ring.md).
    pub producer_pid: u32,
    /// Hot line: the newest completely published frame number ([`NO_FRAME`] before the first).
    pub latest: AtomicU64,
    /// [`STATE_LIVE`], [`STATE_CLOSED`] or [`STATE_REPLACED`].
    pub state: AtomicU32,
    /// [`FLAG_ZERO_COPY`]; written before the segment gets its name, never changed.
    pub flags: u32,
    pub _pad1: [u8; 48],
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
    /// The datum of `height_m` below: [`DATUM_NONE`] (no world frame on the earth: the WGS84
    /// fields are NaN), [`DATUM_ELLIPSOID`], [`DATUM_EGM96`] or [`DATUM_EGM2008`] (the
    /// world's datum: the ellipsoid when the terrain is drawn on it through the lattice, which
    /// carries the terrain's geoid; the terrain's datum in the flat world and in a build
    /// without PROJ).
    pub height_datum: u32,
    pub _reserved1: u32,
    /// The camera on the earth (WGS84 latitude/longitude, degrees).
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// The camera's height in metres above `height_datum`.
    pub height_m: f64,
    /// Attitude in the local north-east-down frame at the camera (aerospace yaw-pitch-roll:
    /// heading clockwise from true north, pitch nose up, roll right wing down; degrees).
    pub heading_deg: f64,
    pub local_pitch_deg: f64,
    pub local_roll_deg: f64,
    pub _reserved2: u64,
}

/// `height_datum`: the world frame is not on the earth (flat local data).
pub const DATUM_NONE: u32 = 0;
/// `height_datum`: metres above the WGS84 ellipsoid.
pub const DATUM_ELLIPSOID: u32 = 1;
/// `height_datum`: metres above the EGM96 geoid (mean sea level; SRTM's heights).
pub const DATUM_EGM96: u32 = 2;
/// `height_datum`: metres above the EGM2008 geoid.
pub const DATUM_EGM2008: u32 = 3;

/// The `height_datum` code of a data set's `vertical_datum` (`dataset::manifest::datum`):
/// local heights on an anchored data set count as ellipsoidal, `unknown` as EGM96.
pub fn datum_code(vertical_datum: &str) -> u32 {
    use crate::dataset::manifest::datum;
    match vertical_datum {
        datum::EGM96 | datum::UNKNOWN => DATUM_EGM96,
        datum::EGM2008 => DATUM_EGM2008,
        _ => DATUM_ELLIPSOID,
    }
}

const _: () = {
    assert!(size_of::<RingHeader>() == 256);
    assert!(size_of::<SlotHeader>() == 320);
    assert!(size_of::<FrameMeta>() == 256);
    assert!(std::mem::offset_of!(FrameMeta, height_datum) == 192);
    assert!(std::mem::offset_of!(FrameMeta, lat_deg) == 200);
    assert!(std::mem::offset_of!(RingHeader, latest) == 64);
    assert!(std::mem::offset_of!(RingHeader, flags) == 76);
    assert!(std::mem::offset_of!(RingHeader, wake) == 128);
    assert!(std::mem::offset_of!(RingHeader, published) == 192);
    assert!(std::mem::offset_of!(SlotHeader, meta) == 64);
};

/// Geometry of a ring: what the producer asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Geometry {
    pub width: u32,
    pub height: u32,
    pub slot_count: u32,
    pub depth: bool,
    /// Alignment of slot 0, every slot size and the pixels (a power of two, 256..=[`MAX_ALIGN`]);
    /// [`SLOT_ALIGN`] unless a device needs more for zero-copy.
    pub align: u32,
}

/// Largest segment accepted (a sanity bound against absurd headers and configs).
pub const MAX_SEGMENT_BYTES: u64 = 16 << 30;

impl Geometry {
    /// A geometry with the default alignment.
    pub fn new(width: u32, height: u32, slot_count: u32, depth: bool) -> Self {
        Geometry {
            width,
            height,
            slot_count,
            depth,
            align: SLOT_ALIGN,
        }
    }
    pub fn row_stride(&self) -> u32 {
        self.width * 4
    }
    pub fn pixel_bytes(&self) -> u64 {
        self.row_stride() as u64 * self.height as u64
    }
    pub fn depth_bytes(&self) -> u64 {
        if self.depth {
            self.width as u64 * self.height as u64 * 4
        } else {
            0
        }
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
        if !self.align.is_power_of_two() || !(256..=MAX_ALIGN).contains(&self.align) {
            return bad(format!(
                "alignment {} is not a power of two in 256..={MAX_ALIGN}",
                self.align
            ));
        }
        let l = Layout::of(*self);
        if l.slot_size > u32::MAX as u64 || l.segment_size() > MAX_SEGMENT_BYTES {
            return bad(format!(
                "{} bytes exceed the {} byte limit",
                l.segment_size(),
                MAX_SEGMENT_BYTES
            ));
        }
        Ok(())
    }
}

/// Where everything lies in a segment: computed from a [`Geometry`] by the producer, or read
/// and checked from a header by readers ([`Layout::from_header`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    pub geometry: Geometry,
    /// Offset of slot 0.
    pub header_size: u64,
    pub slot_size: u64,
    /// Offset of the pixels inside a slot.
    pub pixels_offset: u64,
    /// Offset of the depth inside a slot (0 without depth).
    pub depth_offset: u64,
}

impl Layout {
    /// The producer's layout: header, slot header and pixels each start on an `align`
    /// boundary, so the pixels of every slot are page aligned in the segment.
    pub fn of(g: Geometry) -> Self {
        let a = g.align as u64;
        let pixels_offset = round_up(size_of::<SlotHeader>() as u64, a);
        let depth_offset = if g.depth {
            round_up(pixels_offset + g.pixel_bytes(), a)
        } else {
            0
        };
        let end = if g.depth {
            depth_offset + g.depth_bytes()
        } else {
            pixels_offset + g.pixel_bytes()
        };
        Layout {
            geometry: g,
            header_size: round_up(size_of::<RingHeader>() as u64, a),
            slot_size: round_up(end, a),
            pixels_offset,
            depth_offset,
        }
    }

    pub fn segment_size(&self) -> u64 {
        self.header_size + self.slot_size * self.geometry.slot_count as u64
    }

    /// Offset of slot `index % slot_count` in the segment.
    pub fn slot_offset(&self, frame: u64) -> u64 {
        self.header_size + (frame % self.geometry.slot_count as u64) * self.slot_size
    }

    /// Reads and checks a header's constant line against a segment of `mapped` bytes. Every
    /// offset a reader will use is proven to lie inside the mapping; the error names the first
    /// field that does not fit.
    pub fn from_header(h: &RingHeader, mapped: u64) -> std::result::Result<Self, String> {
        let geometry = Self::geometry_of(h)?;
        let header_size = h.header_size as u64;
        let (slot_size, pixels_offset, depth_offset) = (
            h.slot_size as u64,
            h.pixels_offset as u64,
            h.depth_offset as u64,
        );
        Self::check_slot(&geometry, slot_size, pixels_offset, depth_offset)?;
        let need = header_size + slot_size * h.slot_count as u64;
        if need > mapped || need > MAX_SEGMENT_BYTES {
            return Err(format!(
                "header and slots need {need} bytes but the segment has {mapped}"
            ));
        }
        Ok(Layout {
            geometry,
            header_size,
            slot_size,
            pixels_offset,
            depth_offset,
        })
    }

    /// The header's identity (magic, layout version) and geometry (header size, image size,
    /// formats, row stride, slot count), checked in that order.
    fn geometry_of(h: &RingHeader) -> std::result::Result<Geometry, String> {
        if h.magic != MAGIC {
            return Err("not a vkterrain ring (bad magic)".into());
        }
        if h.layout_version != LAYOUT_VERSION {
            return Err(format!(
                "layout version {} is not the supported {LAYOUT_VERSION}",
                h.layout_version
            ));
        }
        let header_size = h.header_size as u64;
        if header_size < size_of::<RingHeader>() as u64
            || header_size % LINE as u64 != 0
            || header_size > MAX_ALIGN as u64
        {
            return Err(format!(
                "header_size {header_size} is not a multiple of 64 in 256..=65536"
            ));
        }
        if h.width == 0 || h.height == 0 || h.width > 16384 || h.height > 16384 {
            return Err(format!("{}x{} is outside 1..=16384", h.width, h.height));
        }
        if h.pixel_format != FORMAT_RGBA8_SRGB {
            return Err(format!("pixel_format {} is unknown", h.pixel_format));
        }
        if h.row_stride as u64 != h.width as u64 * 4 {
            return Err(format!(
                "row_stride {} is not 4 * width ({})",
                h.row_stride, h.width
            ));
        }
        if !(2..=64).contains(&h.slot_count) {
            return Err(format!("slot_count {} is outside 2..=64", h.slot_count));
        }
        let depth = match h.depth_format {
            DEPTH_NONE => false,
            DEPTH_F32_REVERSED_Z => true,
            d => return Err(format!("depth_format {d} is unknown")),
        };
        Ok(Geometry {
            width: h.width,
            height: h.height,
            slot_count: h.slot_count,
            depth,
            align: h.header_size,
        })
    }

    /// Whether the pixels (and the depth, with `g.depth`) fit a `slot_size`-byte slot after
    /// its header, each on a 64-byte line.
    fn check_slot(
        g: &Geometry,
        slot_size: u64,
        pixels_offset: u64,
        depth_offset: u64,
    ) -> std::result::Result<(), String> {
        if slot_size % LINE as u64 != 0 {
            return Err(format!("slot_size {slot_size} is not a multiple of 64"));
        }
        if pixels_offset < size_of::<SlotHeader>() as u64
            || pixels_offset % LINE as u64 != 0
            || pixels_offset + g.pixel_bytes() > slot_size
        {
            return Err(format!(
                "pixels at {pixels_offset} ({} bytes) do not fit a {slot_size}-byte slot after its header",
                g.pixel_bytes()
            ));
        }
        if g.depth
            && (depth_offset % LINE as u64 != 0
                || depth_offset < pixels_offset + g.pixel_bytes()
                || depth_offset + g.depth_bytes() > slot_size)
        {
            return Err(format!(
                "depth at {depth_offset} does not fit the slot after the pixels"
            ));
        }
        if !g.depth && depth_offset != 0 {
            return Err("depth_offset set without depth".into());
        }
        Ok(())
    }

    /// Whether a slot's metadata agrees with this layout (a reader rejects the slot otherwise).
    pub fn meta_matches(&self, m: &FrameMeta) -> bool {
        m.width == self.geometry.width
            && m.height == self.geometry.height
            && m.row_stride == self.geometry.row_stride()
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

#!/usr/bin/env python3
"""Read frames from a vkterrain shared-memory ring (layout version 2), standard library only.

    from vkterrain_ring import RingReader
    with RingReader("vkterrain") as ring:       # $VKTERRAIN_RING_DIR, default /run/vkterrain
        ev, meta, pixels = ring.wait_next(timeout=1.0)   # "frame", "timeout", "closed", "restarted"
        if ev == "frame":
            ring.save_png("latest.png", meta, pixels)       # or ring.as_array(meta, pixels) with numpy

As a program: ``python3 vkterrain_ring.py NAME [--dir D] [--owner USER] [--seconds S] [--frames N]
[--verify] [--save F.png]`` prints one line of counters (the same as consumers/c/ring_reader).

Trust: a ring is accepted only if it is a regular file owned by the expected user (``owner=``,
``$VKTERRAIN_RING_OWNER``, or else the owner of a ring directory nobody else can write) that
nobody else may write. Every header field is checked against the mapped size at open (the
checked copy is all that is used later) and every slot's metadata against the header before a
frame is returned: a hostile or corrupt segment raises RingError or is skipped, never read out
of bounds.

The segment is mapped read-only with mmap(2) (through ctypes, so that the sequence words can be
loaded as single 8-byte atomic loads). The seqlock check needs an acquire load and an acquire
fence; they come from libatomic (``__atomic_load_8``, ``atomic_thread_fence``), which makes the
check correct on aarch64 as well as x86. Without libatomic the module falls back to plain
8-byte loads, which is only guaranteed on x86 (``ORDERED`` says which one is in use).
See docs/ring.md for the layout and protocol.
"""

import ctypes
import ctypes.util
import os
import platform
import struct
import sys
import time
import zlib

MAGIC = int.from_bytes(b"VKTRING1", "little")
LAYOUT_VERSION = 3
HEADER_SIZE = 256          # size of the header struct (slot 0 starts at header_size >= this)
SLOT_HEADER_SIZE = 320
DEFAULT_DIR = "/run/vkterrain"
FLAG_ZERO_COPY = 1
STATE_LIVE, STATE_CLOSED, STATE_REPLACED = 1, 2, 3
NO_FRAME = (1 << 64) - 1

# Offsets (docs/ring.md; checked against the Rust layout by tests/ring.rs).
H_MAGIC, H_VERSION, H_HEADER_SIZE, H_GENERATION = 0, 8, 12, 16
H_WIDTH, H_HEIGHT, H_FORMAT, H_STRIDE = 24, 28, 32, 36
H_SLOTS, H_DEPTH_FORMAT, H_SLOT_SIZE, H_PIXELS_OFFSET = 40, 44, 48, 52
H_DEPTH_OFFSET, H_PID = 56, 60
H_LATEST, H_STATE, H_FLAGS, H_WAKE, H_PUBLISHED = 64, 72, 76, 128, 192
S_SEQ, S_META = 0, 64
META_FORMAT = "<QQQIIII3d6d4d5dQII6dQ"
META_FIELDS = (
    "frame capture_ns publish_ns width height row_stride _reserved0 px py pz yaw_deg pitch_deg "
    "roll_deg vfov_deg near far fx fy cx cy gpu_prepass_ms gpu_terrain_ms gpu_readback_ms "
    "cpu_record_ms cpu_wait_ms triangles height_datum _reserved1 lat_deg lon_deg height_m "
    "heading_deg local_pitch_deg local_roll_deg _reserved2"
).split()
META_SIZE = struct.calcsize(META_FORMAT)
assert META_SIZE == 256

_libc = ctypes.CDLL(None, use_errno=True)
_libc.mmap.restype = ctypes.c_void_p
_libc.mmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int,
                       ctypes.c_int, ctypes.c_long]
_libc.munmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t]
_libc.syscall.restype = ctypes.c_long
_SYS_FUTEX = {"x86_64": 202, "aarch64": 98, "arm64": 98}.get(platform.machine())
_FUTEX_WAIT = 0
_PROT_READ, _MAP_SHARED = 1, 1
_MAP_FAILED = ctypes.c_void_p(-1).value
_ACQUIRE = 2

try:
    try:
        _atomic = ctypes.CDLL("libatomic.so.1")
    except OSError:  # find_library is slow (it runs ldconfig/cc): only as a fallback
        _atomic = ctypes.CDLL(ctypes.util.find_library("atomic"))
    _atomic.__atomic_load_8.restype = ctypes.c_uint64
    _atomic.__atomic_load_8.argtypes = [ctypes.c_void_p, ctypes.c_int]
    _atomic.atomic_thread_fence.argtypes = [ctypes.c_int]
    ORDERED = True
except (OSError, AttributeError, TypeError):
    _atomic = None
    ORDERED = False


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


def _load_acquire(addr):
    if _atomic is not None:
        return _atomic.__atomic_load_8(addr, _ACQUIRE)
    return ctypes.c_uint64.from_address(addr).value


def _fence_acquire():
    if _atomic is not None:
        _atomic.atomic_thread_fence(_ACQUIRE)


def valid_name(name):
    ok = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-")
    return 1 <= len(name) <= 200 and not name.startswith(".") and set(name) <= ok


class RingError(Exception):
    pass


def user_id(who):
    """A uid from a user name or a decimal uid."""
    if isinstance(who, int):
        return who
    if who.isdigit():
        return int(who)
    import pwd
    return pwd.getpwnam(who).pw_uid


def dir_owner(path):
    """Whose rings to accept in `path` when no owner is named: the directory's owner, if neither
    it nor any directory above it can be written by anyone but root and that owner."""
    real = os.path.realpath(path)
    owner = os.stat(real).st_uid
    p = real
    while True:
        st = os.stat(p)
        if (st.st_uid not in (0, owner)) or (st.st_mode & 0o022):
            raise RingError(f"{real}: {p} can be written by others (uid {st.st_uid}, mode "
                            f"{st.st_mode & 0o7777:o}); name the expected owner")
        if p == "/":
            return owner
        p = os.path.dirname(p)


def check_header(h, mapped):
    """Checks a header's constant line (bytes 0..80) against a segment of `mapped` bytes.
    Returns the checked fields as a dict; raises RingError naming the first field that does not
    fit."""
    (magic, version, header_size, generation, width, height, pixel_format, row_stride,
     slot_count, depth_format, slot_size, pixels_offset, depth_offset, pid) = struct.unpack_from(
        "<QIIQIIIIIIIIII", h, 0)
    flags = struct.unpack_from("<I", h, H_FLAGS)[0]

    def bad(msg):
        raise RingError(msg)
    if magic != MAGIC:
        bad("not a vkterrain ring (bad magic)")
    if version != LAYOUT_VERSION:
        bad(f"layout version {version} is not the supported {LAYOUT_VERSION}")
    if not (HEADER_SIZE <= header_size <= 65536 and header_size % 64 == 0):
        bad(f"header_size {header_size} is not a multiple of 64 in 256..=65536")
    if not (1 <= width <= 16384 and 1 <= height <= 16384):
        bad(f"{width}x{height} is outside 1..=16384")
    if pixel_format != 1:
        bad(f"pixel_format {pixel_format} is unknown")
    if row_stride != 4 * width:
        bad(f"row_stride {row_stride} is not 4 * width")
    if not 2 <= slot_count <= 64:
        bad(f"slot_count {slot_count} is outside 2..=64")
    if depth_format not in (0, 1):
        bad(f"depth_format {depth_format} is unknown")
    pixel_bytes = row_stride * height
    if slot_size % 64 or pixels_offset < SLOT_HEADER_SIZE or pixels_offset % 64 \
            or pixels_offset + pixel_bytes > slot_size:
        bad(f"pixels at {pixels_offset} do not fit a {slot_size}-byte slot")
    if depth_format == 1:
        if depth_offset % 64 or depth_offset < pixels_offset + pixel_bytes \
                or depth_offset + width * height * 4 > slot_size:
            bad(f"depth at {depth_offset} does not fit the slot")
    elif depth_offset != 0:
        bad("depth_offset set without depth")
    if header_size + slot_size * slot_count > mapped:
        bad(f"header and slots need {header_size + slot_size * slot_count} bytes but the "
            f"segment has {mapped}")
    return dict(generation=generation, width=width, height=height, row_stride=row_stride,
                slot_count=slot_count, depth_format=depth_format, slot_size=slot_size,
                pixels_offset=pixels_offset, depth_offset=depth_offset, header_size=header_size,
                pixel_bytes=pixel_bytes, producer_pid=pid, flags=flags)


class RingReader:
    """A read-only view of one ring segment; see the module docstring."""

    def __init__(self, name, dir=None, owner=None):
        if not valid_name(name):
            raise RingError(f"invalid ring name {name!r}")
        self.name = name
        self.dir = dir or os.environ.get("VKTERRAIN_RING_DIR") or DEFAULT_DIR
        if owner is None and os.environ.get("VKTERRAIN_RING_OWNER"):
            owner = os.environ["VKTERRAIN_RING_OWNER"]
        self.owner = user_id(owner) if owner is not None else dir_owner(self.dir)
        self.path = os.path.join(self.dir, name)
        self.received = self.lost = self.torn_retries = self.restarts = self.bad_slots = 0
        self.last = None
        self._map()

    def _map(self):
        fd = os.open(self.path, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW)
        try:
            st = os.fstat(fd)
            if not (st.st_mode & 0o170000 == 0o100000):
                raise RingError(f"{self.path}: not a regular file")
            if st.st_uid != self.owner:
                raise RingError(f"{self.path}: belongs to uid {st.st_uid}, not to the expected "
                                f"owner uid {self.owner}")
            if st.st_mode & 0o022:
                raise RingError(f"{self.path}: writable by group or others "
                                f"(mode {st.st_mode & 0o7777:o})")
            if st.st_size < HEADER_SIZE:
                raise RingError(f"{self.path}: too small for a ring header")
            addr = _libc.mmap(None, st.st_size, _PROT_READ, _MAP_SHARED, fd, 0)
            if addr is None or addr == _MAP_FAILED:
                raise RingError(f"{self.path}: mmap failed (errno {ctypes.get_errno()})")
        except BaseException:
            os.close(fd)
            raise
        try:
            checked = check_header(ctypes.string_at(addr, 80), st.st_size)
        except RingError as e:
            _libc.munmap(addr, st.st_size)
            os.close(fd)
            raise RingError(f"{self.path}: {e}") from None
        self.fd, self.addr, self.size, self.ino = fd, addr, st.st_size, (st.st_dev, st.st_ino)
        for k, v in checked.items():
            setattr(self, k, v)

    def producer_alive(self):
        """Whether a producer process holds the segment (its lock: a crashed producer's segment
        still says "live" in its state word)."""
        import fcntl
        fl = struct.pack("hhxxxxqqi4x", fcntl.F_RDLCK, os.SEEK_SET, 0, 0, 0)
        r = fcntl.fcntl(self.fd, getattr(fcntl, "F_OFD_GETLK", 36), fl)
        return struct.unpack("hhxxxxqqi4x", r)[0] == fcntl.F_WRLCK

    def _unmap(self):
        if getattr(self, "addr", None):
            _libc.munmap(self.addr, self.size)
            os.close(self.fd)
            self.addr = None

    def close(self):
        self._unmap()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _u32(self, off):
        return ctypes.c_uint32.from_address(self.addr + off).value

    def state(self):
        return self._u32(H_STATE)

    def latest(self):
        v = _load_acquire(self.addr + H_LATEST)
        return None if v == NO_FRAME else v

    def _slot(self, frame):
        return self.addr + self.header_size + (frame % self.slot_count) * self.slot_size

    def _read_slot(self, frame):
        """Seqlock copy: (meta dict, pixels bytes), "torn", "bad" (metadata disagrees with the
        header) or None (empty slot)."""
        slot = self._slot(frame)
        s1 = _load_acquire(slot + S_SEQ)
        if s1 == 0:
            return None
        if s1 & 1:
            return "torn"
        raw = ctypes.string_at(slot + S_META, META_SIZE)
        pixels = ctypes.string_at(slot + self.pixels_offset, self.pixel_bytes)
        _fence_acquire()
        s2 = ctypes.c_uint64.from_address(slot + S_SEQ).value
        meta = dict(zip(META_FIELDS, struct.unpack(META_FORMAT, raw)))
        if s1 != s2 or meta["frame"] != (s1 - 2) // 2:
            return "torn"
        if (meta["width"], meta["height"], meta["row_stride"]) != (
                self.width, self.height, self.row_stride):
            return "bad"
        return meta, pixels

    def _replaced_on_disk(self):
        try:
            st = os.stat(self.path)
        except OSError:
            return False
        return (st.st_dev, st.st_ino) != self.ino

    def _try_reopen(self):
        if not self._replaced_on_disk():
            return False
        old = dict(self.__dict__)
        try:
            self._map()
        except (OSError, RingError):
            self.__dict__.update(old)
            return False
        if self.generation == old["generation"]:
            _libc.munmap(self.addr, self.size)
            os.close(self.fd)
            self.__dict__.update(old)
            return False
        _libc.munmap(old["addr"], old["size"])
        os.close(old["fd"])
        self.restarts += 1
        self.last = None
        return True

    def _futex_wait(self, expected, seconds):
        if _SYS_FUTEX is None:
            time.sleep(min(seconds, 0.001))
            return
        ts = _Timespec(int(seconds), int((seconds % 1) * 1e9))
        _libc.syscall(ctypes.c_long(_SYS_FUTEX), ctypes.c_void_p(self.addr + H_WAKE),
                      ctypes.c_int(_FUTEX_WAIT), ctypes.c_uint32(expected), ctypes.byref(ts),
                      ctypes.c_void_p(None), ctypes.c_int(0))

    def wait_next(self, timeout=1.0):
        """Blocks (futex) until a frame newer than the last one returned, at most `timeout`
        seconds. Returns (event, meta, pixels); event is "frame", "timeout", "closed" or
        "restarted". Skipped frames are added to `self.lost`."""
        deadline = time.monotonic() + timeout
        torn = 0
        while True:
            wake = self._u32(H_WAKE)
            latest = self.latest()
            if latest is not None and (self.last is None or latest > self.last):
                r = self._read_slot(latest)
                if r == "torn":
                    # Retry, never past the deadline (a slot a crashed or hostile producer
                    # left odd stays odd).
                    self.torn_retries += 1
                    torn += 1
                    if time.monotonic() >= deadline:
                        return "timeout", None, None
                    if torn % 64 == 0:
                        time.sleep(0.0001)
                    continue
                if r == "bad":
                    self.bad_slots += 1
                    self.last = latest
                    r = None
                if r is not None and (self.last is None or r[0]["frame"] > self.last):
                    meta, pixels = r
                    if self.last is not None:
                        self.lost += meta["frame"] - self.last - 1
                    self.last = meta["frame"]
                    self.received += 1
                    return "frame", meta, pixels
            state = self.state()
            now = time.monotonic()
            if state != STATE_LIVE:
                if self._try_reopen():
                    return "restarted", None, None
                if state == STATE_CLOSED or now >= deadline:
                    return "closed", None, None
                time.sleep(0.01)
                continue
            if now >= deadline:
                return "timeout", None, None
            self._futex_wait(wake, min(deadline - now, 0.1))
            if self._u32(H_WAKE) == wake and self._try_reopen():
                return "restarted", None, None

    @staticmethod
    def save_png(path, meta, pixels):
        """Writes an RGBA8 frame as PNG (zlib only), atomically."""
        w, h, stride = meta["width"], meta["height"], meta["row_stride"]
        rows = b"".join(b"\x00" + pixels[y * stride:y * stride + 4 * w] for y in range(h))

        def chunk(kind, data):
            c = struct.pack(">I", len(data)) + kind + data
            return c + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

        png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
               + chunk(b"IDAT", zlib.compress(rows, 6)) + chunk(b"IEND", b""))
        tmp = f"{path}.tmp{os.getpid()}"
        with open(tmp, "wb") as f:
            f.write(png)
        os.replace(tmp, path)

    @staticmethod
    def as_array(meta, pixels):
        """The frame as a (height, width, 4) uint8 numpy array (needs numpy)."""
        import numpy as np
        a = np.frombuffer(pixels, dtype=np.uint8)
        return a.reshape(meta["height"], meta["row_stride"])[:, :4 * meta["width"]].reshape(
            meta["height"], meta["width"], 4)


def check_pattern(meta, pixels):
    """The test pattern of tests/ring.rs: frame number in bytes 0..8, CRC-32 of bytes 16.. in
    bytes 8..12."""
    if len(pixels) < 16:
        return False
    frame, crc = struct.unpack_from("<QI", pixels, 0)
    return frame == meta["frame"] and crc == zlib.crc32(pixels[16:]) & 0xFFFFFFFF


def main(argv):
    import argparse
    p = argparse.ArgumentParser(description="Read frames from a vkterrain ring.")
    p.add_argument("name")
    p.add_argument("--dir", help="ring directory (default $VKTERRAIN_RING_DIR or /run/vkterrain)")
    p.add_argument("--owner", help="user (name or uid) the ring must belong to")
    p.add_argument("--seconds", type=float, default=5.0)
    p.add_argument("--frames", type=int, default=0)
    p.add_argument("--timeout", type=float, default=5.0, help="open and wait timeout, seconds")
    p.add_argument("--verify", action="store_true", help="check the tests' content checksums")
    p.add_argument("--save", help="write the last frame as PNG")
    p.add_argument("--ready", help="create this file once the first frame has been read")
    a = p.parse_args(argv)
    t0 = time.monotonic()
    while True:
        try:
            ring = RingReader(a.name, dir=a.dir, owner=a.owner)
            break
        except RingError as e:
            print(f"error: refusing ring {a.name}: {e}", file=sys.stderr)
            return 1
        except OSError as e:
            if time.monotonic() - t0 > a.timeout:
                print(f"error: cannot open ring {a.name}: {e}", file=sys.stderr)
                return 1
            time.sleep(0.01)
    end = time.monotonic() + a.seconds
    bad = nonincreasing = gaps = 0
    prev, last, closed = None, None, 0
    with ring:
        while time.monotonic() < end and (a.frames == 0 or ring.received < a.frames):
            ev, meta, pixels = ring.wait_next(a.timeout)
            if ev == "closed":
                closed = 1
                break
            if ev == "restarted":
                prev = None
                continue
            if ev != "frame":
                continue
            if prev is not None:
                if meta["frame"] <= prev:
                    nonincreasing += 1
                else:
                    gaps += meta["frame"] - prev - 1
            prev = meta["frame"]
            if a.verify and not check_pattern(meta, pixels):
                bad += 1
            if a.ready and last is None:
                open(a.ready, "w").close()
            last = (meta, pixels)
        if a.save and last is not None:
            RingReader.save_png(a.save, *last)
        print(f"received={ring.received} lost={ring.lost} gaps={gaps} bad={bad} "
              f"nonincreasing={nonincreasing} torn_retries={ring.torn_retries} "
              f"restarts={ring.restarts} bad_slots={ring.bad_slots} closed={closed} "
              f"ordered={int(ORDERED)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

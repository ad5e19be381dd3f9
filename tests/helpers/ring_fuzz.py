#!/usr/bin/env python3
"""Feeds consumers/python/vkterrain_ring.py hostile segments (run by tests/ring.rs).

    ring_fuzz.py TEMPLATE DIR COUNT SEED [--naive]

Each case is the valid TEMPLATE mutated like tests/helpers/mutate.rs (header fields, slot
metadata, sequence words, random bytes, truncation, lying geometry), written to DIR/case and
read with RingReader + wait_next. Every frame returned must agree with the checked header, and
no case may crash the interpreter (ctypes reads out of bounds would). --naive disables the
reader's checks (the negative control: it must crash or report violations).
"""
import os
import struct
import sys

import vkterrain_ring as v

MASK = (1 << 64) - 1
INTERESTING = [0, 1, 2, 3, 4, 63, 64, 65, 255, 256, 4095, 4096, 8192, 16384, 16385, 65536,
               0x40000001, 0xFFFFFFFF]


class Rng:
    def __init__(self, seed):
        self.s = seed | 1

    def next(self):
        s = self.s
        s ^= s >> 12
        s ^= (s << 25) & MASK
        s ^= s >> 27
        self.s = s
        return (s * 0x2545F4914F6CDD1D) & MASK

    def below(self, n):
        return self.next() % n if n else 0


def put(b, off, fmt, val):
    if off + struct.calcsize(fmt) <= len(b):
        struct.pack_into(fmt, b, off, val)


def mutate(t, r):
    b = bytearray(t)
    hs, ss, slots = struct.unpack_from("<I", t, 12)[0], struct.unpack_from("<I", t, 48)[0], \
        struct.unpack_from("<I", t, 40)[0]

    def slot(i):
        return hs + (i % max(slots, 1)) * ss

    def interesting():
        return r.next() & 0xFFFFFFFF if r.below(4) == 0 else INTERESTING[r.below(len(INTERESTING))]
    for _ in range(1 + r.below(3)):
        k = r.below(6)
        if k == 0:
            put(b, [8, 12, 24, 28, 32, 36, 40, 44, 48, 52, 56, 60, 76][r.below(13)], "<I", interesting())
        elif k == 1:
            put(b, slot(r.below(slots)) + 64 + [24, 28, 32][r.below(3)], "<I", interesting())
        elif k == 2:
            s = slot(r.below(slots))
            val = r.next() >> r.below(64)
            put(b, s if r.below(2) == 0 else 64, "<Q", val)
            put(b, s + 64, "<Q", r.below(8))
        elif k == 3:
            for _ in range(1 + r.below(16)):
                i = min([0, slot(0), slot(1)][r.below(3)] + r.below(320), max(len(b) - 1, 0))
                if b:
                    b[i] = r.next() & 0xFF
        elif k == 4:
            n = r.below(len(t) * 2 + 1)
            b = b[:n] + bytearray(max(0, n - len(b)))
        else:
            w = interesting()
            put(b, 24, "<I", w)
            put(b, 36, "<I", (w * 4) & 0xFFFFFFFF)
    return bytes(b)


def main(argv):
    template, d, count, seed = argv[0], argv[1], int(argv[2]), int(argv[3])
    naive = "--naive" in argv
    if naive:
        # The old reader: take the header's word for everything, and the slot's for the size.
        def trusting(h, mapped):
            f = struct.unpack_from("<QIIQIIIIIIIIII", h, 0)
            return dict(generation=f[3], width=f[4], height=f[5], row_stride=f[7],
                        slot_count=max(f[8], 1), depth_format=f[9], slot_size=f[10],
                        pixels_offset=f[11], depth_offset=f[12], header_size=f[2],
                        pixel_bytes=f[7] * f[5] * 64, producer_pid=f[13], flags=0)
        v.check_header = trusting
    t = open(template, "rb").read()
    r = Rng(seed)
    path = os.path.join(d, "case")
    opened = frames = rejected = violations = 0
    for c in range(count):
        data = t if c == 0 else mutate(t, r)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        os.write(fd, data)
        os.close(fd)
        try:
            ring = v.RingReader("case", dir=d, owner=os.geteuid())
        except (v.RingError, OSError):
            rejected += 1
            continue
        opened += 1
        with ring:
            for _ in range(3):
                ev, meta, pixels = ring.wait_next(0)
                if ev != "frame":
                    break
                frames += 1
                if (meta["width"], meta["height"], meta["row_stride"]) != (
                        ring.width, ring.height, ring.row_stride) \
                        or len(pixels) != meta["row_stride"] * meta["height"]:
                    violations += 1
    print(f"cases={count} opened={opened} frames={frames} rejected={rejected} "
          f"violations={violations}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

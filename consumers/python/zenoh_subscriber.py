#!/usr/bin/env python3
"""Receive `vkterrain serve` frames over Zenoh and save one as PNG (docs/zenoh.md).

    pip install eclipse-zenoh==1.10.2
    python3 zenoh_subscriber.py --ring vkterrain --connect tcp/127.0.0.1:7447 --frames 10 \\
        --save frame.png

Key expressions: <prefix>/<ring>/frame (the ring slot's 256-byte metadata, the RGBA8 pixels,
the depth when the service reads it back), <prefix>/<ring>/control (JSON control messages, the
control socket's), <prefix>/<ring>/status (a queryable answering with the status JSON).
Prints one line per frame and a summary line `received=.. lost=.. bad=.. latency_median_us=..`.
Every payload is checked against its metadata before use (a subscriber never trusts the wire).
"""
import argparse
import json
import os
import struct
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from vkterrain_ring import META_FIELDS, META_FORMAT, META_SIZE, RingReader  # noqa: E402


def parse_payload(data):
    """(meta dict, pixels bytes, depth bytes or None); raises ValueError on a bad payload."""
    if len(data) < META_SIZE:
        raise ValueError(f"{len(data)} bytes is shorter than the metadata")
    meta = dict(zip(META_FIELDS, struct.unpack_from(META_FORMAT, data, 0)))
    w, h, stride = meta["width"], meta["height"], meta["row_stride"]
    if not (1 <= w <= 16384 and 1 <= h <= 16384) or stride != 4 * w:
        raise ValueError(f"bad geometry {w}x{h} stride {stride}")
    px, rest = stride * h, len(data) - META_SIZE
    if rest == px:
        return meta, data[META_SIZE:], None
    if rest == px + w * h * 4:
        return meta, data[META_SIZE:META_SIZE + px], data[META_SIZE + px:]
    raise ValueError(f"{rest} bytes after the metadata, expected {px}")


def monotonic_ns():
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--ring", default="vkterrain")
    p.add_argument("--prefix", default="vkterrain")
    p.add_argument("--connect", action="append", default=[])
    p.add_argument("--listen", action="append", default=[])
    p.add_argument("--frames", type=int, default=0, help="stop after this many frames")
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--save", help="write the last frame as PNG")
    p.add_argument("--no-shm", action="store_true", help="turn Zenoh shared memory off")
    p.add_argument("--quiet", action="store_true")
    a = p.parse_args(argv)
    import zenoh
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps(a.connect))
    conf.insert_json5("listen/endpoints", json.dumps(a.listen))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/shared_memory/enabled", "false" if a.no_shm else "true")
    session = zenoh.open(conf)
    key = f"{a.prefix}/{a.ring}/frame"
    # A small ring of samples: a slow subscriber skips frames, never holds the service up.
    sub = session.declare_subscriber(key, zenoh.handlers.RingChannel(4))
    received = lost = bad = 0
    prev = last = None
    latency = []
    end = time.monotonic() + a.seconds
    while time.monotonic() < end and (a.frames == 0 or received < a.frames):
        sample = sub.try_recv()
        if sample is None:
            time.sleep(0.002)
            continue
        try:
            meta, pixels, _depth = parse_payload(sample.payload.to_bytes())
        except ValueError as e:
            bad += 1
            print(f"bad frame: {e}", file=sys.stderr)
            continue
        lat = (monotonic_ns() - meta["publish_ns"]) / 1e3
        latency.append(lat)
        received += 1
        if prev is not None and meta["frame"] > prev:
            lost += meta["frame"] - prev - 1
        prev = meta["frame"]
        last = (meta, pixels)
        if not a.quiet:
            print(f"frame={meta['frame']} width={meta['width']} height={meta['height']} "
                  f"x={meta['px']} y={meta['py']} z={meta['pz']} yaw_deg={meta['yaw_deg']} "
                  f"latency_us={lat:.0f}")
    if a.save and last is not None:
        RingReader.save_png(a.save, *last)
    latency.sort()
    med = latency[len(latency) // 2] if latency else 0.0
    print(f"received={received} lost={lost} bad={bad} latency_median_us={med:.0f}")
    sub.undeclare()
    session.close()
    return 0 if received > 0 or a.frames == 0 else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

#!/usr/bin/env python3
"""Issue 18's report rows from two `vkterrain eval` runs of one data set: BEFORE by main at
3ab4290 (its CSV columns: wall-clock frame_ms, no oracle), AFTER by this build (GPU
timestamps, the oracle). Per tau, one markdown row: p99.9 / max px before and after, after's
p99.9 / tau (over the coarse pixels too, with their share), triangles (median) before ->
after and the factor, tiles (median) before -> after, GPU ms (median) before -> after, UDLOD/oracle before -> after.

Before's GPU ms is the median of its per-frame prepass + terrain timestamps after the first
WARMUP frames, what after's `gpu_ms` measures; before's UDLOD/oracle is the median over the
frames where after computed the oracle of before's triangles over the oracle's (the same
flight, frames and tau). Before's tiles are its triangles over 512: grid 16 drew every tile
whole; after's are `tiles_median` (eval's tiles column, "-" from a build before it).

usage: scripts/udlod_before_after_table.py BEFORE_DIR AFTER_DIR
"""
import csv
import re
import statistics
import sys

WARMUP = 5
BEFORE_TILE_TRIANGLES = 2 * 16 * 16


def tau_of(variant):
    m = re.search(r"tau_px=([0-9.]+)", variant)
    if not m:
        sys.exit(f"variant {variant!r} names no tau_px")
    return float(m.group(1))


def rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def per_tau(path):
    out = {}
    for r in rows(path):
        out.setdefault(tau_of(r["variant"]), []).append(r)
    return out


def summary(path):
    return {tau_of(r["variant"]): r for r in rows(path)}


def fmt_px(x):
    """Two decimals, three below 0.1 px (exact frames show their last digits)."""
    return f"{x:.2f}" if x >= 0.1 else f"{x:.3f}"


def fmt_share(s):
    return f"{100 * s:.1f} %" if s >= 0.001 else f"{100 * s:.3f} %"


def fmt_int(x):
    return f"{int(round(x)):,}"


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__.strip().splitlines()[-1])
    before_dir, after_dir = sys.argv[1:]
    bf, bs = per_tau(f"{before_dir}/frames.csv"), summary(f"{before_dir}/summary.csv")
    af, as_ = per_tau(f"{after_dir}/frames.csv"), summary(f"{after_dir}/summary.csv")
    for tau in sorted(as_):
        b, a = bs[tau], as_[tau]
        b_frames = {int(r["frame"]): r for r in bf[tau]}
        gpu_before = statistics.median(
            float(r["gpu_prepass_ms"]) + float(r["gpu_terrain_ms"])
            for f, r in b_frames.items()
            if f >= WARMUP
        )
        ratios = [
            float(b_frames[int(r["frame"])]["triangles"]) / float(r["oracle_triangles"])
            for r in af[tau]
            if r["oracle_triangles"] not in ("", "0") and int(r["frame"]) in b_frames
        ]
        ratio_before = statistics.median(ratios) if ratios else float("nan")
        tri_b, tri_a = float(b["triangles_median"]), float(a["triangles_median"])
        tiles_a = a.get("tiles_median") or ""
        tiles_a = fmt_int(float(tiles_a)) if tiles_a else "-"
        p999_a = float(a["err_px_p999"])
        coarse = (
            f"{float(a['coarse_px_p999']) / tau:.2f}, {fmt_share(float(a['coarse_share']))}"
            if float(a["coarse_share"] or 0) > 0
            else "no coarse pixel"
        )
        print(
            f"| | {tau:g} | {float(b['err_px_p999']):.3f} / {fmt_px(float(b['err_px_max']))} "
            f"| {p999_a:.3f} / {fmt_px(float(a['err_px_max']))} | {p999_a / tau:.2f} ({coarse}) "
            f"| {fmt_int(tri_b)} -> {fmt_int(tri_a)} ({tri_b / tri_a:.1f}x) "
            f"| {fmt_int(tri_b / BEFORE_TILE_TRIANGLES)} -> {tiles_a} "
            f"| {gpu_before:.1f} -> {float(a['gpu_ms_median']):.1f} "
            f"| {ratio_before:.2f} -> {float(a['oracle_ratio_median']):.2f} |"
        )


if __name__ == "__main__":
    main()

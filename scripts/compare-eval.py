#!/usr/bin/env python3
"""Compare two evaluation runs (each a results.json from `vkterrain eval` or
target/bench/eval/<case>/results.json) as ratios within each run: the speed (GPU time of
the method's passes, `gpu_ms`; older files: `frame_ms`) relative to brute force of the same
run, errors and swimming as they are. Absolute times from two runs are not compared (the
machines are shared and noisy).

usage: scripts/compare-eval.py OLD/results.json NEW/results.json
"""
import json
import sys


def speed(summary):
    """The speed axis: `gpu_ms` since the GPU evaluator, `frame_ms` before it."""
    return (summary.get("gpu_ms") or summary["frame_ms"])["median"]


def load(path):
    with open(path) as f:
        data = json.load(f)
    rows = {s["variant"]: s for s in data["summaries"]}
    brute = rows.get("brute")
    base = speed(brute) if brute else float("nan")
    return data, rows, base


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__.strip().splitlines()[-1])
    (a, ra, ba), (b, rb, bb) = load(sys.argv[1]), load(sys.argv[2])
    print(f"old: {a['scenario']} on {a['dataset']} ({a['device']})")
    print(f"new: {b['scenario']} on {b['dataset']} ({b['device']})")
    print(f"{'variant':<20} {'time/brute old':>14} {'new':>8} {'err p99.9 old':>14} {'new':>8} {'swim old':>9} {'new':>8}")
    for name in ra:
        if name not in rb:
            continue
        o, n = ra[name], rb[name]
        print(f"{name:<20} {speed(o) / ba:>14.3f} {speed(n) / bb:>8.3f} "
              f"{o['error']['pixels']['p999']:>14.3f} {n['error']['pixels']['p999']:>8.3f} "
              f"{o['swimming_px']['mean']:>9.4f} {n['swimming_px']['mean']:>8.4f}")


if __name__ == "__main__":
    main()

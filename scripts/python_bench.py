#!/usr/bin/env python3
"""Times lidar_noise's Chain.apply with fog + rain + snow on a 35k-point array (the size
of a nuScenes sweep), conversion to and from numpy included: the issue 32 benchmark, to
run by hand (not in CI: nothing may depend on machine speed).

    pip install ./python && python scripts/python_bench.py [--points 35000] [--repeat 200]

Prints the median, 10th and 90th percentile of one `apply` on one core (threads=1) and
with rayon's default pool."""

import argparse
import statistics
import time

import numpy as np

import lidar_noise as ln

CONFIG = {
    "seed": 1,
    "noise": [
        {"type": "fog", "visibility_m": 300.0},
        {"type": "rain", "rate_mm_h": 10.0},
        {"type": "snow", "preset": "moderate"},
    ],
}

# HDL-32E elevations by laser id (manual).
ELEVATIONS = np.array([
    -30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33, -25.33, -4.00, -24.00,
    -2.67, -22.67, -1.33, -21.33, 0.00, -20.00, 1.33, -18.67, 2.67, -17.33, 4.00,
    -16.00, 5.33, -14.67, 6.67, -13.33, 8.00, -12.00, 9.33, -10.67, 10.67,
])


def scan(n, seed=0):
    """n points on the beams at random azimuths and ranges 2-80 m, with rings."""
    rng = np.random.default_rng(seed)
    laser = rng.integers(0, 32, n)
    az = np.radians(rng.uniform(0, 360, n))
    el = np.radians(ELEVATIONS[laser])
    r = rng.uniform(2, 80, n)
    ring = np.argsort(np.argsort(ELEVATIONS, kind="stable"), kind="stable")[laser]
    return np.stack(
        [r * np.cos(el) * np.cos(az), -r * np.cos(el) * np.sin(az), r * np.sin(el),
         rng.uniform(0, 255, n), ring],
        axis=1,
    ).astype(np.float32)


def timed(f, repeat):
    f()  # warm-up (builds the chain's per-seed state, touches the pages)
    out = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        out.append((time.perf_counter() - t) * 1e3)
    out.sort()
    return statistics.median(out), out[len(out) // 10], out[(9 * len(out)) // 10]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=35000)
    ap.add_argument("--repeat", type=int, default=200)
    args = ap.parse_args()
    chain = ln.Chain.from_dict(CONFIG)
    pts = scan(args.points)
    out = chain.apply(pts)
    print(f"{args.points} points, stages {chain.stages}: fates "
          + ", ".join(f"{ln.FATES[i]} {c}" for i, c in enumerate(np.bincount(out['fate'], minlength=6)) if c))
    for label, threads in (("1 thread", 1), ("default pool", None)):
        med, p10, p90 = timed(lambda: chain.apply(pts, frame=3, threads=threads), args.repeat)
        print(f"chain.apply ({label}): median {med:.2f} ms (p10 {p10:.2f}, p90 {p90:.2f}) over {args.repeat} runs")
    med, p10, p90 = timed(lambda: ln.points_to_returns(pts), args.repeat)
    print(f"points_to_returns alone: median {med:.2f} ms (p10 {p10:.2f}, p90 {p90:.2f})")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Times lidar_noise's Chain.apply on one nuScenes-sized scan, conversion to and from
numpy included, and splits the time between the package's conversion and the noise
stages: the issue 32 benchmark, run by hand (not in CI: nothing may depend on machine
speed).

    pip install ./python
    python scripts/dev/python_bench.py [--scan FILE.pcd.bin] [--config configs/adverse-weather.toml]
                                   [--repeat 50]

The scan: a nuScenes LIDAR_TOP sweep (.pcd.bin, float32 x y z intensity ring; nuScenes
records it with an HDL-32E turning at 20 Hz, 1085 firings x 32 lasers = 34,720 slots a
turn) when `--scan` names one, else a synthetic street built here the same way: every
firing of the 20 Hz grid cast into a scene (road plane 1.84 m below the sensor, the
LIDAR_TOP's height; house fronts 12 m either side, 12 m high; cross walls at 60 m; a row
of parked cars each side), a return where a ray hits something within 100 m, none where
it leaves to the sky (the sensor's empty slots, where the weather stages add echoes).

The chain: a configuration file as a user writes it, by default
configs/adverse-weather.toml (fog MOR 300 m, rain 3.125 mm/h Mie with drop echoes and
LISA range noise, snow "moderate", the reference power model and the [detection] filter
0.1 % power, 0.9 m), applied with rotation_hz 20 (nuScenes) and threads=1 (one core).

Prints wall time (median, 10th-90th percentile) and CPU time (median; time.process_time
counts every thread of the process, so threads=1's pool thread too, and not the time the
process waited for a core on a shared machine) over --repeat runs of:
  - apply, whole chain, threads=1 and rayon's default pool;
  - apply with the same configuration and no noise stage (the package's conversion:
    numpy columns in, points_to_returns, detection filter, records out);
  - apply with each noise stage alone (its share = that minus the no-stage time);
  - points_to_returns alone.
"""

import argparse
import os
import statistics
import sys
import time

import numpy as np

import lidar_noise as ln

try:
    import tomllib
except ImportError:  # Python < 3.11
    tomllib = None

# HDL-32E elevations by laser id (manual); ring = rank of the elevation (0 lowest).
ELEVATIONS = np.array([
    -30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33, -25.33, -4.00, -24.00,
    -2.67, -22.67, -1.33, -21.33, 0.00, -20.00, 1.33, -18.67, 2.67, -17.33, 4.00,
    -16.00, 5.33, -14.67, 6.67, -13.33, 8.00, -12.00, 9.33, -10.67, 10.67,
])


def _box_hits(o_dir, lo, hi):
    """Ray parameter t of the first hit of rays from the origin along o_dir (N, 3) with
    the axis-aligned box [lo, hi] (inf where missed): the slab method."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / o_dir
        t1 = lo * inv
        t2 = hi * inv
    tmin = np.nanmax(np.minimum(t1, t2), axis=1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=1)
    hit = (tmax >= tmin) & (tmax > 0)
    return np.where(hit, np.where(tmin > 0, tmin, np.inf), np.inf)


def synthetic_scan(seed=0):
    """A street as the HDL-32E at 20 Hz sees it (see the module comment): float32
    (N, 5) x y z intensity(0-255) ring, in firing order."""
    rng = np.random.default_rng(seed)
    firings = round(1e6 / (20.0 * 46.08))
    az = np.radians(np.arange(firings) * 360.0 / firings)
    el = np.radians(ELEVATIONS)
    A, E = np.meshgrid(az, el, indexing="ij")
    d = np.stack([np.cos(E) * np.cos(A), -np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
    laser = np.tile(np.arange(32), firings)
    h = 1.84
    t = np.full(len(d), np.inf)
    refl = np.zeros(len(d))
    with np.errstate(divide="ignore", invalid="ignore"):
        tg = np.where(d[:, 2] < 0, -h / d[:, 2], np.inf)  # road
        tw = np.where(d[:, 1] != 0, 12.0 / np.abs(d[:, 1]), np.inf)  # house fronts
        tw = np.where(tw * d[:, 2] < 12.0 - h, tw, np.inf)
        tx = np.where(d[:, 0] != 0, 60.0 / np.abs(d[:, 0]), np.inf)  # cross walls
        tx = np.where(tx * d[:, 2] < 8.0 - h, tx, np.inf)
    for tt, rho in ((tg, 20.0), (tw, 60.0), (tx, 45.0)):
        closer = tt < t
        t[closer], refl[closer] = tt[closer], rho
    for x0 in np.arange(-50.0, 50.0, 6.5):  # parked cars, 4.5 x 1.8 x 1.5 m
        for y0 in (-7.5, 5.7):
            tb = _box_hits(d, np.array([x0, y0, -h]), np.array([x0 + 4.5, y0 + 1.8, -h + 1.5]))
            closer = tb < t
            t[closer], refl[closer] = tb[closer], 90.0
    hit = t < 100.0
    r = t[hit] * (1 + rng.normal(0, 0.002, hit.sum()))
    p = d[hit] * r[:, None]
    ring = np.argsort(np.argsort(ELEVATIONS, kind="stable"), kind="stable")[laser[hit]]
    inten = np.clip(refl[hit] + rng.normal(0, 8, hit.sum()), 0, 255)
    return np.column_stack([p, inten, ring]).astype(np.float32)


def load_scan(path):
    a = np.fromfile(path, dtype="<f4")
    if a.size % 5:
        sys.exit(f"{path}: {a.size * 4} bytes is not a whole number of 20-byte points")
    return a.reshape(-1, 5)


def timed(f, repeat):
    """Wall time median, 10th and 90th percentile, and median CPU time (every thread of
    the process) of `repeat` calls, in ms."""
    f()  # warm-up: builds the chain's per-seed state, the pool, touches the pages
    out, cpu = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        f()
        cpu.append((time.process_time() - c) * 1e3)
        out.append((time.perf_counter() - t) * 1e3)
    out.sort()
    return statistics.median(out), out[len(out) // 10], out[(9 * len(out)) // 10], statistics.median(cpu)


def fmt(m):
    return f"{m[0]:7.2f} ms ({m[1]:.2f}-{m[2]:.2f}) | {m[3]:7.2f} ms"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scan", help="a nuScenes .pcd.bin (default: the synthetic street)")
    ap.add_argument("--config", default=os.path.join(os.path.dirname(__file__), "..", "..",
                                                     "configs", "adverse-weather.toml"))
    ap.add_argument("--repeat", type=int, default=50)
    ap.add_argument("--rotation-hz", type=float, default=20.0)
    args = ap.parse_args()
    if tomllib is None:
        sys.exit("needs Python 3.11 or later (tomllib) to split the configuration by stage")
    pts = load_scan(args.scan) if args.scan else synthetic_scan()
    with open(args.config, "rb") as f:
        table = tomllib.load(f)
    chain = ln.Chain.from_dict(table)
    stages = table.get("noise", [])
    bare = ln.Chain.from_dict({k: v for k, v in table.items() if k != "noise"})
    kw = dict(frame=3, rotation_hz=args.rotation_hz)

    out = chain.apply(pts, threads=1, **kw)
    fates = np.bincount(out["fate"], minlength=len(ln.FATES))
    print(f"scan: {args.scan or 'synthetic street (scripts/dev/python_bench.py)'}: {len(pts)} points")
    print(f"config: {args.config}: stages {chain.stages}, rotation_hz {args.rotation_hz}")
    print("fates: " + ", ".join(f"{ln.FATES[i]} {c}" for i, c in enumerate(fates) if c)
          + f"; {len(out)} rows, {int(out['kept'].sum())} kept")
    print(f"numpy {np.__version__}, Python {sys.version.split()[0]}, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at start")
    whole1 = timed(lambda: chain.apply(pts, threads=1, **kw), args.repeat)
    wholep = timed(lambda: chain.apply(pts, **kw), args.repeat)
    conv = timed(lambda: bare.apply(pts, threads=1, **kw), args.repeat)
    p2r = timed(lambda: ln.points_to_returns(pts, rotation_hz=args.rotation_hz), args.repeat)
    print("| what (threads=1 unless said) | wall: median (p10-p90) | CPU: median |")
    print("|---|---|---|")
    print(f"| apply, whole chain | {fmt(whole1)} |")
    print(f"| apply, whole chain, default pool | {fmt(wholep)} |")
    print(f"| apply, no noise stage (conversion + detection filter) | {fmt(conv)} |")
    print(f"| points_to_returns alone | {fmt(p2r)} |")
    for s in stages:
        one = ln.Chain.from_dict({**table, "noise": [s]})
        m = timed(lambda: one.apply(pts, threads=1, **kw), args.repeat)
        print(f"| apply, {s['type']} alone (stage: CPU {m[3] - conv[3]:.2f} ms) | {fmt(m)} |")
    print(f"| stages in the whole chain (whole - no stage) | {whole1[0] - conv[0]:7.2f} ms "
          f"| {whole1[3] - conv[3]:7.2f} ms |")
    print(f"load average {os.getloadavg()[0]:.2f} at end")


if __name__ == "__main__":
    main()

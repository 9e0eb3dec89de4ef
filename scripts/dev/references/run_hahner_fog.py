#!/usr/bin/env python3
"""Runs Hahner et al.'s released fog simulation (LiDAR_fog_sim, fog_simulation.py,
`simulate_fog`) on the returns of PLY files and prints one JSON object of numbers.

Usage: run_hahner_fog.py SNAPSHOT_DIR PLY... [--visibilities 50,100,...]
SNAPSHOT_DIR is a checkout of github:MartinHahner/LiDAR_fog_sim (fog_simulation.py and
integral_lookup_tables/). Nothing of it is copied: it is imported from there.

Layout: Hahner's point cloud is N x 5 float32 (x, y, z, intensity, 5th feature), as in its
own __main__ (Seeing Through Fog HDL-64 bins: intensity 0..255). We give x, y, z in metres,
the HDL-32E intensity byte as recorded (0..255) and the ring as the 5th feature (kept
unchanged by the simulation).

Settings: those of the released script's __main__: ParameterSet(alpha=alpha,
gamma=0.000001), simulate_fog(p, points, 10) (noise = 10, noise_variant 'v1', gain False,
hard and soft), the 'original' integral tables (nearest tabulated alpha), alpha = ln(20)/V.
Quirk of the released ParameterSet: beta (= 0.046 / MOR) and MOR are computed from the
default alpha 0.06 BEFORE the keyword arguments are applied, so the released script uses
beta = 0.046 * 0.06 / ln 20 at every alpha. Run "released" reproduces that; run
"consistent" also passes beta = 0.046 / V and mor = V (the paper's beta for that V).
The module RNG (default_rng(42)) is reset before each visibility, so every V is
reproducible on its own.
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import load_points, quantiles  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("snapshot")
    ap.add_argument("ply", nargs="+")
    ap.add_argument("--visibilities", default="50,100,150,300,600,1000,10000")
    args = ap.parse_args()
    sys.path.insert(0, os.path.abspath(args.snapshot))
    import fog_simulation as fs  # the reference, imported from the snapshot

    pts = load_points(args.ply)
    n = len(pts["x"])
    pc = np.stack([pts["x"], pts["y"], pts["z"], pts["intensity"], pts["ring"]],
                  axis=1).astype(np.float32)
    tables = fs.get_available_alphas()
    out = {"points": n, "tabulated_alphas": tables, "runs": {}}
    for variant in ("released", "consistent"):
        rows = []
        for v in [float(x) for x in args.visibilities.split(",")]:
            alpha = math.log(20) / v
            kw = {"alpha": alpha, "gamma": 0.000001}
            if variant == "consistent":
                kw.update(beta=0.046 / v, mor=v)
            p = fs.ParameterSet(**kw)
            fs.RNG = np.random.default_rng(seed=42)
            t0 = time.time()
            aug, fog, info = fs.simulate_fog(p, pc.copy(), 10)
            secs = time.time() - t0
            k = int(info["num_fog_responses"])
            r = np.linalg.norm(fog[:, :3], axis=1) if fog is not None else np.zeros(0)
            rows.append({
                "visibility_m": v, "alpha_per_m": round(alpha, 6),
                "table_alpha": min(tables, key=lambda a: abs(a - alpha)),
                "beta_used": float(p.beta),
                "fog_points": k, "fog_share_pct": round(100.0 * k / n, 3),
                "fog_range_m": quantiles(r),
                # the echoes' intensity (same scale as the input byte: Hahner scales the
                # fog response by the original intensity) and their rings (5th feature)
                "fog_intensity": quantiles(fog[:, 3]) if fog is not None else None,
                "fog_rings_lower_half_pct": (round(100.0 * float((fog[:, 4] < 16).sum())
                                                   / len(fog), 2) if fog is not None else None),
                "fog_range_hist_m": {f"{a}-{b}": int(((r >= a) & (r < b)).sum())
                                     for a, b in [(0, 2), (2, 5), (5, 10), (10, 20),
                                                  (20, 50), (50, 1000)]},
                "seconds": round(secs, 1)})
            print(f"{variant} V={v}: {k} fog points ({100.0 * k / n:.3f} %) in {secs:.1f} s",
                  file=sys.stderr)
        out["runs"][variant] = rows
    json.dump(out, sys.stdout, indent=1)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Runs LISA (Kilic et al. 2021, github:velatkilic/LISA, pylisa/lisa.py) on the returns of
PLY files and prints one JSON object of numbers.

Usage: run_lisa.py SNAPSHOT_DIR PLY... [--rates 1,7.29,25] [--sample N] [--seed S]
SNAPSHOT_DIR is a checkout of the LISA repository (pylisa/ with its mie shared library);
nothing of it is copied: `pylisa` is imported from there.

Layout: LISA takes N x 4 (x, y, z, reflectivity in [0, 1]). We give x, y, z in metres and
the reflectance our own power model assigns to the HDL-32E calibrated-reflectivity byte
(0..100 -> percent / 100, 101..255 retro-reflectors -> 1, floor 0.005 because LISA leaves a
reflectivity of exactly 0 as a lost point), so both tools see the same targets. Ring is not
used by LISA.

Settings: the class defaults of `Lisa` (m = 1.328, lam = 905 nm, rmax = 200 m, rmin = 1.5 m,
bdiv = 3 mrad, dst = 0.05 mm, dR = 0.09 m, mode 'strongest'): `augment_mc` for the Mie
(Marshall-Palmer) rain and the Marshall-Gunn snow, `msu_rain` for Goodin et al.'s model.
Their random draws come from numpy's global generator: np.random.seed(SEED) before every run.
--sample N runs a random subset of N points (chosen with numpy default_rng(SEED)), because
augment_mc is a per-point Python loop.
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import load_points, reflectance  # noqa: E402


def max_range(rho, alpha, coeff, floor):
    """Largest R with coeff * rho * exp(-2 alpha R) / R^2 >= floor (bisection)."""
    lo, hi = 0.01, 10000.0
    f = lambda r: coeff * rho * math.exp(-2 * alpha * r) / r ** 2 - floor  # noqa: E731
    if f(hi) > 0:
        return hi
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if f(mid) >= 0:
            lo = mid
        else:
            hi = mid
    return round(lo, 2)


def band_sd(r_clean, r_new, keep, lo=20.0, hi=30.0):
    """SD (m) of the range change of kept returns whose clean range is in [lo, hi)."""
    sel = keep & (r_clean >= lo) & (r_clean < hi)
    if sel.sum() < 2:
        return None
    return round(float(np.std(r_new[sel] - r_clean[sel])), 5)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("snapshot")
    ap.add_argument("ply", nargs="+")
    ap.add_argument("--rates", default="1,7.29,25")
    ap.add_argument("--snow-rates", default="1")
    ap.add_argument("--sample", type=int, default=0)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    sys.path.insert(0, os.path.abspath(args.snapshot))
    from pylisa.lisa import Lisa  # the reference, imported from the snapshot
    from pylisa.atmos_models import alpha_beta

    pts = load_points(args.ply)
    n_all = len(pts["x"])
    idx = np.arange(n_all)
    if args.sample and args.sample < n_all:
        idx = np.sort(np.random.default_rng(args.seed).choice(n_all, args.sample, replace=False))
    rho = reflectance(pts["intensity"][idx])
    pc = np.stack([pts["x"][idx], pts["y"][idx], pts["z"][idx], rho], axis=1)
    r_clean = np.linalg.norm(pc[:, :3], axis=1)
    n = len(pc)
    out = {"points_total": n_all, "points_run": n, "sample_seed": args.seed,
           "reflectance_mapping": "byte<=100: byte/100; >100: 1; floor 0.005",
           "rain_mie": [], "rain_msu_goodin": [], "snow_mie": []}

    def lisa_run(model, rate, key):
        lisa = Lisa(atm_model=model)
        nd = lisa.N_model(lisa.D, rate)
        alpha, beta = alpha_beta(nd, lisa.D, lisa.q_ext, lisa.q_back)
        pmin = 0.9 * lisa.rmax ** -2
        np.random.seed(args.seed)
        t0 = time.time()
        res = lisa.augment_mc(pc, rate)
        secs = time.time() - t0
        label = res[:, 4]
        r_new = np.linalg.norm(res[:, :3], axis=1)
        kept = label == 2
        # returns LISA's link budget loses without any rain (our computation, same formula)
        clear_lost = int((pc[:, 3] / r_clean ** 2 < pmin).sum())
        row = {
            "rate_mm_h": rate, "alpha_per_m": float(alpha), "beta_per_m": float(beta),
            "lidar_ratio_sr": float(alpha / (beta / (4 * math.pi))) if beta > 0 else None,
            "lost_pct": round(100.0 * float((label == 0).sum()) / n, 3),
            "lost_in_clear_air_pct": round(100.0 * clear_lost / n, 3),
            "echo_pct": round(100.0 * float((label == 1).sum()) / n, 3),
            "echo_range_m_median": (round(float(np.median(r_new[label == 1])), 3)
                                    if (label == 1).any() else None),
            "range_sd_20_30_m": band_sd(r_clean, r_new, kept),
            "max_range_10pct_lisa_budget_m": max_range(0.1, alpha, 1.0, pmin),
            "max_range_10pct_our_budget_m": max_range(0.1, alpha, 100.0, 1e-3),
            "seconds": round(secs, 1)}
        print(f"{key} {rate}: {row}", file=sys.stderr)
        out[key].append(row)

    for rate in [float(x) for x in args.rates.split(",")]:
        lisa_run("rain", rate, "rain_mie")
        lisa = Lisa(atm_model="rain")
        np.random.seed(args.seed)
        t0 = time.time()
        res = lisa.msu_rain(pc, rate)
        secs = time.time() - t0
        r_new = np.linalg.norm(res[:, :3], axis=1)
        kept = r_new > 0
        alpha = 0.01 * rate ** 0.6
        pmin_msu = 0.9 * lisa.rmax ** -2 / math.pi  # msu_rain's own threshold
        row = {"rate_mm_h": rate, "alpha_per_m": alpha,
               "lost_pct": round(100.0 * float((~kept).sum()) / n, 3),
               "lost_in_clear_air_pct": round(
                   100.0 * float((pc[:, 3] / r_clean ** 2 <= pmin_msu).sum()) / n, 3),
               "range_sd_20_30_m": band_sd(r_clean, r_new, kept),
               "max_range_10pct_lisa_budget_m": max_range(0.1, alpha, 1.0,
                                                          0.9 * lisa.rmax ** -2 / math.pi),
               "max_range_10pct_our_budget_m": max_range(0.1, alpha, 100.0, 1e-3),
               "seconds": round(secs, 2)}
        print(f"msu {rate}: {row}", file=sys.stderr)
        out["rain_msu_goodin"].append(row)
    for rate in [float(x) for x in args.snow_rates.split(",") if x]:
        lisa_run("snow", rate, "snow_mie")
    json.dump(out, sys.stdout, indent=1)


if __name__ == "__main__":
    main()

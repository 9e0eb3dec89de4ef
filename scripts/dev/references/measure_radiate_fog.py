#!/usr/bin/env python3
"""Per-frame figures of a real HDL-32E in fog: RADIATE's fog_6_0 sequence.

The anchor of the fog stage's calibration (docs/fidelity.md, "Fog: a real HDL-32E").
Input: a folder of RADIATE `velo_lidar` frames, NNNNNN.csv, one return a line as
x,y,z,intensity,ring (metres in the sensor's frame, intensity byte, ring 0 the lowest
beam). The sequence is in the RADIATE SDK's repository (marcelsheeny/radiate_sdk,
data/radiate/tiny_foggy/velo_lidar, 60 frames of a moving car; meta.json: fog_6_0).
No visibility is published for it.

What it measures, per frame (medians over the frames):
- the car body: cells of 1 degree of azimuth by one ring with a return within 3 m in at
  least 90 % of the frames (the mount and body behind the sensor), removed; with
  `--margin 2`, also the cells within 2 degrees of a body cell on the same ring (the
  body's edges flicker between frames);
- near-range transients: the returns within 3 m outside the body, their count, range
  quartiles and intensity bytes, and how many fall in open sectors (azimuths 10 degrees
  or more from any body cell) by range band;
- the far-range tail: returns at 20-30, 30-40 and 40-50 m outside the body.

Usage: python3 measure_radiate_fog.py FOLDER [--margin DEG] > figures.json
Needs numpy. Written for lidar-noise; independent of the RADIATE SDK's code.
"""
import argparse
import glob
import json

import numpy as np

NEAR = 3.0
BODY_FRAC = 0.90
N_AZ = 360
N_RING = 32


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("folder")
    ap.add_argument("--margin", type=int, default=0, help="degrees of body edge also removed")
    ap.add_argument("--frames", type=int, default=60)
    a = ap.parse_args()
    files = sorted(glob.glob(f"{a.folder}/[0-9]*.csv"))[: a.frames]
    frames = []
    for f in files:
        x, y, z, inten, ring = np.loadtxt(f, delimiter=",", ndmin=2).T
        r = np.sqrt(x * x + y * y + z * z)
        az = np.minimum((np.degrees(np.arctan2(y, x)) % 360.0).astype(int), N_AZ - 1)
        frames.append(dict(r=r, inten=inten, az=az, ring=ring.astype(int)))
    hit = np.zeros((N_RING, N_AZ))
    for fr in frames:
        near = fr["r"] < NEAR
        cells = np.unique(fr["ring"][near] * N_AZ + fr["az"][near])
        hit.flat[cells] += 1
    body = hit / len(frames) >= BODY_FRAC
    if a.margin:
        grown = body.copy()
        for d in range(1, a.margin + 1):
            grown |= np.roll(body, d, axis=1) | np.roll(body, -d, axis=1)
        body = grown
    # Open azimuths: 10 degrees or more from any body cell of any ring.
    any_body = body.any(axis=0)
    open_az = ~any_body
    for d in range(1, 11):
        open_az &= ~np.roll(any_body, d) & ~np.roll(any_body, -d)
    bands = [(0.0, 1.5), (1.5, 3.0), (3.0, 5.0), (5.0, 8.0)]
    counts, rr, ii = [], [], []
    open_counts = {f"{lo}-{hi}": [] for lo, hi in bands}
    far = {"20-30": [], "30-40": [], "40-50": []}
    for fr in frames:
        isbody = body[fr["ring"], fr["az"]]
        tr = (fr["r"] < NEAR) & ~isbody
        counts.append(int(tr.sum()))
        rr.append(fr["r"][tr])
        ii.append(fr["inten"][tr])
        isopen = open_az[fr["az"]]
        for lo, hi in bands:
            sel = isopen & (fr["r"] >= lo) & (fr["r"] < hi)
            open_counts[f"{lo}-{hi}"].append(int(sel.sum()))
        r = fr["r"][~isbody]
        for k, (lo, hi) in zip(far, [(20, 30), (30, 40), (40, 50)]):
            far[k].append(int(((r >= lo) & (r < hi)).sum()))
    rr, ii = np.concatenate(rr), np.concatenate(ii)
    med = lambda v: float(np.median(v))
    out = {
        "frames": len(frames),
        "margin_deg": a.margin,
        "body_cells": int(body.sum()),
        "open_azimuth_deg": int(open_az.sum()),
        "near_transients": {
            "per_frame": {"median": med(counts), "min": int(min(counts)), "max": int(max(counts))},
            "range_m": {"q25": float(np.percentile(rr, 25)), "median": med(rr),
                        "q75": float(np.percentile(rr, 75))} if rr.size else None,
            "intensity": {"median": med(ii), "p95": float(np.percentile(ii, 95))} if ii.size else None,
        },
        "open_sectors_per_frame_median": {k: med(v) for k, v in open_counts.items()},
        "open_sectors_per_frame_max": {k: int(max(v)) for k, v in open_counts.items()},
        "far_tail_per_frame_median": {k: med(v) for k, v in far.items()},
    }
    out["ratio_30_40_over_20_30"] = out["far_tail_per_frame_median"]["30-40"] / max(
        out["far_tail_per_frame_median"]["20-30"], 1.0)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()

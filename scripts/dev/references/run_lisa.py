#!/usr/bin/env python3
"""Runs LISA (Kilic et al. 2021, github:velatkilic/LISA, pylisa/lisa.py) on the returns of
PLY files and prints one JSON object of numbers.

Usage: run_lisa.py SNAPSHOT_DIR PLY... [--rates 1,7.29,25] [--snow-rates 1] [--sample N]
       [--seed S] [--optics lisa|hdl32e|replica]
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

--optics lisa (default): LISA as published, untouched.

--optics hdl32e: LISA with this tool's finite optics (issue 50). What LISA does per return
(`Lisa.lisa_mc`, strongest mode): the beam is a cone from a point, diameter
D_b(r) = r tan(bdiv); the particles above dst in it number N_tot (pi/3) R (D_b(R)/2)^2,
randomly rounded (one uniform); each lies at r = R u^(1/3) (uniform in the cone's volume)
and is dropped below rmin; its diameter D comes from LISA's size sampler; it returns
P = rho_F exp(-2 alpha r) min(1, (D / D_b(r))^2) / r^2 and the receiver sees every one;
the strongest of the object (rho exp(-2 alpha R) / R^2) and the particles is reported if
it reaches P_min. The cone, the range law and the share are local expressions inside that
one method (no function or attribute to patch them through), so `lisa_mc` is replaced,
on the Lisa instance only, by `matched_step` below (this file's own code, written from
LISA's description: no LISA file is edited or copied). It keeps LISA's pieces and order:
its alpha (`alpha_beta` of its N_model and Mie tables, the same extinction), N_tot,
N_sam (its Marshall-Palmer / Marshall-Gunn sizes), rho_F of its refractive index, rmin,
P_min = 0.9 / rmax^2, dR, the strongest-return rule, the object's range noise, the random
rounding and its global numpy stream, and LISA's own `augment_mc` loop. It swaps, as this
tool's particles.rs does (`Population::with_optics`, `lit_beam`, `power`, `particles`):
 - the lit beam: radius w(r) = a_t + r t from the exit aperture, a_t = 10 mm (20 mm
   aperture, fog.rs HDL32E_APERTURE_MM), t = tan(bdiv) / 2 (our population keeps its own
   divergence, 3 mrad = LISA's bdiv, and `with_optics` sets theta so that
   tan(theta / 2) = tan(bdiv) / 2); the expected count is N_tot times the lit frustum
   (pi / 3t) (w(R)^3 - a_t^3) instead of the cone, and a particle lies where w(r)^3 is
   uniform on [a_t^3, w(R)^3] (uniform in the frustum's volume) instead of at R u^(1/3);
 - the share of the beam a particle intercepts: min(1, (D / 2 w(r))^2) instead of
   min(1, (D / D_b(r))^2), in its power and in the reflectance it is reported with;
 - the receiver: a particle is seen only with probability xi(r) (one more uniform per
   particle, drawn for all of a beam's particles right after N_sam's; an unseen particle
   is removed; particles.rs draws it only for particles bright enough to be detected,
   the same in distribution), xi the biaxial overlap of fog.rs `Biaxial::overlap` (top-hat beam disk of
   radius w(r), receiver field disk a_r + r tan(theta_r / 2), centres d apart:
   intersection over beam area) with `hdl32e_optics()`: d = 30 mm, a_r = 10 mm
   (20 mm), theta_r = 4.1 mrad, and the beam's theta of `with_optics` above (3 mrad, not
   the fog stage's 3.3 mrad): xi = 0 below R1 = 2.82 m (2.70 m with 3.3 mrad), 1 from
   R2 = 54.5 m.
What stays LISA's and differs from this tool (so the comparison isolates the optics):
LISA's size laws (no 6 mm cap on drops; snow by melted diameter), its Fresnel rho_F, its
threshold P_min against our kappa / threshold, its extinction. Only the 'strongest' mode
is replaced; `msu_rain` (no particles) runs only with --optics lisa. --optics replica runs `matched_step` with LISA's own cone (a_t = 0,
t = tan(bdiv) / 2, share against r tan(bdiv), xi = 1, no extra draw): it must give the
labels of --optics lisa draw for draw (checked: identical labels, coordinates within
rounding), which shows the replacement differs from LISA only by the swap.
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


# This tool's HDL-32E optics (src/noise/world/fog.rs `hdl32e_optics`), in metres / radians.
HDL32E_SEPARATION_M = 30e-3
HDL32E_APERTURE_RADIUS_M = 10e-3   # both apertures 20 mm across
HDL32E_FOV_RAD = 4.1e-3


def disk_intersection(d, a, b):
    """Area of the intersection of disks of radii a and b (arrays) whose centres are d
    apart (as fog.rs `disk_intersection`)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    out = np.zeros(np.broadcast(a, b).shape)
    inside = d <= np.abs(a - b)
    out[inside] = np.pi * np.minimum(a, b)[inside] ** 2
    part = (d < a + b) & ~inside
    if part.any():
        aa, bb = a[part], b[part]
        ca = np.clip((d * d + aa * aa - bb * bb) / (2 * d * aa), -1, 1)
        cb = np.clip((d * d + bb * bb - aa * aa) / (2 * d * bb), -1, 1)
        k = np.maximum((-d + aa + bb) * (d + aa - bb) * (d - aa + bb) * (d + aa + bb), 0)
        out[part] = aa * aa * np.arccos(ca) + bb * bb * np.arccos(cb) - 0.5 * np.sqrt(k)
    return out


class Optics:
    """The lit beam w(r) = a + r t and the receiver's share xi(r) a particle is seen with."""

    def __init__(self, kind, bdiv):
        self.kind = kind
        self.t = math.tan(bdiv) / 2  # LISA's cone and our `lit_beam` alike
        self.a = HDL32E_APERTURE_RADIUS_M if kind == "hdl32e" else 0.0
        self.bdiv = bdiv
        # the full angle `Population::with_optics` gives the overlap: tan(theta/2) = t
        theta_t = 2 * math.atan(self.t)
        d, ar, tr = HDL32E_SEPARATION_M, HDL32E_APERTURE_RADIUS_M, math.tan(HDL32E_FOV_RAD / 2)
        self.r1 = max((d - self.a - ar) / (math.tan(theta_t / 2) + tr), 0.0)
        self.r2 = (d + self.a - ar) / (tr - math.tan(theta_t / 2))

    def radius(self, r):
        return self.a + r * self.t

    def volume(self, r):
        """Lit volume (m^3) from the sensor to r."""
        if self.a == 0:  # LISA's cone, LISA's expression
            return (math.pi / 3) * r * (1e-3 * (1e3 * math.tan(self.bdiv) * r) / 2) ** 2
        return math.pi / (3 * self.t) * (self.radius(r) ** 3 - self.a ** 3)

    def place(self, big_r, u):
        """Ranges of particles uniform in the lit volume to big_r, from uniforms u."""
        if self.a == 0:
            return big_r * u ** (1 / 3)
        lo, hi = self.a ** 3, self.radius(big_r) ** 3
        return (np.cbrt(lo + u * (hi - lo)) - self.a) / self.t

    def share(self, d_mm, r):
        """Share of the beam a particle of d_mm intercepts at r."""
        if self.a == 0:  # LISA: against D_b = r tan(bdiv), in mm
            return np.minimum((d_mm / (1e3 * math.tan(self.bdiv) * r)) ** 2, 1.0)
        return np.minimum((1e-3 * d_mm / (2 * self.radius(r))) ** 2, 1.0)

    def xi(self, r):
        """fog.rs `Biaxial::overlap`: beam disk w(r), field disk a_r + r tan(theta_r/2)."""
        wt = self.radius(r)
        wr = HDL32E_APERTURE_RADIUS_M + r * math.tan(HDL32E_FOV_RAD / 2)
        return np.minimum(disk_intersection(HDL32E_SEPARATION_M, wt, wr) / (np.pi * wt * wt), 1.0)


def matched_step(lisa, optics, alpha, x, y, z, ref, rr):
    """One return through LISA's hybrid Monte Carlo with `optics` (module docstring):
    (x, y, z, reflectance, label) as `Lisa.lisa_mc` gives them, strongest mode."""
    rmin, pmin = lisa.rmin, 0.9 * lisa.rmax ** -2
    big_r = math.sqrt(x * x + y * y + z * z)
    count = 0
    if big_r > rmin:
        mean = lisa.N_tot(rr, lisa.dst) * optics.volume(big_r)
        count = int(np.floor(mean) + (np.random.rand() < mean - int(mean)))
    r = optics.place(big_r, np.random.rand(count))
    r = r[r > rmin]
    p_obj = ref * math.exp(-2 * alpha * big_r) / big_r ** 2
    best = None
    if len(r):
        d = lisa.N_sam(rr, len(r), lisa.dst)
        if optics.kind == "hdl32e":  # in the receiver's field with probability xi(r)
            seen = np.random.rand(len(r)) < optics.xi(r)
            r, d = r[seen], d[seen]
        if len(r):
            rho_f = abs((lisa.m - 1) / (lisa.m + 1)) ** 2
            refl = rho_f * np.exp(-2 * alpha * r) * optics.share(d, r)
            k = int(np.argmax(refl / r ** 2))
            best = (float(r[k]), float(refl[k]), float(refl[k] / r[k] ** 2))
    if best is not None and best[2] > p_obj:
        if best[2] < pmin:  # neither reaches P_min
            new_r, new_ref, label = 0.0, 0.0, 0
        else:
            new_r, new_ref, label = best[0], best[1], 1
    elif p_obj < pmin:
        new_r, new_ref, label = 0.0, 0.0, 0
    else:
        sig = lisa.dR / math.sqrt(2 * (p_obj / pmin))
        new_r = big_r + np.random.normal(0, sig)
        new_ref, label = ref * math.exp(-2 * alpha * big_r), 2
    scale = new_r / big_r if big_r > 0 else 0.0
    return x * scale, y * scale, z * scale, new_ref, label


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("snapshot")
    ap.add_argument("ply", nargs="+")
    ap.add_argument("--rates", default="1,7.29,25")
    ap.add_argument("--snow-rates", default="1")
    ap.add_argument("--sample", type=int, default=0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--optics", choices=["lisa", "hdl32e", "replica"], default="lisa",
                    help="lisa: LISA as published; hdl32e: our finite optics swapped in; "
                         "replica: the swap machinery with LISA's cone (a check)")
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
    if args.optics != "lisa":
        o = Optics(args.optics, Lisa().bdiv)
        out["optics"] = args.optics
        out["optics_used"] = (
            f"lit beam radius {o.a * 1e3:g} mm + r tan(bdiv)/2, bdiv = {o.bdiv * 1e3:g} mrad; "
            + ("share (D / 2 w(r))^2; seen with probability xi(r): biaxial, axes "
               f"{HDL32E_SEPARATION_M * 1e3:g} mm apart, apertures "
               f"{HDL32E_APERTURE_RADIUS_M * 2e3:g} mm, field {HDL32E_FOV_RAD * 1e3:g} mrad, "
               f"R1 = {o.r1:.3f} m, R2 = {o.r2:.1f} m"
               if args.optics == "hdl32e" else "LISA's cone through the replacement, xi = 1"))
        del out["rain_msu_goodin"]  # no particles: the optics do not enter it

    def lisa_run(model, rate, key):
        lisa = Lisa(atm_model=model)
        nd = lisa.N_model(lisa.D, rate)
        alpha, beta = alpha_beta(nd, lisa.D, lisa.q_ext, lisa.q_back)
        pmin = 0.9 * lisa.rmax ** -2
        if args.optics != "lisa":
            if lisa.mode != "strongest":
                sys.exit("--optics replaces only the 'strongest' mode")
            optics = Optics(args.optics, lisa.bdiv)
            # this instance only; augment_mc (LISA's loop) calls it per return
            lisa.lisa_mc = lambda x, y, z, ref, rr: matched_step(lisa, optics, alpha,
                                                                 x, y, z, ref, rr)
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
            "echo_count": int((label == 1).sum()),
            "echo_range_m_median": (round(float(np.median(r_new[label == 1])), 3)
                                    if (label == 1).any() else None),
            "range_sd_20_30_m": band_sd(r_clean, r_new, kept),
            "max_range_10pct_lisa_budget_m": max_range(0.1, alpha, 1.0, pmin),
            "max_range_10pct_our_budget_m": max_range(0.1, alpha, 100.0, 1e-3),
            "seconds": round(secs, 1)}
        print(f"{key} {rate}: {row}", file=sys.stderr)
        out[key].append(row)

    for rate in [float(x) for x in args.rates.split(",") if x]:
        lisa_run("rain", rate, "rain_mie")
        if args.optics != "lisa":
            continue
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

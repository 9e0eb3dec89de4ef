#!/usr/bin/env python3
"""lidar_noise side by side with the Python peers on the same points and the same
corruption, in one run (issue 32, "Speed"): Hahner et al.'s LiDAR_fog_sim, LISA (Kilic et
al.) and lidar-aug (PyPI, C++/libtorch). Run by hand, not in CI (nothing may depend on
machine speed); prints a markdown table and the command that made it.

    python scripts/dev/python_peers.py --fog-sim DIR --lisa DIR [--scan FILE.pcd.bin]
                                   [--config configs/adverse-weather.toml] [--repeat 20]

DIR: a checked-out snapshot of github:MartinHahner/LiDAR_fog_sim (fog_simulation.py,
integral_lookup_tables/) and of github:velatkilic/LISA (pylisa/ with its mie library).
Nothing of theirs is copied: each is imported from the folder given. lidar-aug is imported
from the running interpreter when installed (pip install lidar-aug: it pins torch 2.2.0,
numpy 1.24.0 and Python < 3.12), else its cells say why not. The peers need numpy, scipy
< 1.14 (LISA imports scipy.integrate.trapz) and tqdm (LiDAR_fog_sim imports it); run
everything in one environment with lidar_noise installed (pip install ./python).

The points: a nuScenes LIDAR_TOP sweep (--scan, float32 x y z intensity(0-255) ring),
else the synthetic 20 Hz street of scripts/python_bench.py. Each tool gets them in its own
layout: lidar_noise the (N, 5) array as is (rotation_hz 20: nuScenes' HDL-32E); Hahner's
simulate_fog x y z intensity(0-255) ring as float64 (its own __main__'s layout); LISA
x y z and the reflectance our power model gives the intensity byte (0-100 percent,
retro-reflectors 1, floor 0.005; scripts/dev/references/common.py); lidar-aug a float32 torch
tensor x y z intensity/255 (its IntensityRange.MAX_INTENSITY_1).

The corruptions, each stage's settings taken from --config (by default
configs/adverse-weather.toml, a configuration as a user writes it):
  - fog, MOR V = the config's visibility_m (300 m): ours the fog stage; LiDAR_fog_sim
    simulate_fog(ParameterSet(alpha=ln(20)/V, gamma=1e-6), points, 10) as its __main__
    (nearest tabulated alpha); LISA "moderate_advection_fog" (fixed droplet
    distribution: its visibility is not a parameter, the table prints its MOR);
    lidar-aug fog(points, FogParameter.DIST, V).
  - rain, the config's rate_mm_h (3.125 mm/h): ours the rain stage (Mie, drop echoes);
    LISA "rain" augment (Marshall-Palmer drops, per-point Monte Carlo); lidar-aug
    rain(points, dims, drops, rate, EXPONENTIAL): its time grows with the drops it
    places (drops a m^3 x the volume `dims`), so it runs with far fewer than the rain
    has (Marshall-Palmer: N0 / Lambda = 2,470 drops/m^3 at 3.125 mm/h) in a smaller
    box than the scan (--lidar-aug-drops 10 a m^3 in +-20 m x +-20 m x -3..10 m): its
    cells are lower bounds of its time at the stated rate.
  - snow, the config's preset or rate (moderate: Gunn-Marshall R 8.85 mm/h): ours the
    snow stage; LISA "snow" augment at the same R; lidar-aug snow at the same R, with
    the drops and box of its rain (scale 1).
  - all three: ours the whole chain (one call); the peers one call per corruption in a
    row (LiDAR_fog_sim has fog only, so it has no cell there).
Timing: the least CPU time (time.process_time: every thread of the process; the
machine this was written on was shared, where wall time measures the other sessions as
much as the tool) and wall time of --repeat calls (calls that took over a second once,
LISA's per-point Python loops and lidar-aug's rain and snow: of --slow-repeat calls)
after one warm-up, on one core: lidar_noise threads=1; OMP/MKL/torch threads set to 1
before the peers are imported (numpy has no threads of its own here); lidar-aug sets
OpenMP to every core itself ("Setting OpenMP to use 2 threads!"), so its cells had all
the machine's cores. Each tool's set-up (LISA's Mie tables, lidar-aug's import,
our Chain.from_dict) is outside the timing, as a data loader builds it once. Every random
draw is seeded (ours seed 1 frame 0; numpy's global and LiDAR_fog_sim's RNG reset before
each call; torch.manual_seed).
"""

import argparse
import math
import os
import platform
import shlex
import contextlib
import sys
import time

# One core for every tool: set before numpy/torch start their pools.
for _v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

import lidar_noise as ln  # noqa: E402

try:
    import tomllib
except ImportError:  # Python < 3.11
    tomllib = None

HERE = os.path.dirname(os.path.abspath(__file__))
def load_scan(path):
    a = np.fromfile(path, dtype="<f4")
    if a.size % 5:
        sys.exit(f"{path}: {a.size * 4} bytes is not a whole number of 20-byte points")
    return a.reshape(-1, 5)


def timed(f, repeat):
    """Least CPU time (all the process's threads) and wall time of `repeat` calls of f
    (ms), and f's result: on a shared machine the least is the one least disturbed."""
    out = None
    cpu, wall = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = f()
        cpu.append((time.process_time() - c) * 1e3)
        wall.append((time.perf_counter() - t) * 1e3)
    return min(cpu), min(wall), out


def reflectance(intensity):
    """The reflectance our power model gives a calibrated-reflectivity byte (as
    scripts/dev/references/common.py)."""
    rho = np.where(intensity > 100, 1.0, intensity / 100.0)
    return np.maximum(rho, 0.005)


class Ours:
    """lidar_noise on the (N, 5) points."""

    name = "lidar_noise"

    def __init__(self, table, stages, pts):
        self.pts = pts
        base = {k: v for k, v in table.items() if k != "noise"}
        self.chains = {s["type"]: ln.Chain.from_dict({**base, "noise": [s]}) for s in stages}
        self.chains["all"] = ln.Chain.from_dict(table)

    def run(self, what):
        chain = self.chains[what]
        out = chain.apply(self.pts, seed=1, frame=0, rotation_hz=20.0, threads=1)
        fates = np.bincount(out["fate"], minlength=len(ln.FATES))
        changed = len(self.pts) - int(fates[0])
        return f"{changed} changed, {int(fates[5])} added"


class FogSim:
    """Hahner et al.'s simulate_fog (fog only)."""

    name = "LiDAR_fog_sim"

    def __init__(self, snapshot, pts, visibility):
        sys.path.insert(0, os.path.abspath(snapshot))
        cwd = os.getcwd()
        os.chdir(snapshot)  # its lookup tables are opened relative to the module's folder
        try:
            import fog_simulation  # the reference, imported from the snapshot
        finally:
            os.chdir(cwd)
        self.fs = fog_simulation
        self.snapshot = os.path.abspath(snapshot)
        self.pc = pts.astype(np.float64)
        self.alpha = math.log(20.0) / visibility

    def run(self, what):
        if what != "fog":
            return None
        fs = self.fs
        fs.RNG = np.random.default_rng(1)
        p = fs.ParameterSet(alpha=self.alpha, gamma=0.000001)
        cwd = os.getcwd()
        os.chdir(self.snapshot)
        try:
            aug, fog_pts, _info = fs.simulate_fog(p, self.pc.copy(), 10)
        finally:
            os.chdir(cwd)
        m = 0 if fog_pts is None else len(fog_pts)
        return f"{m} fog echoes"


class Lisa:
    """LISA's augment for rain, snow and moderate advection fog."""

    name = "LISA"

    def __init__(self, snapshot, pts, rain_rate, snow_rate):
        sys.path.insert(0, os.path.abspath(snapshot))
        from pylisa.lisa import Lisa as L  # the reference, imported from the snapshot
        from pylisa.atmos_models import alpha_beta

        self.pc = np.column_stack([pts[:, :3].astype(np.float64), reflectance(pts[:, 3])])
        self.models = {
            "fog": L(atm_model="moderate_advection_fog"),
            "rain": L(atm_model="rain"),
            "snow": L(atm_model="snow"),
        }
        f = self.models["fog"]
        alpha, _beta = alpha_beta(f.N_model(f.D), f.D, f.q_ext, f.q_back)
        self.fog_mor = math.log(20.0) / alpha
        self.rates = {"rain": rain_rate, "snow": snow_rate}

    def run(self, what):
        np.random.seed(1)
        if what == "all":
            pc = self.models["fog"].augment(self.pc)
            pc = self.models["rain"].augment(pc[:, :4], self.rates["rain"])
            pc = self.models["snow"].augment(pc[:, :4], self.rates["snow"])
            return f"{int((pc[:, 4] != 2).sum())} changed (snow pass)"
        if what == "fog":
            pc = self.models["fog"].augment(self.pc)
            return f"{int((pc[:, :3] == 0).all(axis=1).sum())} lost"
        pc = self.models[what].augment(self.pc, self.rates[what])
        return f"{int((pc[:, 4] != 2).sum())} changed"


@contextlib.contextmanager
def stdout_to_stderr():
    """lidar-aug's C++ prints "Setting OpenMP to use N threads!" on the process's standard
    output at every call; send it to standard error so that the table stays clean."""
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


class LidarAug:
    """lidar-aug's weather_simulations (torch tensors)."""

    name = "lidar-aug"

    def __init__(self, pts, visibility, rain_rate, snow_rate, drops, half_width):
        import torch
        from lidar_aug import weather_simulations as ws
        from lidar_aug import transformations as tr

        torch.set_num_threads(1)
        self.torch, self.ws = torch, ws
        pc = np.column_stack([pts[:, :3], pts[:, 3] / 255.0]).astype(np.float32)
        self.pc = torch.from_numpy(pc)
        w = float(half_width)
        self.dims = tr.DistributionRanges(
            tr.DistributionRange(-w, w), tr.DistributionRange(-w, w),
            tr.DistributionRange(-3.0, 10.0))
        self.visibility = visibility
        self.rain_rate, self.snow_rate, self.drops = rain_rate, snow_rate, int(drops)

    def _one(self, what, pc):
        ws = self.ws
        if what == "fog":
            return ws.fog(pc, ws.FogParameter.DIST, float(self.visibility))
        if what == "rain":
            return ws.rain(pc, self.dims, self.drops, float(self.rain_rate),
                           ws.Distribution.EXPONENTIAL)
        return ws.snow(pc, self.dims, self.drops, float(self.snow_rate), 1)

    def run(self, what):
        with stdout_to_stderr():
            return self._run(what)

    def _run(self, what):
        self.torch.manual_seed(1)
        if what == "all":
            pc = self.pc
            for w in ("fog", "rain", "snow"):
                pc = self._one(w, pc)
            return f"{pc.shape[0]} points out"
        return f"{self._one(what, self.pc).shape[0]} points out"


def cpu_name():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fog-sim", help="LiDAR_fog_sim snapshot folder")
    ap.add_argument("--lisa", help="LISA snapshot folder")
    ap.add_argument("--scan", help="a nuScenes .pcd.bin (default: the synthetic street)")
    ap.add_argument("--config", default=os.path.join(HERE, "..", "..", "configs", "adverse-weather.toml"))
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--slow-repeat", type=int, default=1,
                    help="calls of a peer that took over 1 s once (LISA's per-point loops)")
    ap.add_argument("--lidar-aug-drops", type=int, default=10,
                    help="lidar-aug's rain and snow particles a cubic metre")
    ap.add_argument("--lidar-aug-box", type=float, default=20.0,
                    help="half-width (m) of the box lidar-aug places them in (z -3..10 m)")
    args = ap.parse_args()
    if tomllib is None:
        sys.exit("needs Python 3.11 or later (tomllib)")
    if args.scan:
        pts = load_scan(args.scan)
    else:
        sys.path.insert(0, HERE)
        sys.dont_write_bytecode = True  # no __pycache__ left in scripts/
        from python_bench import synthetic_scan

        pts = synthetic_scan()
    with open(args.config, "rb") as f:
        table = tomllib.load(f)
    stages = {s["type"]: s for s in table.get("noise", [])}
    missing = [t for t in ("fog", "rain", "snow") if t not in stages]
    if missing:
        sys.exit(f"{args.config}: no {', '.join(missing)} stage (the table compares all three)")
    visibility = float(stages["fog"].get("visibility_m", 300.0))
    rain_rate = float(stages["rain"].get("rate_mm_h", 3.125))
    snow = stages["snow"]
    presets = {"light": (0.5, 2.0), "moderate": (1.0, 1.6), "heavy": (2.5, 1.6)}
    if "preset" in snow:  # Hahner's snowfall S at v_t as a Gunn-Marshall rate (snow.rs)
        s, v = presets[snow["preset"]]
        snow_rate = (s / (487.0 * 0.1 * 0.003 * v)) ** 1.5
    else:
        snow_rate = float(snow.get("rate_mm_h", 1.0))

    tools = [Ours(table, list(stages.values()), pts)]
    skipped = {}
    for name, make in (
        ("LiDAR_fog_sim", lambda: FogSim(args.fog_sim, pts, visibility) if args.fog_sim else None),
        ("LISA", lambda: Lisa(args.lisa, pts, rain_rate, snow_rate) if args.lisa else None),
        ("lidar-aug", lambda: LidarAug(pts, visibility, rain_rate, snow_rate,
                                       args.lidar_aug_drops, args.lidar_aug_box)),
    ):
        try:
            t = make()
        except Exception as e:  # a peer that does not install or import: say why
            skipped[name] = f"{type(e).__name__}: {e}".splitlines()[0][:160]
            continue
        if t is None:
            skipped[name] = "snapshot folder not given"
        else:
            tools.append(t)

    rows = [
        ("fog", f"fog, MOR {visibility:g} m"),
        ("rain", f"rain {rain_rate:g} mm/h"),
        ("snow", f"snow R {snow_rate:.2f} mm/h"),
        ("all", "fog + rain + snow"),
    ]
    cells = {}
    for what, _label in rows:
        for t in tools:
            t0 = time.perf_counter()
            once = t.run(what)  # the warm-up
            if once is None:
                continue
            slow = time.perf_counter() - t0 > 1.0
            cpu, wall, effect = timed(lambda: t.run(what), args.slow_repeat if slow else args.repeat)
            cells[(what, t.name)] = (cpu, wall, effect)
            print(f"  {what:5s} {t.name:14s} CPU {cpu:12.2f} ms, wall {wall:12.2f} ms ({effect})",
                  file=sys.stderr, flush=True)

    names = ["lidar_noise", "LiDAR_fog_sim", "LISA", "lidar-aug"]
    print(f"Command: `python {' '.join(shlex.quote(a) for a in sys.argv)}`")
    print()
    print(f"Machine: {cpu_name()}, {os.cpu_count()} CPUs, one core per tool; load average "
          f"{os.getloadavg()[0]:.2f} at the end; Python {platform.python_version()}, numpy "
          f"{np.__version__}. Points: {args.scan or 'synthetic street'} ({len(pts)} points). "
          f"Config: {os.path.relpath(args.config)}.")
    if "LISA" in [t.name for t in tools]:
        lisa = [t for t in tools if t.name == "LISA"][0]
        print(f"LISA's moderate advection fog has MOR {lisa.fog_mor:.0f} m (fixed by its droplets).")
    print()
    print("CPU time a call (least of the calls; all of the process's threads, so "
          "lidar-aug's OpenMP threads count), x = that over lidar_noise's; the least wall "
          "time and what the call did in brackets.")
    print()
    print("| corruption (same points) | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    for what, label in rows:
        ours = cells.get((what, "lidar_noise"))
        out = []
        for n in names:
            if n in skipped:
                out.append(f"not run ({skipped[n]})" if what == "fog" else "not run")
                continue
            c = cells.get((what, n))
            if c is None:
                out.append("—")
            elif n == "lidar_noise":
                out.append(f"{c[0]:.1f} ms (wall {c[1]:.1f}; {c[2]})")
            else:
                out.append(f"{c[0]:.1f} ms = {c[0] / ours[0]:.1f}x (wall {c[1]:.1f}; {c[2]})")
        print(f"| {label} | " + " | ".join(out) + " |")


if __name__ == "__main__":
    main()

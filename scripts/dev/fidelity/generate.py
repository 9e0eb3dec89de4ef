#!/usr/bin/env python3
"""Generates docs/fidelity.md: per noise stage, the quantity, its anchor, our value, the verdict.

Usage: generate.py --bin target/release/lidar-noise [--capture PCAP] [--frames 2..4]
                   [--refs docs/fidelity/references.json] [--out docs/fidelity.md]

Python 3 standard library only. Every "ours" number is measured here from the tool's own
output: `lidar-noise run CAPTURE -c CFG --frames F --keep-dropped`, where CFG is
configs/clear.toml plus one `[[noise]]` stage written to a temporary file; the returns'
PLY fields (fate, cause, range, range_clean, power, intensity) are joined per firing slot
(frame, laser, time) with the same run without the stage. The anchors are papers' numbers
(cited in ANCHORS below), the reference implementations' runs on the same points
(docs/fidelity/references.json, written by scripts/dev/references/run-references.sh) and the
shared real capture itself. An option the build does not know (the tool rejects unknown
keys) makes that row "not available in this build" instead of failing, so the report can
be regenerated before and after the model branches land.
"""
import argparse
import datetime
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from plyread import read_ply  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", ".."))
NA = "not available in this build"

# Fixed numbers from papers and datasheets (the anchors that are not runs).
HDL32E_ACCURACY_M = 0.02  # Velodyne HDL-32E datasheet: "accuracy < 2 cm (one sigma at 25 m)"
MP_N0 = 8000.0  # Marshall and Palmer 1948: N0 = 8000 m^-3 mm^-1, Lambda = 4.1 R^-0.21 mm^-1


def mp_alpha_geometric(rate):
    """Marshall-Palmer extinction with Q_ext = 2 (large-drop limit): pi N0 / Lambda^3, 1/m."""
    lam = 4.1 * rate ** -0.21
    return math.pi * MP_N0 / lam ** 3 * 1e-6


def max_range(rho, alpha, kappa=100.0, floor=1e-3):
    """Largest R with kappa rho exp(-2 alpha R) / R^2 >= floor (our power model), metres."""
    lo, hi = 0.01, 10000.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if kappa * rho * math.exp(-2 * alpha * mid) / mid ** 2 >= floor:
            lo = mid
        else:
            hi = mid
    return lo


class Unavailable(Exception):
    """The build rejected the stage's options (an option it does not have), or the run
    failed for another reason (`label` says which; the message is the tool's)."""

    def __init__(self, msg, label=NA):
        super().__init__(msg)
        self.label = label


class Runner:
    """Runs the binary on the capture with the base config plus one stage and measures."""

    def __init__(self, binary, capture, frames, base, tmp):
        self.binary, self.capture, self.frames, self.base, self.tmp = (
            binary, capture, frames, base, tmp)
        self.count = 0
        self.seconds = 0.0
        self.clean = None
        self.cache = {}

    def run(self, name, stage):
        """Result of the base config plus `stage` (a dict of TOML values, or None)."""
        key = json.dumps(stage, sort_keys=True)
        if key in self.cache:
            return self.cache[key]
        self.count += 1
        name = "".join(ch if ch.isalnum() or ch in ".-" else "-" for ch in name)
        cfg = os.path.join(self.tmp, f"{self.count:02d}-{name}.toml")
        with open(self.base) as f:
            text = f.read()
        if stage:
            text += "\n[[noise]]\n" + "".join(f"{k} = {toml(v)}\n" for k, v in stage.items())
        with open(cfg, "w") as f:
            f.write(text)
        out = os.path.join(self.tmp, f"{self.count:02d}-{name}")
        cmd = [self.binary, "--quiet", "run", self.capture, "-c", cfg, "--frames",
               self.frames, "--keep-dropped", "-o", out]
        t0 = time.time()
        p = subprocess.run(cmd, capture_output=True, text=True)
        self.seconds += time.time() - t0
        if p.returncode != 0:
            msg = p.stderr.strip().splitlines()[-1] if p.stderr.strip() else "exit %d" % p.returncode
            # drop the temporary file name: keep "noise[0].model (...): unknown key"
            short = msg.split(".toml: ", 1)[-1].split(" (known keys")[0][:160]
            if "unknown" in msg or "expected one of" in msg or "must be one of" in msg:
                res = Unavailable(short)
            else:
                # e.g. a value a new model rejects: say so in the row and keep going
                res = Unavailable(short, label="run failed")
                print(f"warning: {' '.join(cmd)}: {msg}", file=sys.stderr)
            self.cache[key] = res
            return res
        res = Measured(out, self.clean)
        self.cache[key] = res
        return res


def toml(v):
    """A Python value as a TOML literal."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml(x) for x in v) + "]"
    return repr(v)


class Measured:
    """The returns of one run, with the clean run's power and intensity per firing slot."""

    def __init__(self, out, clean):
        sub = [d for d in os.listdir(out) if os.path.isdir(os.path.join(out, d))][0]
        folder = os.path.join(out, sub)
        self.folder = folder
        with open(os.path.join(folder, "summary.json")) as f:
            self.summary = json.load(f)
        self.n_in = self.summary["totals"]["noise"]["returns_in"]
        self.frames = self.summary["totals"]["noise"]["frames"]
        self.rows = []  # (key, fate, cause, range, range_clean, power, intensity, ring)
        for name in sorted(os.listdir(folder)):
            if not name.endswith(".ply"):
                continue
            c = read_ply(os.path.join(folder, name))
            for i in range(len(c["x"])):
                k = (name, c["laser"][i], round(c["time"][i] * 1e7))
                self.rows.append((k, c["fate"][i], c["cause"][i], c["range"][i],
                                  c["range_clean"][i], c["power"][i], c["intensity"][i],
                                  c["ring"][i]))
        self.clean = clean

    def share(self, fates):
        """Share (%) of the recorded returns whose fate is in `fates`."""
        return 100.0 * sum(1 for r in self.rows if r[1] in fates) / self.n_in

    def echo_ranges(self):
        """Ranges of the spurious echoes (replaced or added)."""
        return sorted(r[3] for r in self.rows if r[1] in (4, 5))

    def echo_profile(self):
        """(median intensity byte, % in the lower 16 rings) of the spurious echoes."""
        e = [r for r in self.rows if r[1] in (4, 5)]
        if not e:
            return None
        return (statistics.median(r[6] for r in e),
                100.0 * sum(1 for r in e if r[7] < 16) / len(e))

    def kept(self, lo=0.0, hi=1e9):
        """Kept returns whose clean range is in [lo, hi)."""
        return [r for r in self.rows if r[1] == 0 and lo <= r[4] < hi]

    def range_sd(self, lo=20.0, hi=30.0):
        """SD of range - range_clean of kept returns with clean range in [lo, hi), m."""
        d = [r[3] - r[4] for r in self.kept(lo, hi)]
        return statistics.pstdev(d) if len(d) > 1 else None

    def power_ratio(self, lo, hi):
        """Median P / P_clean of kept returns in [lo, hi) whose clean power is unsaturated."""
        v = []
        for r in self.kept(lo, hi):
            c = self.clean.get(r[0])
            if c and 0 < c[0] < 1.0:
                v.append(r[5] / c[0])
        return statistics.median(v) if v else None

    def alpha_eff(self, lo=5.0, hi=40.0):
        """Extinction (1/m) read from the power loss: median of -ln(P/P_clean) / (2 R)
        over kept returns with clean range in [lo, hi) and unsaturated clean power."""
        v = []
        for r in self.kept(lo, hi):
            c = self.clean.get(r[0])
            if c and 0 < c[0] < 1.0 and r[5] > 0:
                v.append(-math.log(r[5] / c[0]) / (2 * r[4]))
        return statistics.median(v) if v else None

    def intensity(self, lo=30.0, hi=40.0):
        """(share of kept returns in [lo, hi) whose byte changed, median I/I_clean, share
        that follows I = round(I_clean P / P_clean) within 1) over clean bytes 1..100."""
        n = changed = follow = 0
        ratios = []
        for r in self.kept(lo, hi):
            c = self.clean.get(r[0])
            if not c or not 1 <= c[1] <= 100 or not 0 < c[0] < 1.0:
                continue
            n += 1
            changed += r[6] != c[1]
            ratios.append(r[6] / c[1])
            follow += abs(r[6] - round(c[1] * r[5] / c[0])) <= 1
        if not n:
            return None
        return 100.0 * changed / n, statistics.median(ratios), 100.0 * follow / n, n


def repeatability(folder, lo=20.0, hi=30.0, tol_deg=0.01):
    """The recorded sensor's own range noise from a static scene: each return of a frame
    with range in [lo, hi) is paired with the same laser's return in the next frame at
    the nearest azimuth (within tol_deg; pairs more than 0.3 m apart, edges, are left
    out); the SD of one return is that of the differences / sqrt 2. Returns (robust SD
    from the median absolute deviation, plain SD, pairs) in metres, or None."""
    import bisect
    files = sorted(f for f in os.listdir(folder) if f.endswith(".ply"))
    diffs = []
    for fa, fb in zip(files, files[1:]):
        a, b = read_ply(os.path.join(folder, fa)), read_ply(os.path.join(folder, fb))
        by_laser = {}
        for i in range(len(b["x"])):
            if b["fate"][i] == 0:
                by_laser.setdefault(b["laser"][i], []).append((b["azimuth"][i], b["range"][i]))
        for v in by_laser.values():
            v.sort()
        keys = {k: [x[0] for x in v] for k, v in by_laser.items()}
        for i in range(len(a["x"])):
            r = a["range"][i]
            if a["fate"][i] != 0 or not lo <= r < hi or a["laser"][i] not in keys:
                continue
            az, v = keys[a["laser"][i]], by_laser[a["laser"][i]]
            j = bisect.bisect_left(az, a["azimuth"][i])
            best = min((k for k in (j - 1, j) if 0 <= k < len(az)),
                       key=lambda k: abs(az[k] - a["azimuth"][i]), default=None)
            if best is None or abs(az[best] - a["azimuth"][i]) > tol_deg:
                continue
            d = r - v[best][1]
            if abs(d) < 0.3:
                diffs.append(d)
    if len(diffs) < 20:
        return None
    med = statistics.median(diffs)
    mad = statistics.median(abs(d - med) for d in diffs)
    return 1.4826 * mad / math.sqrt(2), statistics.pstdev(diffs) / math.sqrt(2), len(diffs)


def clean_index(m):
    """Firing slot -> (power, intensity) of the run without stages."""
    return {r[0]: (r[5], r[6]) for r in m.rows}


def fmt(x, nd=2, unit=""):
    if x is None:
        return "-"
    if isinstance(x, str):
        return x
    return f"{x:.{nd}f}{unit}"


def compare(ours, ref, rel=0.25, abs_=0.5, unit=""):
    """Verdict of one number against its anchor: within max(rel x ref, abs_) or not."""
    if ours is None or ref is None:
        return "-"
    d = ours - ref
    if abs(d) <= max(rel * abs(ref), abs_):
        return f"agrees (difference {d:+.2f}{unit})"
    k = f", ours/anchor = {ours / ref:.2g}" if ref else ""
    return f"**deviates** (difference {d:+.2f}{unit}{k})"


class Report:
    """Markdown assembled section by section."""

    def __init__(self):
        self.lines = []
        self.tally = []  # (section title, {verdict class: count})

    def section(self, title, text=""):
        self.tally.append((title, {}))
        self.lines += ["", f"## {title}", ""]
        if text:
            self.lines += [text, ""]
        self.lines += ["| quantity | anchor | anchor value | ours | verdict |", "|---|---|---|---|---|"]

    def row(self, q, anchor, aval, ours, verdict):
        self.lines.append(f"| {q} | {anchor} | {aval} | {ours} | {verdict} |")
        if ours in (NA, "run failed"):
            kind = "not available in this build" if ours == NA else "run failed"
        elif verdict.startswith(("agrees", "holds", "within")):
            kind = "agree/hold"
        elif verdict.startswith("**"):
            kind = "deviate/fail"
        else:
            kind = "no verdict"
        t = self.tally[-1][1]
        t[kind] = t.get(kind, 0) + 1
        if kind == "deviate/fail":
            name = re.sub(r" \(build[^)]*\)", "", q).split(";")[0].split(": bytes")[0]
            t.setdefault("_which", []).append(re.sub(r" \([^)]*\)$", "", name))

    def summary(self):
        """One line per section: how many rows agree, deviate, are not available."""
        out = ["", "## Standing in one line per stage", ""]
        for title, t in self.tally:
            which = t.pop("_which", [])
            parts = ", ".join(f"{n} {k}" for k, n in sorted(t.items()))
            line = f"- {title}: {parts or 'no rows'}."
            if which:
                line += " Deviating: " + "; ".join(which) + "."
            out.append(line)
        return out

    def note(self, text):
        self.lines += ["", text]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default=os.path.join(ROOT, "target/release/lidar-noise"))
    ap.add_argument("--capture", default=os.path.join(ROOT, "../shared/data/hdl32e/monterey.pcap"))
    ap.add_argument("--frames", default="2..4")
    ap.add_argument("--base", default=os.path.join(ROOT, "configs/clear.toml"))
    ap.add_argument("--refs", default=os.path.join(ROOT, "docs/fidelity/references.json"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs/fidelity.md"))
    args = ap.parse_args()
    if not os.path.exists(args.capture):
        sys.exit(f"needs the shared capture {args.capture}")
    refs = {}
    if os.path.exists(args.refs):
        with open(args.refs) as f:
            refs = json.load(f)
    t_start = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        r = Runner(args.bin, args.capture, args.frames, args.base, tmp)
        base = r.run("clear", None)
        r.clean = clean_index(base)
        base.clean = r.clean
        rep = Report()
        build(rep, r, base, refs)
        runs, run_secs = r.count, r.seconds
    total = time.time() - t_start
    head = header(args, refs, base, runs, run_secs, total)
    with open(args.out, "w") as f:
        f.write("\n".join(head + rep.summary() + rep.lines) + "\n")
    print(f"wrote {args.out}: {runs} runs, {total:.0f} s", file=sys.stderr)


def git(*a):
    p = subprocess.run(["git", "-C", ROOT, *a], capture_output=True, text=True)
    return p.stdout.strip()


def header(args, refs, base, runs, run_secs, total):
    rel = lambda p: os.path.relpath(p, ROOT)  # noqa: E731
    lines = [
        "# Fidelity report",
        "",
        "<!-- Generated by scripts/dev/make-fidelity.sh (scripts/dev/fidelity/generate.py); do not edit. -->",
        "",
        "Each weather, optics, attack and sensor stage against an anchor: a paper's figure or "
        "table, a published reference implementation run on the same points, or the real "
        "recording itself. Every \"ours\" value is measured by the generator from the tool's "
        "own output, so regenerating this page after a model changes updates every number.",
        "",
        f"- Build: `{git('describe', '--always', '--dirty')}` "
        + ("" if os.path.abspath(args.bin) == os.path.join(ROOT, "target/release/lidar-noise")
           else f"(scripts; binary `{args.bin}`) ") +
        f"(lidar-noise {base.summary.get('version', '?')}), generated "
        f"{datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M')} UTC "
        f"in {total:.0f} s ({runs} runs of the tool, {run_secs:.0f} s of them).",
        f"- Points: frames {args.frames} of `{rel(args.capture)}`"
        + (" (a real HDL-32E capture, vehicle stopped, clear weather)"
           if os.path.basename(args.capture) == "monterey.pcap" else "")
        + f": {base.n_in:,} recorded returns. Every run is "
        f"`lidar-noise run {rel(args.capture)} -c CFG --frames {args.frames} --keep-dropped`, "
        f"CFG = `{rel(args.base)}` plus the one `[[noise]]` stage shown in the row "
        "(its other options at their defaults); seed 42.",
        "- \"Lost\" is the share of recorded returns a stage removes beyond what the detection "
        f"filters already drop in clear air ({base.share((1, 2, 3)):.2f} % of these returns); "
        "\"echoes\" are returns replaced or added by spurious echoes (fog, drops, flakes, "
        "crosstalk, spoofing). Range SD is of range - range_clean of kept returns whose "
        "clean range is 20-30 m. Extinction is read from the power the tool reports: median "
        "of -ln(P / P_clean) / (2 R) over kept returns at 5-40 m.",
    ]
    if refs:
        h, lz = refs.get("hahner_fog", {}), refs.get("lisa", {})
        lines += [
            f"- Reference runs: docs/fidelity/references.json ({refs.get('date_utc', '?')} UTC, "
            f"`{refs.get('generated_by', '')}`; Python {refs.get('python')}, numpy "
            f"{refs.get('numpy')}, scipy {refs.get('scipy')}). Hahner's LiDAR_fog_sim "
            f"{h.get('commit', '?')[:10]} on {h.get('points', 0):,} points: `{h.get('command')}`. "
            f"LISA {lz.get('commit', '?')[:10]} on {lz.get('points_run', 0):,} of "
            f"{lz.get('points_total', 0):,} points: `{lz.get('command')}` "
            f"(reflectance {lz.get('reflectance_mapping')}; Mie library: {lz.get('mie_library')}).",
        ]
    else:
        lines.append("- Reference runs: docs/fidelity/references.json is absent; run "
                     "scripts/dev/references/run-references.sh to add them.")
    return lines


def build(rep, r, base, refs):
    lost0 = base.share((1, 2, 3))

    def lost(m):
        return m.share((1, 2, 3)) - lost0

    h = refs.get("hahner_fog", {}).get("runs", {})
    hc = {row["visibility_m"]: row for row in h.get("consistent", [])}
    hr = {row["visibility_m"]: row for row in h.get("released", [])}
    lz = refs.get("lisa", {})
    # LISA with this tool's optics (issue 50), by rate.
    lm = refs.get("lisa_matched", {})
    matched_mie = {x["rate_mm_h"]: x for x in lm.get("rain_mie", [])}
    matched_snow = {x["rate_mm_h"]: x for x in lm.get("snow_mie", [])}

    # ---- fog -------------------------------------------------------------------------
    rep.section("Fog (`type = \"fog\"`, defaults)",
                "Anchor: Hahner et al., ICCV 2021, released `simulate_fog` on the same points "
                "(\"paper beta\": beta = 0.046 / V as in the paper; \"as released\": its "
                "ParameterSet keeps beta of alpha = 0.06 for every alpha, see references.json). "
                "Clear air: the real capture, recorded in clear weather, has no fog echoes.")
    for v in (50.0, 100.0, 150.0, 300.0, 600.0, 1000.0, 10000.0, float("inf")):
        m = r.run(f"fog-{v}", {"type": "fog", "visibility_m": v})
        vs = "inf" if math.isinf(v) else f"{v:g} m"
        if isinstance(m, Unavailable):
            rep.row(f"V = {vs}: echoes (% of returns)", "", "", m.label, str(m))
            continue
        rep_pct, add_pct = m.share((4,)), m.share((5,))
        echoes = m.echo_ranges()
        med = statistics.median(echoes) if echoes else None
        if v >= 10000.0:
            rep.row(f"V = {vs}: fog echoes (replaced + added)", "clear air: the real capture; "
                    "issue 29 requirement", "0", f"{len(echoes)}",
                    "holds" if not echoes else f"**fails** ({len(echoes)} echoes)")
            continue
        ref = hc.get(v)
        aval = (f"{ref['fog_share_pct']:.2f} % (as released: {hr[v]['fog_share_pct']:.2f} %); "
                f"median echo range {fmt((ref['fog_range_m'] or {}).get('p50'), 2, ' m')}"
                if ref else "-")
        rep.row(f"V = {vs}: returns replaced by fog echoes (%); median echo range",
                "Hahner `simulate_fog`, same points", aval,
                f"{rep_pct:.2f} % (+ {add_pct:.2f} % added in empty slots); "
                f"median echo range {fmt(med, 2, ' m')}",
                compare(rep_pct, ref["fog_share_pct"] if ref else None, rel=0.5, abs_=1.0,
                        unit=" pp"))
        prof, hi_ = m.echo_profile(), (ref or {}).get("fog_intensity")
        if prof and ref and hi_:
            rep.row(f"V = {vs}: fog echoes' median intensity byte; share in the lower 16 rings",
                    "Hahner `simulate_fog` (its echo intensity scales the recorded byte)",
                    f"{hi_['p50']:.0f}; {ref['fog_rings_lower_half_pct']:.0f} %",
                    f"{prof[0]:.0f}; {prof[1]:.0f} %", "-")
        rep.row(f"V = {vs}: extinction read from power (1/m)", "ln(20) / V (Koschmieder, "
                "5 % contrast)", f"{math.log(20) / v:.4g}", fmt(m.alpha_eff(), 4),
                compare(m.alpha_eff(), math.log(20) / v, rel=0.05, abs_=0.0))
    for d in ("hahner", "advection", "radiation"):
        m = r.run(f"fog-droplets-{d}", {"type": "fog", "visibility_m": 300.0, "droplets": d})
        if isinstance(m, Unavailable):
            rep.row(f"V = 300 m, `droplets = \"{d}\"`: echoes (%)", "Mie backscatter of the "
                    "fog droplet distribution", "-", m.label, str(m))
        else:
            rep.row(f"V = 300 m, `droplets = \"{d}\"`: echoes replaced / added (%)",
                    "Hahner `simulate_fog` V = 300 m (paper beta)",
                    fmt(hc.get(300.0, {}).get("fog_share_pct"), 2, " %"),
                    f"{m.share((4,)):.2f} / {m.share((5,)):.2f} %",
                    compare(m.share((4,)), hc.get(300.0, {}).get("fog_share_pct"), 0.5, 1.0,
                            " pp"))

    # ---- fog against a real HDL-32E in fog -----------------------------------------------
    real = refs.get("radiate_fog", {})
    rf, rm = real.get("figures", {}), real.get("figures_margin", {})
    rep.section("Fog: a real HDL-32E (RADIATE `fog_6_0`)",
                "Anchor: 60 frames of a real HDL-32E driving in fog (RADIATE SDK, "
                "`data/radiate/tiny_foggy/velo_lidar`, sequence fog_6_0; no visibility "
                "published), measured by `scripts/dev/references/measure_radiate_fog.py` "
                "(references.json, `radiate_fog`). The car body (cells of 1 degree by one ring "
                "with a return within 3 m in 90 % of the frames) is removed; the returns left "
                "within 3 m sit at the body's flickering edges (with a 2-degree margin "
                "around the body they fall from the first to the second figure, and the open "
                "sectors, 10 degrees or more from the body, hold none within 3 m in any frame). "
                "Ours: defaults, one `fog` stage, the shared capture (a different, clear scene: "
                "the echo figures compare, the counts of hard returns only in ratio). The "
                "visibility in this model that gives the recording's far-tail ratio on the "
                "shared capture is the row's estimate.")
    near = rf.get("near_transients", {})
    nearm = rm.get("near_transients", {})
    opens = rf.get("open_sectors_per_frame_median", {})
    for v in (60.0, 90.0):
        m = r.run(f"fog-{v}", {"type": "fog", "visibility_m": v})
        if isinstance(m, Unavailable) or not rf:
            rep.row(f"V = {v:g} m: fog echoes", "RADIATE fog_6_0", "-",
                    getattr(m, "label", NA), "no reference figures" if not rf else str(m))
            continue
        e = [row for row in m.rows if row[1] in (4, 5)]
        per = len(e) / max(m.frames, 1)
        within3 = sum(1 for row in e if row[3] < 3.0) / max(m.frames, 1)
        ranges = sorted(row[3] for row in e)
        q = (lambda p: ranges[min(len(ranges) - 1, int(p * len(ranges)))]) if ranges else None
        rep.row(f"V = {v:g} m: fog echoes within 3 m a frame",
                "RADIATE: open sectors (median, max over 60 frames)",
                f"{opens.get('0.0-1.5', 0) + opens.get('1.5-3.0', 0):g} "
                f"(max {rf.get('open_sectors_per_frame_max', {}).get('1.5-3.0', '-')} at 1.5-3 m)",
                f"{within3:.1f}", "holds" if within3 < 1.0 else f"**deviates** ({within3:.1f})")
        rep.row(f"V = {v:g} m: fog echoes a frame; median range (IQR)",
                "RADIATE transients within 3 m (body edges, not fog): 90 % rule; 2-degree margin",
                f"{near.get('per_frame', {}).get('median', '-')} at "
                f"{fmt((near.get('range_m') or {}).get('median'), 2, ' m')}; "
                f"{nearm.get('per_frame', {}).get('median', '-')} at "
                f"{fmt((nearm.get('range_m') or {}).get('median'), 2, ' m')}",
                f"{per:.0f}; " + (f"{statistics.median(ranges):.2f} m ({q(0.25):.2f}-{q(0.75):.2f} m)"
                                  if ranges else "-"), "-")
        prof = m.echo_profile()
        ints = sorted(row[6] for row in e)
        ri = near.get("intensity") or {}
        if prof and ri:
            p95 = ints[min(len(ints) - 1, int(0.95 * len(ints)))]
            rep.row(f"V = {v:g} m: echo intensity byte, median; 95th percentile",
                    "RADIATE transients within 3 m", f"{ri['median']:g}; {ri['p95']:g}",
                    f"{prof[0]:g}; {p95:g}",
                    compare(prof[0], ri["median"], rel=0.5, abs_=2.0))
        k = [len(m.kept(lo, lo + 10.0)) for lo in (20.0, 30.0)]
        ratio = k[1] / k[0] if k[0] else None
        rr = rf.get("ratio_30_40_over_20_30")
        rep.row(f"V = {v:g} m: kept returns 30-40 m over 20-30 m",
                "RADIATE far tail (690 / 117 / 7.5 a frame at 20-30 / 30-40 / 40-50 m)",
                fmt(rr, 3), fmt(ratio, 3) + f" ({k[0]} / {k[1]})",
                compare(ratio, rr, rel=0.5, abs_=0.0))
    c = [len(base.kept(lo, lo + 10.0)) for lo in (20.0, 30.0)]
    if c[0]:
        rep.note(f"Clear air on the shared capture: {c[1] / c[0]:.3f} kept at 30-40 m over "
                 "20-30 m, the ratio fog takes down from.")

    # ---- rain --------------------------------------------------------------------------
    lisa_mie = {row["rate_mm_h"]: row for row in lz.get("rain_mie", [])}
    lisa_msu = {row["rate_mm_h"]: row for row in lz.get("rain_msu_goodin", [])}
    for model in ("goodin", "mie"):
        rep.section(f"Rain, `model = \"{model}\"`",
                    "Anchors: LISA (Kilic et al. 2021) run on the same points: `msu_rain` "
                    "(its implementation of Goodin et al. 2019) for goodin, `augment_mc` "
                    "(Marshall-Palmer drops, Mie efficiencies at 905 nm, m = 1.328) for mie; "
                    "the Marshall-Palmer integral with Q_ext = 2 by hand. LISA's link budgets "
                    "differ from ours: its detection threshold in reflectance / R^2 is "
                    "0.9 / rmax^2 = 2.25e-5 in `augment_mc` (a 10 % target reaches 66.7 m in "
                    "clear air) and 0.9 / (pi rmax^2) = 7.16e-6 in `msu_rain` (118 m), ours "
                    "p_th / kappa = 1e-5 (100 m); lost shares are compared beyond what each "
                    "loses in clear air, and differ by that much more where many returns sit "
                    "near the threshold.")
        for rate in (1.0, 7.29, 25.0):
            st = {"type": "rain", "rate_mm_h": rate, "model": model}
            m = r.run(f"rain-{model}-{rate}", st)
            label = f"{rate:g} mm/h"
            if isinstance(m, Unavailable) and model == "goodin":
                m = r.run(f"rain-{rate}", {"type": "rain", "rate_mm_h": rate})
                if not isinstance(m, Unavailable):
                    label += " (build without `model`: its rain is Goodin's)"
            if isinstance(m, Unavailable):
                rep.row(f"{label}: lost, range SD, extinction", "", "", m.label, str(m))
                continue
            a = m.alpha_eff()
            if model == "goodin":
                ref = lisa_msu.get(rate)
                rep.row(f"{label}: extinction (1/m)", "Goodin et al. 2019: 0.01 R^0.6",
                        f"{0.01 * rate ** 0.6:.4g}", fmt(a, 4),
                        compare(a, 0.01 * rate ** 0.6, rel=0.02, abs_=0.0))
            else:
                ref = lisa_mie.get(rate)
                la = ref["alpha_per_m"] if ref else None
                rep.row(f"{label}: extinction (1/m)", "LISA's Mie x Marshall-Palmer integral "
                        f"(pi N0 / Lambda^3 with Q_ext = 2: {mp_alpha_geometric(rate):.4g})",
                        fmt(la, 4), fmt(a, 4), compare(a, la, rel=0.05, abs_=0.0))
            if ref:
                lisa_lost = ref["lost_pct"] - ref.get("lost_in_clear_air_pct", 0.0)
                rep.row(f"{label}: lost beyond clear air (%)", "LISA on the same points "
                        "(its link budget)", f"{lisa_lost:.2f} %", f"{lost(m):.2f} %",
                        compare(lost(m), lisa_lost, rel=0.25, abs_=0.1, unit=" pp"))
                sd = m.range_sd()
                lisa_sd = ref["range_sd_20_30_m"] * 100 if ref["range_sd_20_30_m"] else None
                ours_sd = sd * 100 if sd is not None else None
                if model == "mie" and lisa_sd is not None:
                    # augment_mc's law sigma = dR / sqrt(2 P / Pmin) scales with
                    # sqrt(threshold): in our budget (p_th / kappa = 1e-5 against its
                    # 0.9 / rmax^2 = 2.25e-5) the same law gives sqrt(1e-5 / 2.25e-5) x
                    scale = math.sqrt(1e-5 / 2.25e-5)
                    rep.row(f"{label}: range noise SD at 20-30 m (cm)", "LISA on the same "
                            "points; x sqrt(1e-5 / 2.25e-5) = 0.667 for our threshold",
                            f"{lisa_sd:.2f}; in our budget {lisa_sd * scale:.2f}",
                            fmt(ours_sd, 2), compare(ours_sd, lisa_sd * scale, rel=0.1,
                                                     abs_=0.1, unit=" cm"))
                else:
                    rep.row(f"{label}: range noise SD at 20-30 m (cm)",
                            "LISA on the same points", fmt(lisa_sd, 2), fmt(ours_sd, 2),
                            compare(ours_sd, lisa_sd, rel=0.25, abs_=0.3, unit=" cm"))
                rep.row(f"{label}: range of a 10 % target, our power budget (m)",
                        "the reference's extinction in our budget",
                        fmt(ref["max_range_10pct_our_budget_m"], 1),
                        fmt(max_range(0.1, a) if a is not None else None, 1),
                        compare(max_range(0.1, a) if a is not None else None,
                                ref["max_range_10pct_our_budget_m"], rel=0.05, abs_=1.0,
                                unit=" m"))
                if model == "mie":
                    rep.row(f"{label}: drop echoes (% of returns)", "LISA `augment_mc` "
                            "(strongest return)", f"{ref['echo_pct']:.3f} %",
                            "see the backscatter row below", "-")
        if model == "mie":
            for rate in (7.29, 25.0):
                m = r.run(f"rain-mie-bs-{rate}", {"type": "rain", "rate_mm_h": rate,
                                                  "model": "mie", "backscatter": True})
                ref = lisa_mie.get(rate)
                if isinstance(m, Unavailable):
                    rep.row(f"{rate:g} mm/h, backscatter: drop echoes (%)", "LISA", "-",
                            m.label, str(m))
                    continue
                e = m.share((4,))
                rep.row(f"{rate:g} mm/h, `backscatter = true`: returns replaced by drop echoes "
                        "(+ added in empty slots) (% of returns)", "LISA `augment_mc`, same "
                        "points (replaces recorded returns only)",
                        fmt(ref["echo_pct"] if ref else None, 3, " %"),
                        f"{m.share((4,)):.3f} % (+ {m.share((5,)):.3f} %)",
                        compare(e, ref["echo_pct"] if ref else None, rel=0.5, abs_=0.05,
                                unit=" pp"))
                mref = matched_mie.get(rate)
                if mref:
                    rep.row(f"{rate:g} mm/h, `backscatter = true`: returns replaced by drop "
                            "echoes (% of returns), LISA with our optics",
                            "LISA `augment_mc` with the HDL-32E's exit aperture and receiver "
                            "overlap swapped in (`run_lisa.py --optics hdl32e`), same points",
                            f"{mref['echo_pct']:.3f} %", f"{e:.3f} %",
                            compare(e, mref["echo_pct"], rel=0.5, abs_=0.05, unit=" pp"))
            if lisa_mie:
                x = lisa_mie.get(7.29) or next(iter(lisa_mie.values()))
                rep.note(f"LISA's Mie lidar ratio alpha / (beta / 4 pi) at {x['rate_mm_h']:g} "
                         f"mm/h: {x['lidar_ratio_sr']:.1f} sr (its q_back is Bohren-Huffman's "
                         "backscatter efficiency, 4 pi times the differential one).")

    # ---- snow --------------------------------------------------------------------------
    rep.section("Snow (`type = \"snow\"`, defaults)",
                "Anchor: LISA snow mode (Marshall-Gunn flakes as ice spheres, m = 1.3031) on "
                "the same points; the rate is the melted-water equivalent in both.")
    for ref in lz.get("snow_mie", []) or [{"rate_mm_h": 1.0}]:
        rate = ref["rate_mm_h"]
        m = r.run(f"snow-{rate}", {"type": "snow", "rate_mm_h": rate})
        if isinstance(m, Unavailable):
            rep.row(f"{rate:g} mm/h", "", "", m.label, str(m))
            continue
        a = m.alpha_eff()
        if "alpha_per_m" not in ref:
            rep.row(f"{rate:g} mm/h: extinction (1/m); lost (%); flake echoes (%)",
                    "no reference run", "-", f"{fmt(a, 4)}; {lost(m):.2f} %; "
                    f"{m.share((4, 5)):.3f} %", "-")
            continue
        rep.row(f"{rate:g} mm/h: extinction (1/m)", "LISA's Mie x Marshall-Gunn integral",
                fmt(ref["alpha_per_m"], 4), fmt(a, 4),
                compare(a, ref["alpha_per_m"], rel=0.05, abs_=0.0))
        lisa_lost = ref["lost_pct"] - ref.get("lost_in_clear_air_pct", 0.0)
        rep.row(f"{rate:g} mm/h: lost beyond clear air (%)", "LISA on the same points "
                "(its link budget)", f"{lisa_lost:.2f} %", f"{lost(m):.2f} %",
                compare(lost(m), lisa_lost, rel=0.25, abs_=0.1, unit=" pp"))
        rep.row(f"{rate:g} mm/h: returns replaced by flake echoes (+ added in empty slots) "
                "(% of returns)", "LISA on the same points (replaces recorded returns only)",
                f"{ref['echo_pct']:.3f} %", f"{m.share((4,)):.3f} % (+ {m.share((5,)):.3f} %)",
                compare(m.share((4,)), ref["echo_pct"], rel=0.5, abs_=0.05, unit=" pp"))
        mref = matched_snow.get(rate)
        if mref:
            rep.row(f"{rate:g} mm/h: returns replaced by flake echoes (% of returns), LISA "
                    "with our optics", "LISA snow mode with the HDL-32E's exit aperture and "
                    "receiver overlap swapped in (`run_lisa.py --optics hdl32e`), same points",
                    f"{mref['echo_pct']:.3f} %", f"{m.share((4,)):.3f} %",
                    compare(m.share((4,)), mref["echo_pct"], rel=0.5, abs_=0.05, unit=" pp"))

    # ---- transmission conventions ------------------------------------------------------
    rep.section("Occlusion with transmission and lens damage",
                "Anchor: one convention for both (issue 29): a window of one-way transmission "
                "T is crossed twice, so a return's power is multiplied by T^2. Measured: "
                "median P / P_clean of kept returns, every laser behind the window.")
    occ = r.run("occlusion-t", {"type": "occlusion", "rings": list(range(32)),
                                "transmission": 0.5})
    if isinstance(occ, Unavailable):
        rep.row("occlusion `transmission = 0.5`: power factor", "T^2", "0.25", occ.label, str(occ))
    else:
        pr = occ.power_ratio(10.0, 200.0)
        rep.row("occlusion `transmission = 0.5`: power factor", "T^2 (two passes)", "0.25",
                fmt(pr, 3), compare(pr, 0.25, rel=0.02, abs_=0.0))
    ld = r.run("lens-damage", {"type": "lens_damage", "transmission": 0.5,
                               "scatter_probability": 0.0})
    if isinstance(ld, Unavailable):
        rep.row("lens_damage `transmission = 0.5`: power factor", "T^2", "0.25", ld.label, str(ld))
    else:
        pr = ld.power_ratio(10.0, 200.0)
        rep.row("lens_damage `transmission = 0.5`: power factor", "T^2 (two passes)", "0.25",
                fmt(pr, 3), compare(pr, 0.25, rel=0.02, abs_=0.0))

    # ---- intensity under weather ----------------------------------------------------------
    rep.section("Intensity under weather",
                "Anchor: the rule of issue 29 (reflectivity mode: the range compensation "
                "stays, atmospheric and optical losses show: I = I_clean x P / P_clean, rounded) "
                "and Filgueira et al., Measurement 95 (2017): HDL-32E intensity falls with rain "
                "rate. Kept returns at 30-40 m with clean byte 1-100.")
    cases = [("rain mie 7.29 mm/h", {"type": "rain", "rate_mm_h": 7.29, "model": "mie"}),
             ("rain goodin 7.29 mm/h", {"type": "rain", "rate_mm_h": 7.29, "model": "goodin"}),
             ("fog V = 300 m", {"type": "fog", "visibility_m": 300.0}),
             ("snow 1 mm/h", {"type": "snow", "rate_mm_h": 1.0}),
             ("lens_damage T = 0.5", {"type": "lens_damage", "transmission": 0.5,
                                      "scatter_probability": 0.0})]
    for label, st in cases:
        m = r.run(label.replace(" ", "-").replace("=", ""), st)
        if isinstance(m, Unavailable):
            if st.get("model") == "goodin":
                st = {k: v for k, v in st.items() if k != "model"}
                m = r.run(label.replace(" ", "-") + "-nomodel", st)
                label += " (build's only rain)"
            if isinstance(m, Unavailable):
                rep.row(label, "", "", m.label, str(m))
                continue
        res = m.intensity()
        pr = m.power_ratio(30.0, 40.0)
        if res is None:
            rep.row(label, "-", "-", "no kept returns at 30-40 m", "-")
            continue
        changed, ratio, follow, n = res
        rep.row(f"{label}: bytes changed / median I/I_clean / returns following the rule",
                "the rule: median P / P_clean", fmt(pr, 3),
                f"{changed:.1f} % / {ratio:.3f} / {follow:.1f} % of {n:,}",
                "holds" if follow >= 99.0 else f"**fails** ({100 - follow:.1f} % off the rule)")
    zero = r.run("rain-zero", {"type": "rain", "rate_mm_h": 0.0, "model": "mie"})
    if not isinstance(zero, Unavailable):
        res = zero.intensity()
        if res:
            rep.row("rain mie at 0 mm/h: bytes changed", "unchanged at zero strength", "0 %",
                    f"{res[0]:.1f} %", "holds" if res[0] == 0 else "**fails**")

    # ---- crosstalk, spoofing ------------------------------------------------------------
    rep.section("Crosstalk and spoofing (defaults)",
                "Anchors: the default crosstalk (a modelled interferer, issue 50) against a "
                "measurement of LiDAR interference (Martins, Neves, Drummond and Albuquerque, "
                "RECPAD 2019: a VLP-16 beside a Hesai Pandar40, 1e-5 to 1e-3 of the points "
                "interfered, 1e-3 at worst); the benchmarks' model A against its corruption "
                "rate (3D_Corruptions_AD / Robo3D: 0.4-2 % of returns); spoofing budget: a "
                "finite default from the attack papers (Cao et al. CCS 2019, as the project's "
                "model notes cite it: about 100 spoofed points in 8-10 degrees, not verified "
                "against the paper).")
    m = r.run("crosstalk", {"type": "crosstalk"})
    if isinstance(m, Unavailable):
        rep.row("crosstalk", "", "", m.label, str(m))
    else:
        echoes = [x for x in m.rows if x[1] in (4, 5)]
        powers = sorted(x[5] for x in echoes)
        share = m.share((4, 5))
        rep.row("crosstalk echoes, default interferer (% of returns)",
                "Martins et al. 2019: interfered points at worst (the default's calibration; "
                "at best 0.001 %)", "0.1 %", f"{share:.3f} %",
                compare(share, 0.1, rel=0.25, abs_=0.0, unit=" pp"))
        rep.row("crosstalk echo power (fraction of emitted), median", "the interferer's "
                "direct pulse from 20 m: P = min(1, r kappa pi / (theta_w theta_h d^2))", "1",
                fmt(statistics.median(powers) if powers else None, 3),
                "-" if not powers else compare(statistics.median(powers), 1.0, rel=0.05,
                                               abs_=0.0))
    m = r.run("crosstalk-benchmark", {"type": "crosstalk", "model": "benchmark"})
    if isinstance(m, Unavailable):
        rep.row("crosstalk, `model = \"benchmark\"`", "", "", m.label, str(m))
    else:
        share = m.share((4, 5))
        rep.row("crosstalk echoes, `model = \"benchmark\"` (% of returns)",
                "benchmarks 0.4-2 % (every corrupted point reported)", "0.4-2 %",
                f"{share:.2f} %", "agrees" if 0.4 <= share <= 2.0 else
                "**deviates** (an equal interferer's reflection: its peak beats the "
                "return's in about half the slots)")
    m = r.run("spoofing", {"type": "spoofing"})
    if isinstance(m, Unavailable):
        rep.row("spoofing", "", "", m.label, str(m))
    else:
        per_frame = sum(1 for x in m.rows if x[1] in (4, 5)) / max(m.frames, 1)
        rep.row("spoofed points per frame", "Cao et al. 2019 attack budget", "about 100",
                f"{per_frame:.0f}", compare(per_frame, 100.0, rel=0.5, abs_=0.0))

    # ---- sensor stages ------------------------------------------------------------------
    rep.section("Sensor stages' added range noise (defaults)",
                "Anchor: HDL-32E datasheet accuracy < 2 cm for the WHOLE sensor; a recorded "
                "capture already contains its sensor's noise, so the defaults applied to it "
                "should add the spread between units, well under 2 cm. Range SD of kept "
                "returns at 20-30 m.")
    rec = repeatability(base.folder)
    if rec:
        rep.row("the recorded sensor's own range noise at 20-30 m (cm): robust SD (plain SD), "
                "consecutive frames of the static scene, same laser, azimuth within 0.01 deg "
                "(an upper bound: the surface under the 0.01 deg is not flat)",
                "datasheet < 2 cm (whole sensor)", "< 2",
                f"{rec[0] * 100:.2f} ({rec[1] * 100:.2f}) from {rec[2]:,} pairs",
                "the real recording's own noise: what a stage added to it comes on top")
    combo = []
    for st in ({"type": "laser_diode"}, {"type": "clock"}, {"type": "receiver"}):
        m = r.run(st["type"], st)
        if isinstance(m, Unavailable):
            rep.row(st["type"], "", "", m.label, str(m))
            continue
        sd = m.range_sd()
        combo.append(sd or 0.0)
        rep.row(f"`{st['type']}`: added range SD at 20-30 m (cm)", "datasheet 2 cm (whole "
                "sensor)", "< 2", fmt(sd * 100 if sd is not None else None, 2),
                "within" if sd is not None and sd < HDL32E_ACCURACY_M else "**beyond**")
    if combo:
        tot = math.sqrt(sum(x * x for x in combo))
        rep.row("laser_diode + clock + receiver (root sum of squares, cm)",
                "datasheet 2 cm (whole sensor)", "< 2", f"{tot * 100:.2f}",
                "within" if tot < HDL32E_ACCURACY_M else "**beyond** the datasheet for the "
                "whole sensor, added on top of a recorded one")


if __name__ == "__main__":
    main()

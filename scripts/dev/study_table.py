#!/usr/bin/env python3
"""Formats the reference-study tables of the manual from sweep aggregate.csv files.

Usage: study_table.py NAME=DIR [NAME=DIR ...]
Each DIR is a sweep over --vary ground.method=... --vary occlusion=on,off
--vary rain.rate_mm_h=0,7. A NAME that several DIRs share (e.g. the randomized scenes,
one capture each) is reported as the mean over those captures of their per-capture means,
with the smallest and largest per-capture mean in brackets instead of an interval.
Prints one Markdown table: detected share per distance band, mean [95 % interval over
seeds] (the interval is the tool's own: per-seed means, exact Student t).
"""
import csv
import sys
from collections import defaultdict

BANDS = [("0_5m", "0-5 m"), ("5_10m", "5-10 m"), ("10_20m", "10-20 m"),
         ("20_40m", "20-40 m"), ("40m_plus", "40+ m")]
NOISE = [(("off", "0"), "none"), (("on", "0"), "occlusion only"),
         (("off", "7"), "rain 7 mm/h only"), (("on", "7"), "both")]


def fmt(mean, lo, hi, objects):
    if mean == "" or objects in ("", "0"):
        return "-"
    m = float(mean)
    if lo == "" or hi == "":
        return f"{m:.2f}"
    return f"{m:.2f} [{float(lo):.2f}, {float(hi):.2f}]"


def main():
    groups = defaultdict(list)
    order = []
    for arg in sys.argv[1:]:
        name, path = arg.split("=", 1)
        if name not in groups:
            order.append(name)
        with open(path + "/aggregate.csv", newline="") as f:
            groups[name].extend(csv.DictReader(f))
    cols = ["overall"] + [b[1] for b in BANDS]
    print("| scene | ground | noise | " + " | ".join(cols) + " |")
    print("|" + "---|" * (3 + len(cols)))
    for name in order:
        rows = groups[name]
        methods = []
        for r in rows:
            if r["ground.method"] not in methods:
                methods.append(r["ground.method"])
        captures = sorted({r["capture"] for r in rows})
        for method in methods:
            for (occ, rate), label in NOISE:
                sel = [r for r in rows if r["ground.method"] == method
                       and r["occlusion"] == occ and r["rain.rate_mm_h"] == rate]
                cells = []
                for key in [""] + ["_" + b[0] for b in BANDS]:
                    obj = "objects" + key + "_mean"
                    det = "detected_share" + key
                    if len(captures) == 1:
                        r = sel[0]
                        cells.append(fmt(r[det + "_mean"], r[det + "_lo"], r[det + "_hi"],
                                         r[obj]))
                    else:
                        vals = [float(r[det + "_mean"]) for r in sel
                                if r[det + "_mean"] != "" and r[obj] not in ("", "0")]
                        if not vals:
                            cells.append("-")
                        else:
                            cells.append(f"{sum(vals) / len(vals):.2f} "
                                         f"[{min(vals):.2f}-{max(vals):.2f}] (n={len(vals)})")
                print(f"| {name} | {method} | {label} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()

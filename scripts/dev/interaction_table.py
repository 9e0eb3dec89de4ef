#!/usr/bin/env python3
"""Markdown tables from `sweep --interactions` folders (scripts/dev/make-interaction-tables.sh).

Arguments: CONFIG:METHOD=DIR ... Each DIR holds an interactions.csv. Per-capture rows are
shown for single captures (crossroad, parking, monterey); a folder of several random scenes
contributes only its "all captures" rows (pooled per seed), named "random (5 scenes)".
"""
import csv
import sys
from collections import defaultdict

SCENES = {"crossroad": "crossroad", "parking": "parking", "monterey": "monterey (real)"}


def num(v, digits=2):
    return "" if v == "" else f"{float(v):.{digits}f}"


def main(args):
    tables = defaultdict(list)
    for arg in args:
        label, folder = arg.split("=", 1)
        config, method = label.split(":")
        with open(f"{folder}/interactions.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        captures = {r["capture"] for r in rows}
        for r in rows:
            if r["capture"] in SCENES and "all captures" not in captures:
                scene = SCENES[r["capture"]]
            elif r["capture"] in SCENES:
                scene = SCENES[r["capture"]]
            elif r["capture"] == "all captures" and not (captures & set(SCENES)):
                scene = "random (5 scenes)"
            else:
                continue
            tables[config].append((scene, method, r))
    out = []
    for config, rows in tables.items():
        pairs = sorted({(r["stage_a"], r["stage_b"]) for _, _, r in rows},
                       key=lambda p: [x for x, _, r in []] or p)
        if config == "paper":
            out.append("### Occlusion (five lasers) and rain (7 mm/h), configs/paper.toml\n")
            out.append("Shares of objects detected relative to the run without noise, "
                       "mean over noise seeds 1..3; verdict rule on the manual's page Interactions between noise stages.\n")
            out.append("| scenes | ground | band | object-frames | occlusion alone | rain alone "
                       "| both | product | both - product [95 % CI] | verdict |")
            out.append("|---|---|---|---:|---:|---:|---:|---:|---|---|")
            for scene, method, r in rows:
                if r["verdict"] == "no objects":
                    continue
                ci = num(r["both_minus_product"])
                if r["both_minus_product_lo"]:
                    ci += f" [{num(r['both_minus_product_lo'])}, {num(r['both_minus_product_hi'])}]"
                out.append(
                    f"| {scene} | {method} | {r['band']} | {num(r['object_frames'], 1)} "
                    f"| {num(r['a_alone'])} | {num(r['b_alone'])} | {num(r['both'])} "
                    f"| {num(r['independence_product'])} | {ci} | {r['verdict']} |")
            out.append("")
        else:
            out.append("### p-diagram sensor stages, configs/pdiagram-sensor.toml "
                       "(default ground method)\n")
            out.append("Verdict counts over the stage pairs, per scene set and band "
                       f"({len(pairs)} pairs); the lowest detected share of any pair with "
                       "both stages.\n")
            out.append("| scenes | band | compounding | independent | masking | unclear "
                       "| lowest 'both' |")
            out.append("|---|---|---:|---:|---:|---:|---:|")
            groups = defaultdict(list)
            for scene, method, r in rows:
                if r["verdict"] != "no objects":
                    groups[(scene, r["band"])].append(r)
            for (scene, band), rs in groups.items():
                count = lambda v: sum(1 for r in rs if r["verdict"] == v)
                low = min(float(r["both"]) for r in rs)
                out.append(f"| {scene} | {band} | {count('compounding')} | "
                           f"{count('independent')} | {count('masking')} | "
                           f"{count('unclear')} | {low:.2f} |")
            out.append("")
    print("\n".join(out))


if __name__ == "__main__":
    main(sys.argv[1:])

#!/usr/bin/env python3
"""Prints a configuration with the rain stage's model set explicitly.

Usage: mie_config.py CONFIG [mie|goodin] > OUT.toml   (default mie)
In every `[[noise]]` block whose type is "rain": any `model = ...` line is removed and
`model = "<MODEL>"` is added; for mie the `range_noise = ...` line (Goodin's Eq. 9 choice)
is removed too, so the range noise is the mie model's default. The rain's other options
(rate, backscatter) and everything else are copied as they are (comments included).
"""
import re
import sys


def main(path, model="mie"):
    lines = open(path).read().split("\n")
    out, block, is_rain = [], [], False

    def flush():
        if is_rain:
            drop = r"\s*(model|range_noise)\s*=" if model == "mie" else r"\s*model\s*="
            kept = [x for x in block if not re.match(drop, x)]
            at = next(i for i, x in enumerate(kept) if re.match(r'\s*type\s*=\s*"rain"', x))
            kept.insert(at + 1, f'model = "{model}"    # written by scripts/dev/make-study-mie.sh')
            out.extend(kept)
        else:
            out.extend(block)

    for line in lines:
        if re.match(r"\s*\[", line):
            flush()
            block, is_rain = [], False
        block.append(line)
        if re.match(r'\s*type\s*=\s*"rain"', line):
            is_rain = True
    flush()
    sys.stdout.write("\n".join(out))


if __name__ == "__main__":
    main(*sys.argv[1:3])

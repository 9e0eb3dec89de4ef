#!/usr/bin/env python3
"""Prints a configuration with the rain stage switched to physical (Mie) rain.

Usage: mie_config.py CONFIG > OUT.toml
In every `[[noise]]` block whose type is "rain": any `model = ...` line and the
`range_noise = ...` line (Goodin's Eq. 9 choice) are removed and `model = "mie"` is added,
so the rain's other options (rate, backscatter) stay and its range noise is the mie
model's default. Everything else is copied as it is (comments included).
"""
import re
import sys


def main(path):
    lines = open(path).read().split("\n")
    out, block, is_rain = [], [], False

    def flush():
        if is_rain:
            kept = [x for x in block if not re.match(r"\s*(model|range_noise)\s*=", x)]
            at = next(i for i, x in enumerate(kept) if re.match(r'\s*type\s*=\s*"rain"', x))
            kept.insert(at + 1, 'model = "mie"    # written by scripts/make-study-mie.sh')
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
    main(sys.argv[1])

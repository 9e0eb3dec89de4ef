#!/usr/bin/env python3
"""Runs the README's code blocks marked as runnable, as a reader would type them.

A fenced block right after a line `<!-- runnable -->` (a ```sh block) or
`<!-- runnable python -->` (a ```python block) is run; other blocks are examples only.
All blocks run in order in one temporary folder that holds links to the repository's
fixtures/ and configs/ (the README's commands run from the repository's root), with the
given binary's folder first on PATH, each sh block under `bash -euo pipefail`. A block
that fails stops the run with its output and exit code.

Usage: scripts/ci/readme_run.py BINARY [--python PYTHON] [README]
  PYTHON runs the python blocks (CI gives its virtual environment with laspy); without it
  they are reported as SKIPPED.
Exit: 0 every block passed, 1 a block failed, 2 usage or no runnable block.
Standard library only.
"""
import os
import re
import shutil
import subprocess
import sys
import tempfile


def blocks(text):
    """(line number, language, code) of each runnable block."""
    out = []
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        m = re.match(r"^<!--\s*runnable(?:\s+(\w+))?\s*-->\s*$", lines[i])
        if m:
            lang = m.group(1) or "sh"
            j = i + 1
            if j >= len(lines) or not lines[j].startswith("```" + lang):
                raise ValueError("line %d: a runnable marker not followed by a ```%s block" % (i + 1, lang))
            k = j + 1
            while k < len(lines) and not lines[k].startswith("```"):
                k += 1
            out.append((j + 1, lang, "\n".join(lines[j + 1:k]) + "\n"))
            i = k
        i += 1
    return out


def main():
    args = sys.argv[1:]
    python = None
    if "--python" in args:
        at = args.index("--python")
        python = args[at + 1]
        del args[at:at + 2]
    if not args or not os.access(args[0], os.X_OK):
        print(__doc__.split("\n\n")[2], file=sys.stderr)
        return 2
    binary = os.path.abspath(args[0])
    readme = args[1] if len(args) > 1 else "README.md"
    repo = os.path.dirname(os.path.abspath(readme))
    found = blocks(open(readme, encoding="utf-8").read())
    if not found:
        print("readme_run: no runnable block in %s" % readme)
        return 2
    work = tempfile.mkdtemp(prefix="readme-run-")
    try:
        for name in ("fixtures", "configs"):
            os.symlink(os.path.join(repo, name), os.path.join(work, name))
        env = dict(os.environ, PATH=os.path.dirname(binary) + os.pathsep + os.environ.get("PATH", ""))
        passed = skipped = 0
        for line, lang, code in found:
            if lang == "sh":
                cmd = ["bash", "-euo", "pipefail", "-c", code]
            elif lang == "python":
                if python is None:
                    print("SKIPPED: README line %d (python): no --python given" % line)
                    skipped += 1
                    continue
                cmd = [python, "-c", code]
            else:
                print("FAIL: README line %d: unknown block language %s" % (line, lang))
                return 1
            r = subprocess.run(cmd, cwd=work, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
            if r.returncode != 0:
                print("FAIL: README line %d (%s) exited with %d:\n%s\n--- output:\n%s"
                      % (line, lang, r.returncode, code, r.stdout))
                return 1
            passed += 1
            print("readme_run: README line %d (%s) ok" % (line, lang))
        print("readme_run: %d passed, 0 failed, %d skipped" % (passed, skipped))
        return 0
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())

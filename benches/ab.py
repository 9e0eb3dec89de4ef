#!/usr/bin/env python3
"""Interleaved A/B timing of lidar-noise binaries: wall and CPU (user + sys) per run.

Usage: python3 benches/ab.py OLD,NEW THREADS RUNS ARGS...  (binaries by path, run in turn;
prints median and minimum of each). For comparing builds on a loaded machine, where
only same-load, interleaved runs are comparable.

PAUSE=SECONDS sleeps before each run: on a VM that hands freed memory back to its host
(free page reporting, about every 2 s), a run started after a pause gets memory the host
must supply again, as a single run from a script does; back-to-back runs mostly reuse
memory the last run freed (manual, "Benchmark history": huge pages).
"""
import subprocess, time, os, sys, resource
bins = sys.argv[1].split(',')
threads = sys.argv[2]
n = int(sys.argv[3])
args = sys.argv[4:]
res = {b: [] for b in bins}
env = dict(os.environ, RAYON_NUM_THREADS=threads)
pause = float(os.environ.get("PAUSE", "0"))
for i in range(n):
    for b in bins:
        time.sleep(pause)
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        subprocess.run([b if '/' in b else './' + b] + args, env=env, check=True)
        w = time.perf_counter() - t
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
        res[b].append((w, cpu))
for b in bins:
    ws = sorted(x[0] for x in res[b]); cs = sorted(x[1] for x in res[b])
    print(f"{b}: wall median {ws[len(ws)//2]*1e3:.1f} min {ws[0]*1e3:.1f} ms; cpu median {cs[len(cs)//2]*1e3:.1f} min {cs[0]*1e3:.1f} ms")

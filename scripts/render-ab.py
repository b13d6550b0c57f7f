#!/usr/bin/env python3
# render-ab.py: two terrad builds timed against each other on one render, their runs
# interleaved (A, B, A, B, ...) so that a shared machine's load falls on both alike: the
# median of each stage's milliseconds and of their sum (`terrad render --stats`,
# stages_ms), one thread, and whether the two builds wrote the same image bytes. The
# README's "Coherent camera and shadow rays" has the figures it gave (panoramas and
# curvature, 2026-12-01).
#
#   scripts/render-ab.py TERRAD_A TERRAD_B SCENE.json [RUNS]
#
# SCENE's dataset is a DEM path (as `terrad render` takes it); RUNS defaults to 7.
import json
import statistics
import subprocess
import sys
import tempfile

if len(sys.argv) < 4:
    sys.exit(__doc__ if __doc__ else "usage: render-ab.py TERRAD_A TERRAD_B SCENE.json [RUNS]")
builds = {"A": sys.argv[1], "B": sys.argv[2]}
scene = sys.argv[3]
runs = int(sys.argv[4]) if len(sys.argv) > 4 else 7
work = tempfile.mkdtemp(prefix="render-ab.")
stages = {k: {} for k in builds}
for _ in range(runs):
    for k, exe in builds.items():
        out, stats = f"{work}/{k}.img", f"{work}/{k}.json"
        r = subprocess.run([exe, "render", scene, "-o", out, "--threads", "1", "--stats", stats],
                           capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(f"render-ab: {exe} failed:\n{r.stderr[-2000:]}")
        ms = json.load(open(stats))["stages_ms"]
        for name, v in ms.items():
            stages[k].setdefault(name, []).append(v)
        stages[k].setdefault("total", []).append(sum(ms.values()))
for k, exe in builds.items():
    med = {n: statistics.median(v) for n, v in stages[k].items()}
    shown = ", ".join(f"{n} {v:.1f}" for n, v in med.items() if v >= 0.05)
    print(f"{k} {exe}: median of {runs} (ms): {shown}")
same = open(f"{work}/A.img", "rb").read() == open(f"{work}/B.img", "rb").read()
print("same image bytes:", "yes" if same else "no")

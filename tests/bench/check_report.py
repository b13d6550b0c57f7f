#!/usr/bin/env python3
"""check_report.py: smoke test of `terrad bench`. Runs `terrad bench --quick` on the small
fixtures, then checks the report's structure and that its numbers are sane (never a
timing): every section and table is there, terrad's triangle hits agree with Embree's,
every method finds the same hits for a surface, the bilinear surface is its own
reference, the coarser surfaces err more, effects trace only their own rays, the charts
are well-formed SVG, the camera views' table is whole and, with one round, its ratios are the quotients of
its rates (the summary's taken from it), and `terrad trace --threads 1` on the rays of `--write-rays` takes
the same steps as the report says.
usage: check_report.py TERRAD SOURCE_DIR WORK_DIR"""
import json
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

terrad, src, work = sys.argv[1:4]
failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print("FAIL:", what)


def num(cell):
    """First number in a table cell ('3.09 M' -> 3.09e6, '92.4%' -> 92.4)."""
    m = re.search(r"-?[0-9.]+(?:e[-+]?[0-9]+)?", cell)
    if not m:
        return float("nan")
    v = float(m.group(0))
    if re.search(r"[0-9] M\b", cell):
        v *= 1e6
    elif re.search(r"[0-9] k\b", cell):
        v *= 1e3
    return v


def tables_after(text, heading):
    """The tables (lists of rows of cells) between `heading` and the next heading of the
    same or a higher level."""
    lines = text.split("\n")
    level = len(heading) - len(heading.lstrip("#"))
    out, cur, inside = [], None, False
    for ln in lines:
        if ln.startswith(heading):
            inside = True
            continue
        if inside and ln.startswith("#"):
            lv = len(ln) - len(ln.lstrip("#"))
            if lv <= level:
                break
        if not inside:
            continue
        if ln.startswith("|"):
            cells = [c.strip() for c in ln.strip().strip("|").split("|")]
            if cur is None:
                cur = []
                out.append(cur)
            if not all(re.fullmatch(r"-+", c) for c in cells):
                cur.append(cells)
        else:
            cur = None
    return out


dem = os.path.join(src, "tests/data/trinidad-crop.f32")
if os.path.isdir(work):
    shutil.rmtree(work)
os.makedirs(work)
cmd = [terrad, "bench", "--quick", "--quiet", "--runs", "2", "--out", work, "--trinidad", dem,
       "--picos", os.path.join(src, "tests/data/picos-dtm.asc"),
       "--levi", os.path.join(src, "data/levi/topography.png"),
       "--scene-dem", os.path.join(src, "data/trinidad/blanca.f32")]
r = subprocess.run(cmd, capture_output=True, text=True)
check(r.returncode == 0, "terrad bench --quick exits 0: " + r.stderr[-500:])
report = open(os.path.join(work, "accuracy-vs-time.md")).read()
summary = open(os.path.join(work, "bench-summary.md")).read()

# structure
for h in ["# Accuracy against time", "## Targets", "## How this is measured",
          "## 1. Speed per method and surface", "## 2. Error against the bilinear surface",
          "## 3. Paglieroni and Petersen's Table 1", "## 4. Qu et al.'s Table 1",
          "## 5. The cost of each effect", "## 6. Pareto charts", "## 7. Camera views"]:
    check(h in report, "report has the heading " + h)
check("AMD" in report or "Intel" in report or "CPU" in report or "cores" in report, "report names the machine")
check(re.search(r"commit `[0-9a-f]{7,}`|commit `unknown`", report) is not None, "report names the commit")
check("Quick mode" in report, "a quick report says it measures nothing")
check("x Embree best" in summary and "accuracy-vs-time.md" in summary, "summary has its table and link")

# section 1: per dataset, 16 rows of terrad and 2 of Embree
datasets = ["trinidad", "picos", "levi", "procedural"]
for ds in datasets:
    t = tables_after(report, "### " + ds + " (")
    check(len(t) == 2, ds + ": a terrad table and an Embree table")
    if len(t) != 2:
        continue
    rows = t[0][1:]
    check(len(rows) == 16, ds + ": 16 method x surface rows")
    hits = {}
    for row in rows:
        method, surface = row[0], row[1]
        rps, steps, p99, bpc, hitpct = num(row[2]), num(row[4]), num(row[5]), num(row[7]), num(row[8])
        check(rps > 0, f"{ds} {method}/{surface}: rays/s > 0")
        check(steps >= 1 and p99 >= 1, f"{ds} {method}/{surface}: at least one step per ray")
        check(4.0 <= bpc < 64, f"{ds} {method}/{surface}: bytes per cell {bpc} between 4 and 64")
        hits.setdefault(surface, set()).add(hitpct)
        if surface == "triangle":
            check(num(row[9]) >= 99.5, f"{ds} {method}/triangle agrees with Embree ({row[9]})")
        if method == "incremental":
            check(abs(bpc - 4.0) < 0.1, f"{ds}: incremental holds only heights ({bpc})")
    for s, v in hits.items():
        check(len(v) == 1, f"{ds} {s}: every method finds the same hits ({v})")
    emb = t[1][1:]
    check(len(emb) == 2, ds + ": Embree triangle mesh and GRID rows")
    for row in emb:
        check(num(row[1]) > 0 and num(row[2]) > 0, f"{ds} Embree {row[0]}: rays/s > 0")
        check(num(row[4]) > 4, f"{ds} Embree {row[0]}: memory counted ({row[4]})")
        a = re.findall(r"([0-9.]+)%", row[6])
        check(len(a) == 2 and all(float(x) >= 99.5 for x in a), f"{ds} Embree {row[0]} agrees ({row[6]})")

# section 2: per-ray errors
t = tables_after(report, "### Per ray")
rows = t[0][1:] if t else []
check(len(rows) == 16, "error table: 4 datasets x 4 surfaces")
err = {(r[0], r[1]): num(r[2]) for r in rows}
for ds in datasets:
    if (ds, "bilinear") in err:
        check(err[(ds, "bilinear")] < 1e-6, f"{ds}: bilinear against itself is float rounding only")
        check(err[(ds, "triangle")] > err[(ds, "bilinear")], f"{ds}: triangle errs more than bilinear")
        check(err[(ds, "plane")] > err[(ds, "triangle")], f"{ds}: plane errs more than triangle")
# pictures: 24 configurations, the reference row exact
t = tables_after(report, "### Pictures")
rows = t[0][1:] if t else []
check(len(rows) == 24, "picture table: 4 surfaces x 3 samples x lod off/on")
for r in rows:
    if r[0] == "bilinear" and r[1] == "4" and r[2] == "off":
        check(r[7] == "exact" and num(r[8]) == 0, "the reference picture equals itself")
    else:
        check(num(r[6]) >= 0 and num(r[3]) > 0, "picture row has time and RMSE: " + "|".join(r))
# K sweep
t = tables_after(report, "### K of the parameter planes")
rows = t[0][1:] if t else []
check([int(r[0]) for r in rows] == [1, 2, 4, 8, 16, 32, 64], "K sweep over 1 .. 64")
check(len(rows) > 0 and all(0.5 <= num(r[2]) <= 0.6 for r in rows),
      "planes take two bytes a 2 x 2 block of cells (and a table of K + 1 heights a tile) whatever K is")
if rows:
    check(num(rows[-1][3]) <= num(rows[0][3]), "K = 64 takes no more steps than K = 1")

# section 3: 16 views; the parametric method takes fewer steps than the incremental walk
t = tables_after(report, "## 3. Paglieroni")
check(len(t) == 2 and len(t[0]) == 18, "Paglieroni: 16 views and a mean row")
if len(t) == 2:
    mean = t[0][-1]
    check(num(mean[3]) > num(mean[5]) > 0, "n_pierce > parametric steps > 0")
    check(len(t[1]) == 4, "Paglieroni: three methods beside the paper")

# section 4: Qu, plane = 1
t = tables_after(report, "## 4. Qu")
rows = t[0][1:] if t else []
check(len(rows) == 4 and all(num(x) == 1.0 for x in rows[0][2:6]), "Qu: ratios against the plane")

# section 5: effects trace only their own rays
t = tables_after(report, "## 5. The cost")
rows = {r[0]: [int(x) for x in r[5].split("/")] for r in (t[0][1:] if t else [])}
check(len(rows) == 11, "effects: 11 scenes")
if len(rows) == 11:
    check(rows["none (shading only)"][1:] == [0, 0, 0], "no effect, no secondary ray")
    check(rows["shadows"][1] > 0 and rows["shadows"][2:] == [0, 0], "shadows trace shadow rays only")
    check(rows["ambient occlusion (8 rays)"][3] > 0, "ambient occlusion traces ao rays")
    check(rows["supersampling 2 x 2"][0] == 4 * rows["none (shading only)"][0], "2 x 2 samples, 4x the primary rays")

# section 6: charts
for name, npts in [("pareto-trace.svg", 20), ("pareto-render.svg", 24), ("planes-k.svg", 7)]:
    p = os.path.join(work, "bench", name)
    check(os.path.exists(p), name + " written")
    if os.path.exists(p):
        root = ET.parse(p).getroot()
        circles = [e for e in root.iter() if e.tag.endswith("circle") and e.find("{*}title") is not None]
        check(len(circles) == npts, f"{name}: {npts} points ({len(circles)})")
        check("bench/" + name in report, name + " linked from the report")

# section 7: camera views. Structure, numbers that parse, ratios that are the quotients of
# the printed rates, the summary's best surfaces taken from the section's table. terrad's
# exactness counts are parsed, never judged (the oracle tests judge); Embree's occluded
# and intersect calls must agree (a test of td_embree_occluded16).
def close(ratio, a, b):
    """ratio (printed %.2f) against a / b (printed to 4 significant digits)"""
    return abs(ratio - a / b) <= 0.006 + 0.002 * ratio


cam_views = ["level", "grazing sunset", "rolled", "straight down"]
cam_ds = ["trinidad", "picos", "levi"]
surfaces = ["plane", "linear", "triangle", "bilinear"]
t = tables_after(report, "### The views")
rows = t[0][1:] if t else []
check([(r[0], r[1]) for r in rows] == [(d, v) for d in cam_ds for v in cam_views],
      "camera views: 4 views of trinidad, picos and levi")
for r in rows:
    check(int(r[7]) == 32 * 32, f"camera view {r[0]} {r[1]}: 32 x 32 camera rays in quick mode ({r[7]})")
    check(0 <= num(r[8]) <= 100 and 0 <= num(r[9]) <= 100, f"camera view {r[0]} {r[1]}: shares in percent")
t = tables_after(report, "### Camera views: rays per second")
rows = t[0][1:] if t else []
check(len(rows) == 48 and all(len(r) == 23 for r in rows), "camera table: 3 datasets x 4 views x 4 surfaces, 23 columns")
best = {}
for r in rows:
    what = f"camera {r[0]} {r[1]} {r[2]}"
    check(r[2] in surfaces, what + ": a surface")
    on, off, emb = num(r[3]), num(r[4]), num(r[5])
    check(on > 0 and off > 0 and emb > 0, what + ": camera rates parse and are > 0")
    if on > 0 and off > 0 and emb > 0:  # each round's quotient, the median (one round: below)
        check(num(r[6]) > 0 and num(r[7]) > 0, what + ": camera x Embree > 0")
    check(num(r[8]) > 0 and num(r[9]) > 0, what + ": steps per camera ray > 0")
    nsh = int(r[10])
    srates, semb = [num(x) for x in r[11:15]], num(r[15])  # on, bound kept, no sun bound, off
    if nsh > 0:
        check(all(x > 0 for x in srates) and semb > 0, what + ": shadow rates parse and are > 0")
        if all(x > 0 for x in srates) and semb > 0:
            check(all(num(r[16 + k]) > 0 for k in range(4)), what + ": shadow x Embree > 0")
        # with the sun bound on, its shadow side may answer every ray without a walk (0)
        check(num(r[20]) >= 0 and all(num(x) > 0 for x in r[21:23]),
              what + ": steps per shadow ray >= 0 with the sun bound, > 0 without")
        check(num(r[20]) <= min(num(x) for x in r[21:23]),
              what + ": the sun bound takes no more steps per shadow ray than without it")
    b = best.setdefault((r[0], r[1]), {"p": {}, "s": {}, "k": {}, "steps": {}})
    b["p"][r[2]] = num(r[6])
    if r[16] != "-":
        b["s"][r[2]] = num(r[16])
        b["k"][r[2]] = num(r[17])
    b["steps"][r[2]] = num(r[8])
# with one round, each x Embree is the quotient of the rates beside it (bench_camera.c's
# paired_x: the pairing of terrad's and Embree's times by round, and their order)
work1 = work + "-one-round"
r1 = subprocess.run(cmd[:4] + ["--runs", "1", "--sections", "camera", "--out", work1] + cmd[8:],
                    capture_output=True, text=True)
check(r1.returncode == 0, "terrad bench --quick --runs 1 --sections camera exits 0: " + r1.stderr[-500:])
t1 = tables_after(open(os.path.join(work1, "accuracy-vs-time.md")).read() if r1.returncode == 0 else "",
                  "### Camera views: rays per second")
rows1 = t1[0][1:] if t1 else []
check(len(rows1) == 48, "one round: the camera table has its 48 rows")
for r in rows1:
    what = f"camera, one round, {r[0]} {r[1]} {r[2]}"
    on, off, emb = num(r[3]), num(r[4]), num(r[5])
    if on > 0 and off > 0 and emb > 0:
        check(close(num(r[6]), on, emb) and close(num(r[7]), off, emb), what + ": camera x Embree = quotients")
    srates, semb = [num(x) for x in r[11:15]], num(r[15])
    if int(r[10]) > 0 and all(x > 0 for x in srates) and semb > 0:
        check(all(close(num(r[16 + k]), srates[k], semb) for k in range(4)), what + ": shadow x Embree = quotients")
if os.path.isdir(work1):
    shutil.rmtree(work1)
t = tables_after(report, "### Exactness against Embree")
rows = t[0][1:] if t else []
check(len(rows) == 12, "camera exactness: 12 views")
for r in rows:
    nums = [int(x) for x in [r[2], r[4], r[5], r[6], r[7], r[8]]] + [int(x) for x in r[3].split("/")]
    check(all(0 <= x for x in nums) and max(nums[1], nums[2]) <= nums[0] and max(nums[4], nums[5]) <= nums[3],
          f"camera exactness {r[0]} {r[1]}: counts parse and stay within the rays")
    # Embree against itself: rtcOccluded16 (td_embree_occluded16) and rtcIntersect16 on the same rays
    check(int(r[8]) == 0, f"camera exactness {r[0]} {r[1]}: Embree's occluded and intersect agree ({r[8]})")
# issue 13: the camera rays with no preprocessing; silhouette's depths are the walk's, bit for bit
t = tables_after(report, "### Without preprocessing")
rows = t[0][1:] if t else []
check(len(rows) == 12 and all(len(r) == 11 for r in rows), "no-preprocessing table: 12 views, 11 columns")
for r in rows:
    what = f"no preprocessing {r[0]} {r[1]}"
    rates = [num(x) for x in r[2:5]]
    check(all(x > 0 for x in rates), what + ": rates parse and are > 0")
    if all(x > 0 for x in rates):
        check(close(num(r[5]), rates[2], rates[1]), what + ": silhouette / walk + horizon = quotient")
    check(all(num(x) >= 0 for x in r[6:9]) and num(r[6]) > 0, what + ": steps per ray parse")
    check(int(r[9]) > 0, what + ": the partition has entries")
    check(int(r[10]) == 0, what + f": silhouette depths equal the walk's ({r[10]} differ)")
t = tables_after(report, "### What no preprocessing saves")
rows = t[0][1:] if t else []
check(len(rows) == 12 and all(len(r) == 9 for r in rows), "amortised table: 12 views, 9 columns")
for r in rows:
    ms = [num(x) for x in r[2:9]]
    check(all(x > 0 for x in ms), f"amortised {r[0]} {r[1]}: times parse and are > 0")
    # a build spread over more frames costs less a frame; both structures at least the max-mipmap
    check(ms[1] >= ms[2] >= ms[3] and ms[4] >= ms[5] >= ms[6] and ms[4] >= ms[1],
          f"amortised {r[0]} {r[1]}: ordered")
check("camera rays >= 3x Embree's rtcIntersect16" in report and "shadow rays >= 3x Embree's rtcOccluded16" in report,
      "targets table has the camera rows")
srows = [r for r in summary.split("\n") if r.startswith("| ") and any(r.startswith("| " + d + " |") for d in cam_ds)]
check(len(srows) == 12, "summary: a camera row per view")
for ln in srows:
    r = [c.strip() for c in ln.strip().strip("|").split("|")]
    b = best.get((r[0], r[1]))
    if b is None:
        check(False, f"summary row {r[0]} {r[1]} is in the camera table")
        continue
    # the best surface's ratio (the printed ratios may tie: any surface with the highest)
    sp, ss = re.search(r"\((\w+)\)", r[2]), re.search(r"\((\w+)\)", r[3])
    check(sp is not None and b["p"].get(sp.group(1)) == num(r[2]) == max(b["p"].values()),
          f"summary {r[0]} {r[1]}: camera x Embree is the best surface's ({r[2]} vs {b['p']})")
    check(r[3].startswith("-") or (ss is not None and b["s"].get(ss.group(1)) == num(r[3]) == max(b["s"].values())),
          f"summary {r[0]} {r[1]}: shadow x Embree is the best surface's ({r[3]} vs {b['s']})")
    sk = re.search(r"\((\w+)\)", r[4])
    check(r[4].startswith("-") or (sk is not None and b["k"].get(sk.group(1)) == num(r[4]) == max(b["k"].values())),
          f"summary {r[0]} {r[1]}: shadow x Embree with the bound kept is the best surface's ({r[4]} vs {b['k']})")
    check(sp is not None and abs(num(r[5]) - b["steps"].get(sp.group(1), -1)) < 1e-9,
          f"summary {r[0]} {r[1]}: steps of that surface")
check("3x rtcIntersect16" in summary and "2 steps per camera ray" in summary, "summary states the camera targets")

# terrad trace on the bench's rays takes the report's steps (same rays, same loop)
rays = os.path.join(work, "trinidad.rays")
r = subprocess.run([terrad, "bench", "--write-rays", rays, "--quick", "--trinidad", dem],
                   capture_output=True, text=True)
check(r.returncode == 0, "--write-rays exits 0: " + r.stderr[-300:])
stats = os.path.join(work, "trace.json")
with open(rays, "rb") as fin:
    r = subprocess.run([terrad, "trace", "--dem", dem, "--method", "hierarchical", "--surface", "triangle",
                        "--threads", "1", "--stats", stats], stdin=fin, capture_output=True)
check(r.returncode == 0, "terrad trace on the written rays exits 0")
if r.returncode == 0:
    st = json.load(open(stats))
    t = tables_after(report, "### trinidad (")
    row = [x for x in t[0][1:] if x[0] == "hierarchical" and x[1] == "triangle"][0]
    check(abs(st["mean_steps"] - num(row[4])) < 0.006, f"terrad trace mean steps {st['mean_steps']} = report {row[4]}")
    check(abs(100.0 * st["hits"] / st["rays"] - num(row[8])) < 0.06, "terrad trace hits = report")
    check(os.path.getsize(rays) == 48 * st["rays"], "ray file holds 48 bytes a ray")

print("bench smoke:", "FAILED %d checks" % len(failures) if failures else "all checks passed")
sys.exit(1 if failures else 0)

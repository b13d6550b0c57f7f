#!/usr/bin/env bash
# Renders the README gallery: each scene JSON here -> NAME.png and NAME.stats.json
# (the median of 3 runs by render time; machines here are shared and noisy), then prints
# the timing table of docs/gallery/README-section.md.
#   usage: docs/gallery/render.sh [BUILD_DIR]   (default: build)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
terrad="$root/${1:-build}/terrad"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
for scene in "$here"/*.json; do
  case "$scene" in *.stats.json | *.peaks.json) continue ;; esac
  name="$(basename "$scene" .json)"
  for run in 1 2 3; do
    "$terrad" render "$scene" -o "$tmp/$name.$run.png" --stats "$tmp/$name.$run.stats.json"
  done
  best="$(python3 - "$tmp" "$name" <<'PY'
import json, sys
tmp, name = sys.argv[1], sys.argv[2]
runs = sorted((json.load(open(f"{tmp}/{name}.{r}.stats.json"))["render_ms"], r) for r in (1, 2, 3))
print(runs[1][1])
PY
)"
  cp "$tmp/$name.$best.png" "$here/$name.png"
  cp "$tmp/$name.$best.stats.json" "$here/$name.stats.json"
done
python3 - "$here" <<'PY'
import glob, json, os, sys
here = sys.argv[1]
print("| image | size | rays (primary / shadow / ao) | render ms (median of 3) | stages ms |")
print("|---|---|---|---|---|")
for f in sorted(glob.glob(os.path.join(here, "*.stats.json"))):
    s = json.load(open(f))
    name = os.path.basename(f)[:-len(".stats.json")]
    r = s["rays"]
    stages = ", ".join(f"{k} {v:.0f}" for k, v in s["stages_ms"].items())
    print(f"| {name} | {s['width']}x{s['height']}, {s['samples']}x{s['samples']} samples | "
          f"{r['primary']} / {r['shadow']} / {r['ao']} | {s['render_ms']:.0f} | {stages} |")
PY

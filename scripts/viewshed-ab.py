#!/usr/bin/env python3
# viewshed-ab.py: two terrad builds timed against each other on one viewshed, their runs
# interleaved (A, B, A, B, ...) so that the shared machine's load falls on both alike:
# min and median of the whole command's CPU time (the child's rusage) and of terrad's own
# split (--stats cpu_ms: load, max-mipmaps, viewshed, PNG), one thread. docs/viewshed.md
# "Speed" has the figures.
#
#   scripts/viewshed-ab.py TERRAD_A TERRAD_B [RUNS] [DEM COL ROW HEIGHT]
#
# Default: trinidad from Blanca Peak (/work/shared/data/trinidad/dem.f32, sample 617, 508,
# eye 2 m up), 15 runs each.
import json, os, statistics, subprocess, sys, tempfile

a, b = sys.argv[1], sys.argv[2]
runs = int(sys.argv[3]) if len(sys.argv) > 3 else 15
dem, col, row, h = (sys.argv[4:8] if len(sys.argv) > 7 else
                    ('/work/shared/data/trinidad/dem.f32', '617', '508', '2'))
t = tempfile.mkdtemp(prefix='vs-ab.')
info = json.loads(subprocess.run([a, 'info', '--json', dem], check=True, capture_output=True).stdout)
x = int(col) * info['spacing'][0]
y = (info['height'] - 1 - int(row)) * info['spacing'][1]
res = {a: [], b: []}
for _ in range(runs):
    for exe in (a, b):
        cmd = [exe, 'viewshed', '--dem', dem, '--observer', f'{x!r},{y!r}', '--height', h, '--threads', '1',
               '-o', f'{t}/o.png', '--stats', f'{t}/st.json']
        p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _, status, ru = os.wait4(p.pid, 0)
        if status != 0:
            sys.exit('failed: ' + ' '.join(cmd))
        j = json.load(open(f'{t}/st.json'))
        cp = j['cpu_ms']
        res[exe].append(((ru.ru_utime + ru.ru_stime) * 1e3, cp['load'], cp['accel'], cp['viewshed'],
                         cp['encode'], j['rays']))
names = ('whole', 'load', 'max-mipmaps', 'viewshed', 'PNG')
for exe in (a, b):
    r = res[exe]
    cols = [f'{n} {min(v[k] for v in r):.1f}/{statistics.median(v[k] for v in r):.1f}'
            for k, n in enumerate(names)]
    print(f'{exe}: min/median of {runs} (ms): ' + ', '.join(cols) + f'; casts {r[0][5]}')

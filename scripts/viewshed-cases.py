#!/usr/bin/env python3
# viewshed-cases.py: the 21 viewshed cases of docs/viewshed.md ("Speed": picos and the
# whole trinidad, observers on the peak, the lowest sample, a valley, beside voids, the
# corner, with max_distance, curvature, target height, the eye on the ground, three
# observers, every surface but plane), run with two terrad binaries (one thread) and
# compared pixel for pixel (the PNGs decoded), with each run's number of casts.
#
#   scripts/viewshed-cases.py OLD_TERRAD NEW_TERRAD [CASE ...]
#
# DATA (default /work/shared/data) holds picos/dtm.asc and trinidad/dem.f32. Exit status 1
# when a case differs.
import atexit, json, os, shutil, struct, subprocess, sys, tempfile, zlib
old, new = sys.argv[1], sys.argv[2]
out = tempfile.mkdtemp(prefix='vs-cases.')
atexit.register(shutil.rmtree, out, True)
data = os.environ.get('DATA', '/work/shared/data')
def read_asc(p):
    f = open(p); hdr = {}
    for _ in range(6):
        k, v = f.readline().split(); hdr[k.lower()] = float(v)
    vals = [float(x) for x in f.read().split()]
    w, h = int(hdr['ncols']), int(hdr['nrows'])
    return w, h, [None if v == hdr['nodata_value'] else v for v in vals]
def read_f32(p, w, h):
    d = open(p, 'rb').read(); v = struct.unpack('<%df' % (w * h), d)
    return [None if x != x else x for x in v]
P = f'{data}/picos/dtm.asc'; T = f'{data}/trinidad/dem.f32'
pw, ph, pz = read_asc(P); tw, th_ = 2401, 1201; tz = read_f32(T, tw, th_)
psx, psy = 4.8888633782088409, 6.6804651430307551; tsx, tsy = 73.688000000000002, 92.489000000000004
def xy(c, r, h, sx, sy): return f"{c * sx!r},{(h - 1 - r) * sy!r}"
def arg(z, w): i = max((k for k in range(len(z)) if z[k] is not None), key=lambda k: z[k]); return i % w, i // w
def argmin(z, w): i = min((k for k in range(len(z)) if z[k] is not None), key=lambda k: z[k]); return i % w, i // w
# picos: peak, lowest, a valley (local min of 5x5 near centre), void-edge samples near corners
pk, lw = arg(pz, pw), argmin(pz, pw)
def void_edge(z, w, h, c0, r0):
    best = None
    for r in range(1, h - 1):
        for c in range(1, w - 1):
            if any(z[(r + dr) * w + c + dc] is None for dr in (0, 1) for dc in (-1, 0)): continue
            if any(z[(r + dr) * w + c + dc] is None for dr in (-1, 0, 1) for dc in (-1, 0, 1)):
                d = (c - c0) ** 2 + (r - r0) ** 2
                if best is None or d < best[0]: best = (d, c, r)
    return best[1], best[2]
v1, v2 = void_edge(pz, pw, ph, 0, 0), void_edge(pz, pw, ph, pw - 1, ph - 1)
def valley(z, w, h, c0, r0):
    best = None
    for r in range(r0 - 60, r0 + 60):
        for c in range(c0 - 60, c0 + 60):
            if z[r * w + c] is None: continue
            if best is None or z[r * w + c] < best[0]: best = (z[r * w + c], c, r)
    return best[1], best[2]
pv = valley(pz, pw, ph, 357, 241); tv = valley(tz, tw, th_, 1200, 600)
edge_low = min(((tz[r * tw + c], c, r) for r in range(th_) for c in range(tw) if (r in (0, th_ - 1) or c in (0, tw - 1)) and tz[r * tw + c] is not None))[1:]
cases = [
 ('p_centre', P, [xy(357, 241, ph, psx, psy)], ['--height', '2']),
 ('p_peak', P, [xy(*pk, ph, psx, psy)], ['--height', '2']),
 ('p_low', P, [xy(*lw, ph, psx, psy)], ['--height', '2']),
 ('p_valley_1000', P, [xy(*pv, ph, psx, psy)], ['--height', '2', '--max-distance', '1000']),
 ('p_void1', P, [xy(*v1, ph, psx, psy)], ['--height', '10']),
 ('p_void2', P, [xy(*v2, ph, psx, psy)], ['--height', '3']),
 ('p_curv', P, [xy(357, 241, ph, psx, psy)], ['--height', '2', '--curvature', '0.13']),
 ('p_linear', P, [xy(357, 241, ph, psx, psy)], ['--height', '2', '--surface', 'linear']),
 ('p_triangle', P, [xy(357, 241, ph, psx, psy)], ['--height', '2', '--surface', 'triangle']),
 ('p_tgt3', P, [xy(357, 241, ph, psx, psy)], ['--height', '2', '--target-height', '3']),
 ('p_peak_ground', P, [xy(*pk, ph, psx, psy)], ['--height', '0']),
 ('p_three', P, [xy(357, 241, ph, psx, psy), xy(*pk, ph, psx, psy), xy(*pv, ph, psx, psy)], ['--height', '2']),
 ('t_blanca', T, [xy(617, 508, th_, tsx, tsy)], ['--height', '2']),
 ('t_valley', T, [xy(*tv, th_, tsx, tsy)], ['--height', '2']),
 ('t_edgelow', T, [xy(*edge_low, th_, tsx, tsy)], ['--height', '2']),
 ('t_sw', T, [xy(0, th_ - 1, th_, tsx, tsy)], ['--height', '2']),
 ('t_blanca_20k_curv', T, [xy(617, 508, th_, tsx, tsy)], ['--height', '2', '--max-distance', '20000', '--curvature', '0.13']),
 ('t_valley_linear', T, [xy(*tv, th_, tsx, tsy)], ['--height', '2', '--surface', 'linear']),
 ('t_centre_ground_t2', T, [xy(1200, 600, th_, tsx, tsy)], ['--height', '0', '--target-height', '2']),
 ('t_blanca_triangle', T, [xy(617, 508, th_, tsx, tsy)], ['--height', '2', '--surface', 'triangle']),
 ('t_blanca_ground', T, [xy(617, 508, th_, tsx, tsy)], ['--height', '0']),
]
def pixels(p):
    d = open(p, 'rb').read(); pos = 8; idat = b''; w = h = 0
    while pos < len(d):
        n, = struct.unpack('>I', d[pos:pos + 4]); t = d[pos + 4:pos + 8]
        if t == b'IHDR': w, h = struct.unpack('>II', d[pos + 8:pos + 16])
        if t == b'IDAT': idat += d[pos + 8:pos + 8 + n]
        pos += 12 + n
    raw = zlib.decompress(idat); rows = []; prev = bytearray(w)
    for r in range(h):
        f = raw[r * (w + 1)]; line = bytearray(raw[r * (w + 1) + 1:(r + 1) * (w + 1)])
        assert f == 0, 'filter'
        rows.append(bytes(line))
    return b''.join(rows)
bad = 0
only = sys.argv[3:] 
for name, dem, obs, extra in cases:
    if only and name not in only: continue
    res = []
    for tag, b in (('old', old), ('new', new)):
        cmd = [b, 'viewshed', '--dem', dem, '--threads', '1', '-o', f'{out}/{name}.{tag}.png', '--stats', f'{out}/{name}.{tag}.json'] + extra
        for o in obs: cmd += ['--observer', o]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        res.append(pixels(f'{out}/{name}.{tag}.png'))
    nd = sum(1 for a, b in zip(res[0], res[1]) if a != b) + abs(len(res[0]) - len(res[1]))
    bad += nd != 0
    sn = json.load(open(f'{out}/{name}.new.json')); so = json.load(open(f'{out}/{name}.old.json'))
    print(f'{name:22s} {" ".join(obs):40s} {" ".join(extra):40s} differ {nd}  rays {so["rays"]} -> {sn["rays"]}{"" if so["rays"] == sn["rays"] else " RAYSDIFF"}')
print('cases with differences:', bad)
sys.exit(1 if bad else 0)

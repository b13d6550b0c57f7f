#!/usr/bin/env python3
# viewshed-gdal-ab.py: gdal_viewshed and one or more terrad builds on the same DEM and
# observer, their runs interleaved (gdal, A, B, gdal, A, B, ...) so that a shared machine's
# load falls on all alike: min and median of each whole command's CPU time (the child's
# rusage), one thread, and each median over gdal_viewshed's. viewshed-vs-gdal.sh runs each
# tool's repetitions one after the other (and checks the agreement); on a machine whose
# speed drifts within a minute, this script's ratios are the ones to quote.
#
#   scripts/viewshed-gdal-ab.py RUNS DEM COL ROW HEIGHT TERRAD [TERRAD ...]
#
# COL, ROW: the observer's sample in the file's order (row 0 north), as viewshed-vs-gdal.sh
# takes them; GDAL reads a float32 copy (voids -9999) through an ESRI .hdr in the same local
# frame (x = col * sx, y = (h - 1 - row) * sy). No curvature on either side.
import json, os, shutil, statistics, struct, subprocess, sys, tempfile

runs, dem, col, row, height = int(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
builds = sys.argv[6:]
t = tempfile.mkdtemp(prefix='vs-gdal-ab.')
try:
    info = json.loads(subprocess.run([builds[0], 'info', '--json', dem], check=True, capture_output=True).stdout)
    w, h, (sx, sy) = info['width'], info['height'], info['spacing']
    x, y = col * sx, (h - 1 - row) * sy
    if dem.endswith('.f32'):
        d = open(dem, 'rb').read()
        v = struct.unpack('<%df' % (w * h), d)
        open(f'{t}/dem.bil', 'wb').write(struct.pack('<%df' % (w * h), *[-9999.0 if z != z else z for z in v]))
    else:
        subprocess.run(['gdal_translate', '-q', '-of', 'EHdr', '-ot', 'Float32', '-a_nodata', '-9999', dem,
                        f'{t}/dem.bil'], check=True)
        for f in ('dem.prj', 'dem.bil.aux.xml'):
            if os.path.exists(f'{t}/{f}'):
                os.remove(f'{t}/{f}')
    open(f'{t}/dem.hdr', 'w').write(f'BYTEORDER I\nLAYOUT BIL\nNROWS {h}\nNCOLS {w}\nNBANDS 1\nNBITS 32\n'
                                    f'PIXELTYPE FLOAT\nULXMAP 0\nULYMAP {(h - 1) * sy!r}\nXDIM {sx!r}\n'
                                    f'YDIM {sy!r}\nNODATA -9999\n')
    cmds = {'gdal_viewshed': ['gdal_viewshed', '-q', '-ox', repr(x), '-oy', repr(y), '-oz', height, '-tz', '0',
                              '-cc', '0', '-vv', '255', '-iv', '0', '-ov', '128', '-om', 'NORMAL', f'{t}/dem.bil',
                              f'{t}/gdal.tif']}
    for b in builds:
        cmds[b] = [b, 'viewshed', '--dem', dem, '--observer', f'{x!r},{y!r}', '--height', height, '--threads', '1',
                   '-o', f'{t}/terrad.png']
    cpu = {k: [] for k in cmds}
    for _ in range(runs):
        for k, c in cmds.items():
            p = subprocess.Popen(c, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            _, status, ru = os.wait4(p.pid, 0)
            if status != 0:
                sys.exit('failed: ' + ' '.join(c))
            cpu[k].append((ru.ru_utime + ru.ru_stime) * 1e3)
    g = statistics.median(cpu['gdal_viewshed'])
    print(f'{dem} from sample ({col}, {row}), eye {height} m up: CPU ms of the whole command, min / median '
          f'of {runs} interleaved runs')
    for k, v in cpu.items():
        print(f'  {k}: {min(v):.1f} / {statistics.median(v):.1f} ms, {statistics.median(v) / g:.2f}x gdal_viewshed')
finally:
    shutil.rmtree(t, ignore_errors=True)

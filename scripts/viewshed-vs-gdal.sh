#!/usr/bin/env bash
# viewshed-vs-gdal.sh: terrad's viewshed against gdal_viewshed (Debian's gdal-bin) on the
# same DEM and observer: agreement in per cent of the samples both answer, each
# disagreement judged by the double-precision reference (tests/oracle/viewshed_oracle),
# and the CPU time of each (whole command, start-up, terrad's split), one thread, median of
# RUNS runs. docs/viewshed.md has the figures.
#
#   scripts/viewshed-vs-gdal.sh BUILD DEM COL ROW HEIGHT [RUNS]
#
# TIMES_ONLY=1 skips the agreement (the reference re-traces every disagreement: minutes on
# the whole trinidad).
#
# COL, ROW: the observer's sample in the file's order (row 0 north), so both tools put the
# eye at the same place: the sample's height plus HEIGHT. GDAL reads the heights through
# an ESRI .hdr beside a raw float32 copy, in a local metric frame whose pixel centres are
# terrad's samples (x = col * sx, y = (h - 1 - row) * sy; sx, sy from `terrad info`, so
# lon/lat grids get the spacing terrad uses). No curvature on either side (GDAL -cc 0).
set -euo pipefail
BUILD=$1 DEM=$2 COL=$3 ROW=$4 H=$5 RUNS=${6:-3}
TERRAD=$BUILD/terrad
ORACLE=$BUILD/tests/oracle/viewshed_oracle
T=$(mktemp -d /tmp/vs-gdal.XXXXXX)
trap 'rm -rf "$T"' EXIT

"$TERRAD" info --json "$DEM" > "$T/info.json"
read -r W HH SX SY < <(python3 -c "import json,sys; j=json.load(open(sys.argv[1])); print(j['width'], j['height'], repr(j['spacing'][0]), repr(j['spacing'][1]))" "$T/info.json")
read -r X Y < <(python3 -c "import sys; c,r,w,h,sx,sy=int(sys.argv[1]),int(sys.argv[2]),int(sys.argv[3]),int(sys.argv[4]),float(sys.argv[5]),float(sys.argv[6]); print(repr(c*sx), repr((h-1-r)*sy))" "$COL" "$ROW" "$W" "$HH" "$SX" "$SY")

# Heights as raw float32, north row first, voids -9999.
case "$DEM" in
  *.f32) python3 -c "
import struct,sys
d=open(sys.argv[1],'rb').read(); n=len(d)//4
v=struct.unpack('<%df'%n,d)
open(sys.argv[2],'wb').write(struct.pack('<%df'%n,*[-9999.0 if x!=x else x for x in v]))" "$DEM" "$T/dem.bil" ;;
  *) gdal_translate -q -of EHdr -ot Float32 -a_nodata -9999 "$DEM" "$T/dem.bil"; rm -f "$T/dem.prj" "$T/dem.hdr" "$T"/dem.bil.aux.xml ;;
esac
YUL=$(python3 -c "import sys; print(repr((int(sys.argv[1])-1)*float(sys.argv[2])))" "$HH" "$SY")
cat > "$T/dem.hdr" <<EOF
BYTEORDER I
LAYOUT BIL
NROWS $HH
NCOLS $W
NBANDS 1
NBITS 32
PIXELTYPE FLOAT
ULXMAP 0
ULYMAP $YUL
XDIM $SX
YDIM $SY
NODATA -9999
EOF
echo "DEM $DEM: $W x $HH samples, spacing $SX x $SY m; observer sample col $COL row $ROW (x $X, y $Y), eye $H m up"

# CPU time (user + system: the child's own rusage), median of RUNS runs: gdal_viewshed on the
# float32 copy; terrad viewshed on the DEM as given and on the same float32 copy (read
# through its GDAL loader, which loads libgdal on first use: like with like); each tool's
# start-up alone (`gdalinfo --version`: dynamic linking of libgdal and its libraries;
# `terrad --help`: terrad without GDAL, which it loads only for a file that needs it), so
# "work" = command - start-up (GDAL's includes registering its drivers); terrad's own
# split from --stats (cpu_ms: loading, max-mipmaps, the viewshed itself, the PNG).
python3 - "$RUNS" "$TERRAD" "$DEM" "$T" "$X" "$Y" "$H" "$W" "$HH" <<'EOF'
import json, os, statistics, subprocess, sys
runs, terrad, dem, t, x, y, h, w, hh = sys.argv[1:]
runs, n = int(runs), int(w) * int(hh)

def cpu(cmd):
    ts = []
    for _ in range(runs):
        p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _, status, ru = os.wait4(p.pid, 0)
        if status != 0:
            sys.exit("failed: " + " ".join(cmd))
        ts.append((ru.ru_utime + ru.ru_stime) * 1e3)
    return statistics.median(ts)

def ours(src):
    cmd = [terrad, "viewshed", "--dem", src, "--observer", f"{x},{y}", "--height", h, "--threads", "1",
           "-o", f"{t}/ours.png", "--stats", f"{t}/st.json"]
    c, parts = cpu(cmd), []
    for _ in range(runs):
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        j = json.load(open(f"{t}/st.json"))
        cp = j["cpu_ms"]
        parts.append((cp["load"], cp["accel"], cp["viewshed"], cp["encode"], j["swept"], j["rays"]))
    return c, [statistics.median(p[k] for p in parts) for k in range(4)], parts[0][4], parts[0][5]

g_up = cpu(["gdalinfo", "--version"])
t_up = cpu([terrad, "--help"])
g = cpu(["gdal_viewshed", "-q", "-ox", x, "-oy", y, "-oz", h, "-tz", "0", "-cc", "0", "-vv", "255", "-iv", "0",
         "-ov", "128", "-om", "NORMAL", f"{t}/dem.bil", f"{t}/gdal.tif"])
print(f"CPU ms, median of {runs}: start-up alone: gdal {g_up:.0f}, terrad {t_up:.0f}")
print(f"  gdal_viewshed (float32 copy): {g:.0f} whole command, {g - g_up:.0f} work")
for label, src in (("DEM as given", dem), ("float32 copy", f"{t}/dem.bil")):
    c, (ld, ac, tr, en), swept, rays = ours(src)
    print(f"  terrad viewshed ({label}): {c:.0f} whole command, {c - t_up:.0f} work (load {ld:.0f}, "
          f"max-mipmaps {ac:.0f}, viewshed {tr:.0f} = {n / tr / 1e3:.1f} M samples/s, PNG {en:.0f}; {swept} "
          f"swept, {rays} cast): terrad/gdal {c / g:.2f}x whole command, {(c - t_up) / (g - g_up):.2f}x work")
EOF
gdal_translate -q -of ENVI "$T/gdal.tif" "$T/gdal.raw"

[ "${TIMES_ONLY:-0}" = 1 ] && exit 0
for s in bilinear triangle linear plane; do
  "$ORACLE" "$DEM" --gdal "$T/gdal.raw" "$X" "$Y" "$H" --surface "$s"
done

#!/usr/bin/env bash
# viewshed-vs-gdal.sh: terrad's viewshed against gdal_viewshed (Debian's gdal-bin) on the
# same DEM and observer: agreement in per cent of the samples both answer, each
# disagreement judged by the double-precision reference (tests/oracle/viewshed_oracle),
# and the time of each, one thread, median of RUNS runs. docs/viewshed.md has the figures.
#
#   scripts/viewshed-vs-gdal.sh BUILD DEM COL ROW HEIGHT [RUNS]
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

median() { sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
echo "DEM $DEM: $W x $HH samples, spacing $SX x $SY m; observer sample col $COL row $ROW (x $X, y $Y), eye $H m up"

for r in $(seq "$RUNS"); do
  s=$(date +%s.%N)
  gdal_viewshed -q -ox "$X" -oy "$Y" -oz "$H" -tz 0 -cc 0 -vv 255 -iv 0 -ov 128 -om NORMAL \
    "$T/dem.bil" "$T/gdal.tif" > /dev/null
  e=$(date +%s.%N)
  python3 -c "import sys; print(float(sys.argv[2])-float(sys.argv[1]))" "$s" "$e"
done | median > "$T/gdal_s"
gdal_translate -q -of ENVI "$T/gdal.tif" "$T/gdal.raw"

for r in $(seq "$RUNS"); do
  s=$(date +%s.%N)
  "$TERRAD" viewshed --dem "$DEM" --observer "$X,$Y" --height "$H" --threads 1 -o "$T/ours.png" --stats "$T/st.json"
  e=$(date +%s.%N)
  python3 -c "import sys,json; j=json.load(open(sys.argv[3])); print(float(sys.argv[2])-float(sys.argv[1]), j['timings_ms']['trace']/1e3, j['mean_steps'])" "$s" "$e" "$T/st.json"
done | sort -g -k2 > "$T/ours"
read -r WALL TRACE STEPS < <(awk -v n="$RUNS" 'NR==int((n+1)/2)' "$T/ours")
G=$(cat "$T/gdal_s")
N=$((W * HH))
python3 - "$G" "$WALL" "$TRACE" "$STEPS" "$N" <<'EOF'
import sys
g, wall, trace, steps, n = map(float, sys.argv[1:])
print(f"time, one thread, median: gdal_viewshed {g*1e3:.0f} ms ({n/g/1e6:.2f} M samples/s, whole command); "
      f"terrad viewshed {wall*1e3:.0f} ms whole command, {trace*1e3:.0f} ms tracing "
      f"({n/trace/1e6:.2f} M samples/s, {steps:.1f} steps a segment): terrad/gdal {trace/g:.2f}x (tracing), {wall/g:.2f}x (whole)")
EOF
for s in bilinear triangle linear plane; do
  "$ORACLE" "$DEM" --gdal "$T/gdal.raw" "$X" "$Y" "$H" --surface "$s"
done

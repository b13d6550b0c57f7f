#!/bin/sh
# cli_trace_check.sh ORACLE TERRAD DEM SEED RAYS: `terrad trace` end to end. Writes a ray
# set (seed not used by the in-process oracle runs) for DEM, pipes it through
# `terrad trace` for every method and surface, and judges the hits with the oracle
# (triangle: Embree + exact settling; others: the double reference). Also checks that a
# truncated record and a bad ray are refused.
set -eu
oracle=$1 terrad=$2 dem=$3 seed=$4 rays=$5
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$oracle" --dem "$dem" --write-rays "$tmp/rays.bin" --rays "$rays" --seed "$seed" >/dev/null
for s in triangle bilinear plane linear; do
  for m in incremental hierarchical parametric silhouette auto; do
    "$terrad" trace --dem "$dem" --method "$m" --surface "$s" --threads 2 \
      --stats "$tmp/stats.json" < "$tmp/rays.bin" > "$tmp/hits.bin"
    grep -q "\"rays\": $rays" "$tmp/stats.json"
    printf '%-12s ' "$m"
    if ! "$oracle" --dem "$dem" --surface "$s" --check "$tmp/rays.bin" "$tmp/hits.bin" > "$tmp/check.txt"; then
      cat "$tmp/check.txt"; exit 1
    fi
    tail -n 2 "$tmp/check.txt" | tr "\n" " "; echo
  done
done
# refusals: a truncated final record, and a zero direction (ray index 1)
head -c 100 "$tmp/rays.bin" > "$tmp/short.bin"
if "$terrad" trace --dem "$dem" < "$tmp/short.bin" > /dev/null 2> "$tmp/err"; then
  echo "FAIL: truncated input accepted"; exit 1
fi
grep -q truncated "$tmp/err"
head -c 48 "$tmp/rays.bin" > "$tmp/bad.bin"
printf '\000\000\000\000\000\000\360\077%.0s' 1 2 3 >> "$tmp/bad.bin"   # o = (1, 1, 1)
printf '\000\000\000\000\000\000\000\000%.0s' 1 2 3 >> "$tmp/bad.bin"   # d = 0
if "$terrad" trace --dem "$dem" < "$tmp/bad.bin" > /dev/null 2> "$tmp/err"; then
  echo "FAIL: zero direction accepted"; exit 1
fi
grep -q "ray 1" "$tmp/err"
echo "PASS: terrad trace refuses truncated input and bad rays"

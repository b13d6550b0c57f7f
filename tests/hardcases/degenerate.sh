#!/bin/bash
# degenerate.sh: `terrad trace` on made-up degenerate terrains and ray sets beyond those of
# the hard-cases suite (other sizes, spacings, seeds, void patterns and nodata written as
# a number), for every method and surface, each answer judged against the double
# reference by hc_tool check (no wrong hit, no missed hit, no hit behind the origin, no
# NaN). Also: a ray file with NaN or inf in any component is refused (exit 1, no output).
#
#   tests/hardcases/degenerate.sh TERRAD HC_TOOL [WORKDIR]
#   (ctest runs it as hardcases_degenerate_cli; RAYS=N sets the rays per terrain)
set -u
terrad=${1:?usage: degenerate.sh TERRAD HC_TOOL [WORKDIR]}
tool=${2:?usage: degenerate.sh TERRAD HC_TOOL [WORKDIR]}
work=${3:-}
rays=${RAYS:-1500}
if [ -z "$work" ]; then
    work=$(mktemp -d /tmp/terrad-degenerate.XXXXXX)
    trap 'rm -rf "$work"' EXIT
fi
mkdir -p "$work"

# name | hc_tool dem arguments | --k
terrains=(
    "flat-strip|flat w=50 h=3 sx=2.5 base=-7.25|16"
    "single-cell|saddles w=2 h=2 sx=4 sy=9 relief=40|1"
    "cell-column|procedural w=2 h=300 sx=3 relief=200 seed=5|16"
    "needle-5km|needle w=70 h=70 sx=0.5 relief=5000|16"
    "wall-1e4|wall w=33 h=65 sx=3 sy=0.7 relief=10000 base=-3000|2"
    "terraces-k8|terraces w=60 h=45 k=8 relief=70 base=0|8"
    "terraces-k16|terraces w=100 h=90 k=16 relief=150 base=20|16"
    "plateau|plateau w=80 h=20 plateau=130 seed=3|16"
    "steps-rows|steps w=77 h=51 voids=rows seed=4|16"
    "saddles-tiles|saddles w=40 h=40 voids=tiles tile=3 seed=6|3"
    "voids-single|procedural w=90 h=70 voids=single seed=9|255"
    "voids-seams-cm|procedural w=64 h=48 sx=0.01 sy=0.02 base=1 relief=0.3 voids=seams tile=3|16"
    "ridge-10km|ridge w=45 h=30 sx=10000 sy=7000 relief=8000|16"
    "deep-1e4|procedural w=30 h=60 base=-10000 relief=20|16"
    "high-1e4|steps w=61 h=33 base=9990 relief=10|1"
    "all-void|procedural w=20 h=20 voids=all|16"
)
methods="incremental hierarchical parametric silhouette auto"
surfaces="plane linear triangle bilinear"
fail=0
runs=0
seed=9001
for entry in "${terrains[@]}"; do
    IFS='|' read -r name args k <<<"$entry"
    read -r kind params <<<"$args"
    # shellcheck disable=SC2086
    if ! "$tool" dem "$kind" "$work/$name" $params; then
        echo "FAIL $name: hc_tool dem $args"
        fail=$((fail + 1))
        continue
    fi
    seed=$((seed + 1))
    if ! "$tool" rays "$work/$name.f32" "$work/$name.rays" "$rays" "$seed"; then
        echo "FAIL $name: hc_tool rays"
        fail=$((fail + 1))
        continue
    fi
    pairs=()
    for m in $methods; do
        for s in $surfaces; do
            runs=$((runs + 1))
            if ! "$terrad" trace --dem "$work/$name.f32" --method "$m" --surface "$s" --k "$k" \
                    --threads 2 <"$work/$name.rays" >"$work/$name.$m.$s.hits" 2>"$work/$name.err"; then
                echo "FAIL $name $m $s: terrad trace: $(cat "$work/$name.err")"
                fail=$((fail + 1))
                continue
            fi
            pairs+=("$s" "$work/$name.$m.$s.hits")
        done
    done
    if [ ${#pairs[@]} -gt 0 ] && ! "$tool" check "$work/$name.f32" "$work/$name.rays" "${pairs[@]}" \
            >"$work/$name.check"; then
        echo "FAIL $name (see below)"
        fail=$((fail + 1))
    fi
    sed -e "s|$work/||" "$work/$name.check"
done

# NaN or inf in each component: the file is refused with the ray's index, nothing written
if ! "$tool" dem procedural "$work/bad" w=20 h=20; then
    echo "FAIL hc_tool could not write the DEM for the bad rays"
    fail=$((fail + 1))
fi
for c in 0 1 2 3 4 5; do
    if ! "$tool" badrays "$work/bad.rays" "$c"; then
        echo "FAIL hc_tool could not write the bad rays"
        fail=$((fail + 1))
    elif "$terrad" trace --dem "$work/bad.f32" <"$work/bad.rays" >"$work/bad.hits" 2>"$work/bad.err"; then
        echo "FAIL terrad trace accepted rays with NaN/inf in component $c"
        fail=$((fail + 1))
    elif [ -s "$work/bad.hits" ]; then
        echo "FAIL terrad trace wrote hits for a refused ray file (component $c)"
        fail=$((fail + 1))
    else
        echo "NaN/inf in component $c refused: $(head -c 120 "$work/bad.err")"
    fi
done

echo "degenerate terrains: ${#terrains[@]}, trace runs: $runs ($rays rays each), failures: $fail"
[ "$fail" -eq 0 ]

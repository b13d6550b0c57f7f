#!/usr/bin/env bash
# topology.sh: the docker/compose.yaml topology without Docker. Debian's nginx on loopback,
# with a config generated into a temporary directory, in front of three `terrad serve`
# processes sharing one data directory of twelve datasets. Checked:
#  - routing by dataset: every dataset's requests (renders with ?dataset=, tiles by path)
#    reach exactly one replica, read from each replica's own /metrics
#    (terrad_dataset_requests_total), and the datasets spread over more than one replica;
#  - failover: the replica that owns the first dataset gets SIGTERM in the middle of a run
#    of renders, and no request fails (terrad finishes what it holds and refuses new work;
#    nginx's proxy_next_upstream sends refused or failed attempts to the next replica);
#  - consistent hashing: afterwards the stopped replica's datasets are served by the
#    others, and no dataset of a surviving replica moved.
#
# The nginx configuration is docker/nginx.conf itself (the one compose.yaml mounts), with
# the replicas' addresses and the listen port substituted.
#
# usage: topology.sh TERRAD DATA_DIR NGINX_CONF   (exit 77 = skipped: no nginx or curl)
set -u
TERRAD=$1
DATA=$2
CONF=$3
NGINX=$(command -v nginx || echo /usr/sbin/nginx)
[ -x "$NGINX" ] || { echo "skip: nginx not installed"; exit 77; }
command -v curl >/dev/null || { echo "skip: curl not installed"; exit 77; }

T=$(mktemp -d "${TMPDIR:-/tmp}/terrad-topology.XXXXXX")
chmod 755 "$T"
PIDS=()
cleanup() {
  for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null; done
  wait 2>/dev/null
  rm -rf "$T"
}
trap cleanup EXIT
fail() { echo "FAIL: $*"; echo "--- nginx error log"; tail -20 "$T/error.log" 2>/dev/null; exit 1; }

# Twelve datasets (copies of the demo volcano under other ids): with three replicas the
# chance that all land on one is 3^-11, so "spread" is a fair assertion.
mkdir -p "$T/data"
DS=()
for k in 01 02 03 04 05 06 07 08 09 10 11 12; do
  cp "$DATA/volcano/volcano.asc" "$T/data/d$k.asc" || fail "no demo volcano in $DATA"
  DS+=("d$k")
done

start_terrad() { # $1 = name; started from this shell, so that `wait` can collect it
  "$TERRAD" serve --listen 127.0.0.1:0 --demo-dir "" --data "$T/data" --preload none \
      --render-workers 1 --queue 8 --shutdown-timeout 10 >"$T/$1.out" 2>"$T/$1.log" &
  echo $! >"$T/$1.pid"
  PIDS+=("$!")
}
port_of() { # $1 = name; prints the port from its `listening` line, once it is `ready`
  for _ in $(seq 200); do
    port=$(grep -o 'event=listening.* port=[0-9]*' "$T/$1.log" | grep -o 'port=[0-9]*' | cut -d= -f2)
    [ -n "$port" ] && grep -q 'event=ready ' "$T/$1.log" && { echo "$port"; return 0; }
    sleep 0.05
  done
  return 1
}

start_terrad r1
start_terrad r2
start_terrad r3
P1=$(port_of r1) || fail "replica 1 did not start"
P2=$(port_of r2) || fail "replica 2 did not start"
P3=$(port_of r3) || fail "replica 3 did not start"
PORT=([1]="$P1" [2]="$P2" [3]="$P3")

mkdir -p "$T/tmp"
chmod 777 "$T/tmp"
start_nginx() { # $1 = port; docker/nginx.conf with loopback addresses, in a temp prefix
  sed -e "s/terrad1:8080/127.0.0.1:$P1/" -e "s/terrad2:8080/127.0.0.1:$P2/" \
      -e "s/terrad3:8080/127.0.0.1:$P3/" \
      -e "s/listen 80;/listen 127.0.0.1:$1;/" "$CONF" >"$T/default.conf"
  grep -q "127.0.0.1:$P1" "$T/default.conf" && grep -q "127.0.0.1:$P2" "$T/default.conf" \
      && grep -q "127.0.0.1:$P3" "$T/default.conf" && grep -q "hash \$terrad_dataset consistent" "$T/default.conf" \
      && grep -q "listen 127.0.0.1:$1;" "$T/default.conf" || fail "docker/nginx.conf changed shape"
  cat >"$T/nginx.conf" <<CONF
worker_processes 1;
daemon off;
pid $T/nginx.pid;
error_log $T/error.log warn;
events { worker_connections 256; }
http {
  access_log $T/access.log;
  client_body_temp_path $T/tmp/body;
  proxy_temp_path $T/tmp/proxy;
  fastcgi_temp_path $T/tmp/fastcgi;
  uwsgi_temp_path $T/tmp/uwsgi;
  scgi_temp_path $T/tmp/scgi;
  include $T/default.conf;
}
CONF
  "$NGINX" -c "$T/nginx.conf" -p "$T" >/dev/null 2>>"$T/error.log" &
  NGINX_PID=$!
}
for _ in $(seq 20); do
  PN=$(( 20000 + (RANDOM % 20000) ))
  start_nginx "$PN"
  ok=0
  for _ in $(seq 40); do
    curl -s -o /dev/null "http://127.0.0.1:$PN/healthz" && { ok=1; break; }
    kill -0 "$NGINX_PID" 2>/dev/null || break
    sleep 0.05
  done
  [ "$ok" = 1 ] && break
  kill "$NGINX_PID" 2>/dev/null
  wait "$NGINX_PID" 2>/dev/null
done
[ "$ok" = 1 ] || fail "nginx did not start"
PIDS+=("$NGINX_PID")

scene() { echo "{\"dataset\":\"$1\",\"camera\":{\"position\":{\"x\":300,\"y\":-400,\"z\":450},\"pitch\":-20},\"image\":{\"width\":64,\"height\":48}}"; }
render() { # $1 = dataset; prints the status
  curl -s -o /dev/null -w '%{http_code}\n' -X POST -H 'Content-Type: application/json' \
       --data "$(scene "$1")" "http://127.0.0.1:$PN/v1/render?dataset=$1"
}
requests_on() { # $1 = replica number, $2 = dataset: its terrad_dataset_requests_total
  curl -s "http://127.0.0.1:${PORT[$1]}/metrics" |
    sed -n "s/^terrad_dataset_requests_total{dataset=\"$2\"} //p"
}

# 1. Each dataset to one replica: renders by query key, a tile by path.
for d in "${DS[@]}"; do
  for _ in 1 2; do echo "$(render "$d")"; done
  curl -s -o /dev/null -w '%{http_code}\n' "http://127.0.0.1:$PN/v1/tiles/$d/0/0/0.png"
done >"$T/phase1.codes"
[ "$(grep -c '^200$' "$T/phase1.codes")" = 36 ] || fail "phase 1: $(sort "$T/phase1.codes" | uniq -c | tr '\n' ' ')"
declare -A OWNER
for d in "${DS[@]}"; do
  owners=""
  for r in 1 2 3; do
    n=$(requests_on "$r" "$d")
    [ -n "$n" ] || fail "replica $r has no terrad_dataset_requests_total for $d"
    [ "$n" -gt 0 ] && owners="$owners$r"
  done
  [ ${#owners} = 1 ] || fail "dataset $d reached replicas '$owners', not exactly one"
  OWNER[$d]=$owners
done
used=$(printf '%s\n' "${OWNER[@]}" | sort -u | wc -l)
echo "owners: $(for d in "${DS[@]}"; do printf '%s=r%s ' "$d" "${OWNER[$d]}"; done)"
[ "$used" -ge 2 ] || fail "all datasets on one replica"
VICTIM=${OWNER[d01]}

# 2. Renders over every dataset from two clients; the first dataset's replica is stopped.
client() { # $1 = name, $2 = rounds over the datasets; one status per line
  for _ in $(seq "$2"); do
    for d in "${DS[@]}"; do render "$d"; done
  done >"$T/$1.codes"
}
client c1 5 &
C1=$!
client c2 5 &
C2=$!
for _ in $(seq 400); do
  [ "$(cat "$T/c1.codes" "$T/c2.codes" 2>/dev/null | wc -l)" -ge 20 ] && break
  sleep 0.05
done
kill -TERM "$(cat "$T/r$VICTIM.pid")"
wait "$(cat "$T/r$VICTIM.pid")"
rcv=$?
wait "$C1" "$C2"

total=$(cat "$T/c1.codes" "$T/c2.codes" | wc -l)
good=$(cat "$T/c1.codes" "$T/c2.codes" | grep -c '^200$')
echo "requests=$total ok=$good stopped=r$VICTIM exit=$rcv"
[ "$total" = 120 ] || fail "expected 120 answers, got $total"
[ "$good" = 120 ] || fail "$((total - good)) requests failed: $(sort "$T"/c*.codes | uniq -c | tr '\n' ' ')"
[ "$rcv" = 0 ] || fail "replica $VICTIM exited $rcv on SIGTERM"
grep -q 'event=stopped' "$T/r$VICTIM.log" || fail "replica $VICTIM did not log its stop"

# 3. The stopped replica's datasets moved to the others; no other dataset moved.
for d in "${DS[@]}"; do
  o=${OWNER[$d]}
  for r in 1 2 3; do
    [ "$r" = "$VICTIM" ] && continue
    n=$(requests_on "$r" "$d")
    if [ "$o" = "$VICTIM" ]; then
      [ "$n" -gt 0 ] && moved=1
    elif [ "$r" != "$o" ] && [ "$n" != 0 ]; then
      fail "dataset $d of surviving replica $o also reached replica $r ($n requests)"
    fi
  done
done
[ "${moved:-0}" = 1 ] || fail "the stopped replica's datasets were served by no other replica"
for r in 1 2 3; do
  [ "$r" = "$VICTIM" ] && continue
  curl -s "http://127.0.0.1:${PORT[$r]}/metrics" | grep -q '^terrad_dataset_resident_bytes{dataset="d01"} [1-9]' ||
    fail "replica $r has no per-dataset residency in /metrics"
done
echo "PASS"

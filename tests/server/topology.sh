#!/usr/bin/env bash
# topology.sh: the docker/compose.yaml topology without Docker. Debian's nginx on loopback,
# with a config generated into a temporary directory, in front of two `terrad serve`
# processes; renders go through nginx; one replica gets SIGTERM in the middle of the run,
# and no request may fail: terrad finishes what it holds and refuses new work, and
# nginx's proxy_next_upstream sends refused or failed attempts to the other replica.
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

start_terrad() { # $1 = name; started from this shell, so that `wait` can collect it
  "$TERRAD" serve --listen 127.0.0.1:0 --demo-dir "$DATA" --preload none \
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
P1=$(port_of r1) || fail "replica 1 did not start"
P2=$(port_of r2) || fail "replica 2 did not start"

mkdir -p "$T/tmp"
chmod 777 "$T/tmp"
start_nginx() { # $1 = port; docker/nginx.conf with loopback addresses, in a temp prefix
  sed -e "s/terrad1:8080/127.0.0.1:$P1/" -e "s/terrad2:8080/127.0.0.1:$P2/" \
      -e "s/listen 80;/listen 127.0.0.1:$1;/" "$CONF" >"$T/default.conf"
  grep -q "127.0.0.1:$P1" "$T/default.conf" && grep -q "127.0.0.1:$P2" "$T/default.conf" \
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

SCENE='{"dataset":"volcano","camera":{"position":{"x":300,"y":-400,"z":450},"pitch":-20},"image":{"width":96,"height":64}}'
client() { # $1 = name, $2 = requests; one status per line
  for _ in $(seq "$2"); do
    curl -s -o /dev/null -w '%{http_code}\n' -X POST -H 'Content-Type: application/json' \
         --data "$SCENE" "http://127.0.0.1:$PN/v1/render"
  done >"$T/$1.codes"
}
client c1 60 &
C1=$!
client c2 60 &
C2=$!
# Once both replicas have answered renders, stop replica 1 while the clients run on.
for _ in $(seq 400); do
  n1=$(grep -c 'route=render status=200' "$T/r1.log")
  n2=$(grep -c 'route=render status=200' "$T/r2.log")
  [ "$n1" -ge 5 ] && [ "$n2" -ge 5 ] && break
  sleep 0.05
done
[ "$n1" -ge 5 ] && [ "$n2" -ge 5 ] || fail "renders were not spread over both replicas ($n1, $n2)"
kill -TERM "$(cat "$T/r1.pid")"
wait "$(cat "$T/r1.pid")"
rc1=$?
wait "$C1" "$C2"

total=$(cat "$T/c1.codes" "$T/c2.codes" | wc -l)
good=$(cat "$T/c1.codes" "$T/c2.codes" | grep -c '^200$')
after=$(grep -c 'route=render status=200' "$T/r2.log")
echo "requests=$total ok=$good replica1_exit=$rc1 replica1_renders=$n1+ replica2_renders=$after"
[ "$total" = 120 ] || fail "expected 120 answers, got $total"
[ "$good" = 120 ] || fail "$((total - good)) requests failed: $(sort "$T"/c*.codes | uniq -c | tr '\n' ' ')"
[ "$rc1" = 0 ] || fail "replica 1 exited $rc1 on SIGTERM"
grep -q 'event=stopped' "$T/r1.log" || fail "replica 1 did not log its stop"
[ "$after" -gt "$n2" ] || fail "replica 2 took no renders after replica 1 stopped"
echo "PASS"

#!/usr/bin/env bash
# Sharded place maps on one machine: two recogd shards behind nginx with the shipped router
# configuration (deploy/nginx/recogd-router.conf), the placement table read by nginx and by both
# servers. Checks that maps streamed through nginx give the results of a single server, that a
# shard refuses a map it does not own (naming the owner), that nginx refuses an unplaced map,
# that a killed shard's maps get UNAVAILABLE while the other shard's keep working, and that the
# restarted shard has every acknowledged frame.
# Usage: sharding_test.sh RECOG RECOGD PROJECT_DIR. Exits 77 (skipped) without nginx.
set -u
recog=$1
recogd=$2
project=$3
nginx_bin=$(command -v nginx || echo /usr/sbin/nginx)
if [ ! -x "$nginx_bin" ]; then
  echo "SKIP: nginx is not installed (Debian: apt-get install nginx)"
  exit 77
fi
tmp=$(mktemp -d)
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill -KILL "$pid" 2>/dev/null; done
  rm -rf "$tmp"
}
trap cleanup EXIT
# shellcheck source=../../tools/recog/cli_test_lib.sh
source "$project/tools/recog/cli_test_lib.sh"

# start_shard NAME PORT: a recogd for shard NAME on PORT with its own data directory.
start_shard() {
  "$recogd" --listen "127.0.0.1:$2" --data-dir "$tmp/$1" --metrics-listen "" --workers 2 \
    --shard-name "$1" --placement-file "$tmp/router/placement.map" >>"$tmp/$1.log" 2>&1 &
  pids+=($!)
  eval "pid_$1=$!"
  wait_serving "127.0.0.1:$2" || fail "shard $1 did not come up: $(tail -3 "$tmp/$1.log")"
}
wait_serving() {
  for _ in $(seq 150); do
    "$recog" admin health --server "$1" --timeout-ms 500 >/dev/null 2>&1 && return 0
    sleep 0.1
  done
  return 1
}

images=$project/tests/data/corridor
port_a=$(free_port); port_b=$(free_port); port_single=$(free_port); port_router=$(free_port)
mkdir -p "$tmp/router"
cat >"$tmp/router/placement.map" <<MAP
# test placement
corridor-a   shard_a;
corridor-b   shard_b;
MAP
printf 'shard_a shard_a;\nshard_b shard_b;\n' >"$tmp/router/shards.map"
cat >"$tmp/router/upstreams.conf" <<UPSTREAMS
upstream shard_a { server 127.0.0.1:$port_a; }
upstream shard_b { server 127.0.0.1:$port_b; }
upstream models_primary { server 127.0.0.1:$port_a; }
upstream models_any { server 127.0.0.1:$port_a; server 127.0.0.1:$port_b; }
UPSTREAMS
# The shipped router configuration, with its files and port moved here.
sed -e "s|/etc/recogd/router/|$tmp/router/|g" -e "s|listen 50050 http2;|listen 127.0.0.1:$port_router http2;|" \
  "$project/deploy/nginx/recogd-router.conf" >"$tmp/router/recogd-router.conf"
mkdir -p "$tmp/nginx"
cat >"$tmp/nginx.conf" <<CONF
daemon off;
master_process off;
worker_processes 1;
error_log $tmp/nginx/error.log warn;
pid $tmp/nginx/nginx.pid;
events { worker_connections 256; }
http {
  access_log off;
  client_body_temp_path $tmp/nginx/body;
  proxy_temp_path $tmp/nginx/proxy;
  fastcgi_temp_path $tmp/nginx/fastcgi;
  uwsgi_temp_path $tmp/nginx/uwsgi;
  scgi_temp_path $tmp/nginx/scgi;
  include $tmp/router/recogd-router.conf;
}
CONF
"$nginx_bin" -t -p "$tmp/nginx" -c "$tmp/nginx.conf" >"$tmp/nginx-t.log" 2>&1 \
  && pass || fail "nginx accepts the router configuration: $(cat "$tmp/nginx-t.log")"

start_shard shard_a "$port_a"
start_shard shard_b "$port_b"
"$nginx_bin" -p "$tmp/nginx" -c "$tmp/nginx.conf" >"$tmp/nginx/stdout.log" 2>&1 &
pids+=($!)
"$recogd" --listen "127.0.0.1:$port_single" --data-dir "$tmp/single" --metrics-listen "" \
  --workers 2 >"$tmp/single.log" 2>&1 &
pids+=($!)
wait_serving "127.0.0.1:$port_single" || fail "the single server did not come up"
wait_serving "127.0.0.1:$port_router" || fail "nginx did not route health checks: $(tail -3 "$tmp/nginx/error.log")"
router=(--server "127.0.0.1:$port_router")

# The same frames into a map on each shard through nginx, and into one map of a single server.
for map in corridor-a corridor-b; do
  expect_ok "stream into $map through nginx" "$recog" stream --map "$map" --create \
    --images "$images" --json -q "${router[@]}"
  grep -v '"summary"' "$tmp/out" >"$tmp/$map.loops"
  grep -q '"frames":4' "$tmp/out" && pass || fail "$map: 4 frames answered: $(cat "$tmp/out")"
done
expect_ok "stream into a single server" "$recog" stream --map corridor-a --create \
  --images "$images" --json -q --server "127.0.0.1:$port_single"
grep -v '"summary"' "$tmp/out" >"$tmp/single.loops"
cmp -s "$tmp/corridor-a.loops" "$tmp/single.loops" && cmp -s "$tmp/corridor-b.loops" "$tmp/single.loops" \
  && pass || fail "the shards' loops equal the single server's"
for map in corridor-a corridor-b; do
  expect_ok "maps stats $map through nginx" "$recog" maps stats "$map" --json "${router[@]}"
  json_check "$map has 4 frames" "assert d['frames']==4, d"
done
expect_ok "maps list of shard_b through nginx" "$recog" maps list --shard shard_b --json "${router[@]}"
json_check "shard_b lists corridor-b only" "assert [m['name'] for m in d]==['corridor-b'], d"

# Refusals: a shard asked for another shard's map; nginx asked for an unplaced map.
expect_error "shard_a refuses corridor-b" "FAILED_PRECONDITION.*belongs to shard 'shard_b'" \
  "$recog" maps create corridor-b --server "127.0.0.1:$port_a"
expect_error "nginx refuses an unplaced map" "FAILED_PRECONDITION.*placement table" \
  "$recog" maps create elsewhere "${router[@]}"
expect_error "maps list needs a shard through nginx" "FAILED_PRECONDITION" \
  "$recog" maps list "${router[@]}"

# shard_b dies: its maps are UNAVAILABLE, shard_a's keep working; restarted, it has every frame.
kill -KILL "$pid_shard_b"
wait "$pid_shard_b" 2>/dev/null
expect_error "corridor-b while shard_b is down" "UNAVAILABLE" \
  "$recog" maps stats corridor-b "${router[@]}"
expect_ok "corridor-a while shard_b is down" "$recog" query --map corridor-a "$images/41.jpg" \
  --json "${router[@]}"
json_check "corridor-a still finds its places" "assert d['status']=='loop_detected' and d['match']==2, d"
start_shard shard_b "$port_b"
expect_ok "corridor-b after the restart" "$recog" maps stats corridor-b --json "${router[@]}"
json_check "corridor-b kept its 4 acknowledged frames" "assert d['frames']==4, d"

report_and_exit

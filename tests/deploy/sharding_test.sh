#!/usr/bin/env bash
# Several servers on one machine: two recogd shards, which are also replicas of the model
# repository, and a repository primary, behind nginx with the shipped router configuration
# (deploy/nginx/recogd-router.conf, clients over TLS), the placement table read by nginx and by
# both shards.
# Checks that maps streamed through nginx give the results of a single server, that a shard
# refuses a map it does not own (naming the owner), that nginx refuses an unplaced map, that a
# killed shard's maps get UNAVAILABLE while the other shard's keep working, that the restarted
# shard has every acknowledged frame, and that a model uploaded through nginx (to the primary,
# while a shard is down) is recognised through every shard, and deleted from every shard.
# Usage: sharding_test.sh RECOG RECOGD PROJECT_DIR. Exits 77 (skipped) without nginx.
recog=$1
recogd=$2
project=$3
# shellcheck source=router_test_lib.sh
source "$project/tests/deploy/router_test_lib.sh"

# start_shard NAME PORT: a recogd for shard NAME on PORT, following the repository primary.
start_shard() {
  start_recogd "$1" "127.0.0.1:$2" --shard-name "$1" --placement-file "$tmp/router/placement.map" \
    --repository-primary "127.0.0.1:$port_primary"
}

images=$project/tests/data/corridor
port_a=$(free_port); port_b=$(free_port); port_single=$(free_port); port_router=$(free_port)
port_primary=$(free_port)
cat >"$tmp/router/placement.map" <<MAP
# test placement
corridor-a   shard_a;
corridor-b   shard_b;
fleet-a      shard_b;
fleet-x      shard_a;
group:fleet  shard_b;
MAP
printf 'shard_a 127.0.0.1:%s;\nshard_b 127.0.0.1:%s;\n' "$port_a" "$port_b" >"$tmp/router/shards.map"
printf 'primary 127.0.0.1:%s;\nany 127.0.0.1:%s;\n' "$port_primary" "$port_primary" >"$tmp/router/models.map"
make_router_certs
write_router_conf "$port_router" "$(free_port)"

start_recogd primary "127.0.0.1:$port_primary"
start_shard shard_a "$port_a"
start_shard shard_b "$port_b"
start_router
start_recogd single "127.0.0.1:$port_single"
wait_serving "127.0.0.1:$port_router" --tls-ca "$tmp/ca.crt" || fail "nginx did not route health checks: $(tail -3 "$tmp/nginx/error.log")"

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

# A group lives on its shard: a Relocalize that names only the group is routed there by nginx;
# a map of the group cannot be created elsewhere, nor can another shard's map search the group.
expect_ok "stream into fleet-a, of group fleet, through nginx" "$recog" stream --map fleet-a \
  --create --group fleet --images "$images" -q "${router[@]}"
expect_ok "relocalize in the group through nginx" "$recog" relocalize "$images/41.jpg" \
  --group fleet --json "${router[@]}"
json_check "the group's shard finds 41.jpg in fleet-a" \
  "p=d['places']; assert [x['map'] for x in p]==['fleet-a'] and p[0]['result']['match']==2, d"
expect_error "a map of the group on another shard" \
  "FAILED_PRECONDITION.*group 'fleet' belongs to shard 'shard_b'" \
  "$recog" maps create fleet-x --group fleet "${router[@]}"
expect_error "shard_a's map searching the group" \
  "FAILED_PRECONDITION.*group 'fleet' belongs to shard 'shard_b'" \
  "$recog" stream --map corridor-a --images "$images/41.jpg" --search-group fleet -q "${router[@]}"

# shard_b dies: its maps are UNAVAILABLE, shard_a's keep working; restarted, it has every frame.
kill -KILL "$pid_shard_b"
wait "$pid_shard_b" 2>/dev/null
expect_error "corridor-b while shard_b is down" "UNAVAILABLE" \
  "$recog" maps stats corridor-b "${router[@]}"
expect_ok "corridor-a while shard_b is down" "$recog" query --map corridor-a "$images/41.jpg" \
  --json "${router[@]}"
json_check "corridor-a still finds its places" "assert d['status']=='loop_detected' and d['match']==2, d"

# A model pushed through nginx while shard_b is down goes to the repository primary; shard_a
# follows it at once, shard_b once it is back.
expect_ok "model build" "$recog" model build --planar "$images/1.jpg" --width 0.64 --height 0.48 \
  --name poster -o "$tmp/poster.robj"
expect_ok "models push through nginx" "$recog" models push "$tmp/poster.robj" --json "${router[@]}"
json_check "the primary stored version 1" "assert d[0]['name']=='poster' and d[0]['version']==1, d"
# recognised_through SHARD PYTHON: recognition through nginx on SHARD, until PYTHON holds of the
# detected (name, version) pairs `found` (20 s at most).
recognised_through() {
  for _ in $(seq 200); do
    "$recog" recognize --image "$images/1.jpg" --camera 500,500,256,192 --json --shard "$1" \
      "${router[@]}" >"$tmp/out" 2>"$tmp/err" &&
      /usr/bin/python3 -c "import json; d=json.load(open('$tmp/out'));
found=[(x['name'], x['version']) for x in d['detections']]; assert $2" 2>/dev/null && return 0
    sleep 0.1
  done
  return 1
}
recognised_through shard_a "('poster', 1) in found" && pass \
  || fail "shard_a recognises the pushed poster: $(cat "$tmp/out" "$tmp/err")"
expect_error "a shard refuses an upload, naming the primary" \
  "FAILED_PRECONDITION.*read-only replica.*127.0.0.1:$port_primary" \
  "$recog" models push "$tmp/poster.robj" --server "127.0.0.1:$port_a"

start_shard shard_b "$port_b"
expect_ok "corridor-b after the restart" "$recog" maps stats corridor-b --json "${router[@]}"
json_check "corridor-b kept its 4 acknowledged frames" "assert d['frames']==4, d"
recognised_through shard_b "('poster', 1) in found" && pass \
  || fail "shard_b, restarted, recognises the poster pushed while it was down: $(cat "$tmp/out" "$tmp/err")"
expect_ok "models pull from shard_b through nginx" "$recog" models pull poster -o "$tmp/pulled.robj" \
  --shard shard_b "${router[@]}"
cmp -s "$tmp/poster.robj" "$tmp/pulled.robj" && pass || fail "shard_b holds the pushed file"

expect_ok "models delete through nginx" "$recog" models delete poster "${router[@]}"
for shard in shard_a shard_b; do
  recognised_through "$shard" "'poster' not in [n for n, v in found]" && pass \
    || fail "$shard forgets the deleted poster: $(cat "$tmp/out")"
done

report_and_exit

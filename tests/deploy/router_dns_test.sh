#!/usr/bin/env bash
# A shard that comes back on another address, behind its name, reached through the router without
# reloading nginx (deploy/nginx/recogd-router.conf re-resolves names: resolver.conf, `valid=`).
# A small DNS server (tiny_dns.py) answers for shard-m.recog.test from a file the test rewrites;
# the router's resolver is that server with `valid=1s`. A recogd on 127.0.0.1:P is the shard;
# it is killed and started again, with the same store, on 127.0.0.2:P (a pod restarted with a
# new IP; the port stays, as in the router's files). Checks that calls through the router fail
# with UNAVAILABLE while the name still points to the old address, reach the new server once the
# name moves (the same 4 frames), and fail with UNAVAILABLE when the name stops resolving; and that
# calls for `any` (models.map: a name with both addresses) reach the server wherever it is, by
# moving on from the address that refuses.
# Usage: router_dns_test.sh RECOG RECOGD PROJECT_DIR. Exits 77 (skipped) without nginx.
recog=$1
recogd=$2
project=$3
# shellcheck source=router_test_lib.sh
source "$project/tests/deploy/router_test_lib.sh"

images=$project/tests/data/corridor
port_shard=$(free_port); port_router=$(free_port)
name=shard-m.recog.test
any=models.recog.test
printf '%s 127.0.0.1\n%s 127.0.0.1\n%s 127.0.0.2\n' "$name" "$any" "$any" >"$tmp/dns.records"
/usr/bin/python3 "$project/tests/deploy/tiny_dns.py" "$tmp/dns.records" "$tmp/dns.port" \
  2>"$tmp/dns.log" &
pids+=($!)
for _ in $(seq 100); do [ -s "$tmp/dns.port" ] && break; sleep 0.05; done
[ -s "$tmp/dns.port" ] || { fail "the DNS server did not start: $(cat "$tmp/dns.log")"; report_and_exit; }
echo "resolver 127.0.0.1:$(cat "$tmp/dns.port") valid=1s; resolver_timeout 1s;" >"$tmp/router/resolver.conf"
echo "corridor-m shard_m;" >"$tmp/router/placement.map"
echo "shard_m $name:$port_shard;" >"$tmp/router/shards.map"
printf 'primary %s:%s;\nany %s:%s;\n' "$name" "$port_shard" "$any" "$port_shard" >"$tmp/router/models.map"
make_router_certs
write_router_conf "$port_router" "$(free_port)"
shard_flags=(--shard-name shard_m --placement-file "$tmp/router/placement.map")
start_recogd shard_m "127.0.0.1:$port_shard" "${shard_flags[@]}"
start_router
wait_serving "127.0.0.1:$port_router" --tls-ca "$tmp/ca.crt" \
  || fail "health through the router, by name: $(tail -3 "$tmp/nginx/error.log")"

expect_ok "stream into corridor-m through the router" "$recog" stream --map corridor-m --create \
  --images "$images" --json -q "${router[@]}"
grep -q '"frames":4' "$tmp/out" && pass || fail "4 frames answered: $(cat "$tmp/out")"

# The pod restarts with a new address; its name still points to the old one for now.
kill -KILL "$pid_shard_m"
wait "$pid_shard_m" 2>/dev/null
start_recogd shard_m "127.0.0.2:$port_shard" "${shard_flags[@]}"
expect_error "the old address while the name points to it" "UNAVAILABLE" \
  "$recog" maps stats corridor-m --json "${router[@]}"

# until_router PYTHON: maps stats corridor-m through the router until PYTHON holds of `ok` (it
# answered) and `d` (its JSON, or None), 10 s at most; prints the seconds it took.
until_router() {
  local start=$SECONDS code
  for _ in $(seq 50); do
    "$recog" maps stats corridor-m --json "${router[@]}" >"$tmp/out" 2>"$tmp/err"
    code=$?
    /usr/bin/python3 -c "import json; ok = $code == 0; d = json.load(open('$tmp/out')) if ok else None
assert $1" 2>/dev/null && { echo "  took $((SECONDS - start)) s"; return 0; }
    sleep 0.2
  done
  return 1
}
sed -i "s/^$name 127.0.0.1\$/$name 127.0.0.2/" "$tmp/dns.records"
until_router "ok and d['frames'] == 4" && pass \
  || fail "the router reaches the moved shard by its name: $(cat "$tmp/out" "$tmp/err")"
# `any` round-robins over its two addresses: every call gets an answer, from 127.0.0.2.
for i in 1 2 3 4; do
  expect_ok "health through the router for any, call $i" "$recog" admin health "${router[@]}"
done

# A name that does not resolve (the pod is gone): UNAVAILABLE.
: >"$tmp/dns.records"
until_router "not ok" && grep -q "UNAVAILABLE" "$tmp/err" && pass \
  || fail "UNAVAILABLE once the name does not resolve: $(cat "$tmp/out" "$tmp/err")"

report_and_exit

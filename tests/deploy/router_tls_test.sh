#!/usr/bin/env bash
# The router's client side (deploy/nginx/recogd-router.conf): TLS, tokens, health, reflection.
# One recogd with a token file behind nginx with the shipped router configuration and a
# certificate of a throwaway CA. Checks that a client trusting that CA streams through the router
# with its bearer token (which nginx passes on, and the server checks), that plaintext, an
# untrusted certificate and a missing token are refused, that health answers on the TLS port and
# on the plaintext health-only port (which refuses everything else), and that server reflection
# through the router lists the server's very services and describes them (what grpcurl does), for
# a caller with a token only.
# Usage: router_tls_test.sh RECOG RECOGD PROJECT_DIR. Exits 77 (skipped) without nginx.
recog=$1
recogd=$2
project=$3
# shellcheck source=router_test_lib.sh
source "$project/tests/deploy/router_test_lib.sh"
reflect=(/usr/bin/python3 "$project/tests/deploy/reflection_client.py")

images=$project/tests/data/corridor
port_shard=$(free_port); port_router=$(free_port); port_health=$(free_port)
cat >"$tmp/tokens.yaml" <<TOKENS
tokens:
  - name: operator
    token: "router-test-secret-0123456789"
    rights: [read, write]
TOKENS
echo "router-test-secret-0123456789" >"$tmp/token"
echo "corridor-a shard_a;" >"$tmp/router/placement.map"
echo "shard_a 127.0.0.1:$port_shard;" >"$tmp/router/shards.map"
printf 'primary 127.0.0.1:%s;\nany 127.0.0.1:%s;\n' "$port_shard" "$port_shard" >"$tmp/router/models.map"
make_router_certs
make_ca other-ca
write_router_conf "$port_router" "$port_health"
start_recogd shard_a "127.0.0.1:$port_shard" --shard-name shard_a \
  --placement-file "$tmp/router/placement.map" --token-file "$tmp/tokens.yaml"
start_router
wait_serving "127.0.0.1:$port_router" --tls-ca "$tmp/ca.crt" \
  || fail "health through the router's TLS port: $(tail -3 "$tmp/nginx/error.log")"

# TLS and tokens.
expect_ok "stream through the router over TLS with a token" "$recog" stream --map corridor-a \
  --create --images "$images" --json -q --token-file "$tmp/token" "${router[@]}"
grep -q '"frames":4' "$tmp/out" && pass || fail "4 frames answered: $(cat "$tmp/out")"
expect_ok "maps stats over TLS" "$recog" maps stats corridor-a --json --token-file "$tmp/token" \
  "${router[@]}"
json_check "corridor-a has 4 frames" "assert d['frames']==4, d"
expect_error "no token: the server behind the router refuses" "UNAUTHENTICATED" \
  "$recog" maps stats corridor-a "${router[@]}"
expect_error "plaintext to the TLS port" "UNAVAILABLE" \
  "$recog" maps stats corridor-a --token-file "$tmp/token" --server "127.0.0.1:$port_router"
# (GRPC_VERBOSITY: without gRPC's own log line of the failed handshake)
expect_error "a client that trusts another CA" "UNAVAILABLE" env GRPC_VERBOSITY=NONE \
  "$recog" maps stats corridor-a --token-file "$tmp/token" --server "127.0.0.1:$port_router" \
  --tls-ca "$tmp/other-ca.crt"

# Health: on the TLS port (above), and on the plaintext port, which answers nothing else.
expect_ok "health on the plaintext health port" "$recog" admin health \
  --server "127.0.0.1:$port_health"
expect_error "the health port refuses other calls" "UNIMPLEMENTED.*health checks only" \
  "$recog" maps stats corridor-a --token-file "$tmp/token" --server "127.0.0.1:$port_health"

# Reflection through the router: the server's own list, and a service's methods; with tokens on,
# only for a caller with a token.
expect_error "reflection without a token is refused" "CANCELLED" "${reflect[@]}" \
  "127.0.0.1:$port_shard"
expect_ok "reflection at the server" "${reflect[@]}" "127.0.0.1:$port_shard" \
  --token-file "$tmp/token"
cp "$tmp/out" "$tmp/direct.json"
expect_ok "reflection through the router" "${reflect[@]}" "127.0.0.1:$port_router" \
  --tls-ca "$tmp/ca.crt" --token-file "$tmp/token" recognition.v1.PlaceRecognition
json_check "the router's reflection lists the server's services" "
direct = json.load(open('$tmp/direct.json'))['services']
assert d['services'] == direct and 'recognition.v1.PlaceRecognition' in direct \
    and 'grpc.health.v1.Health' in direct, (d, direct)"
json_check "reflection describes PlaceRecognition" \
  "assert {'StreamFrames', 'QueryPlace', 'CreateMap'} <= set(d['methods']['recognition.v1.PlaceRecognition']), d"
# v1 reflection reaches the server too: it answers, or says it does not serve v1 (gRPC 1.51);
# never the router's "not a recogd method".
"${reflect[@]}" "127.0.0.1:$port_router" --tls-ca "$tmp/ca.crt" --token-file "$tmp/token" \
  --version v1 >"$tmp/out" 2>"$tmp/err"
code=$?
if [ "$code" -eq 0 ]; then
  json_check "v1 reflection lists the services" "assert 'grpc.health.v1.Health' in d['services'], d"
else
  grep -q "^UNIMPLEMENTED" "$tmp/err" && ! grep -q "not a recogd method" "$tmp/err" && pass \
    || fail "v1 reflection is passed to the server: $(cat "$tmp/err")"
fi

report_and_exit

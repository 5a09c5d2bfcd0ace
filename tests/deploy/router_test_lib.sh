# shellcheck shell=bash
# Shared by the router tests (sharding_test.sh, router_tls_test.sh, router_dns_test.sh,
# router_config_test.sh); sourced, not run: recogd servers and nginx with the shipped router configuration
# (deploy/nginx/recogd-router.conf) on loopback ports, as the current user, everything (routing
# files, certificates, stores, logs, nginx's pid and temp files) under one temporary folder that
# is removed at exit with every process started here.
#
# The test sets `recog`, `recogd` and `project` (the repository root), then sources this file,
# which sources tools/recog/cli_test_lib.sh (checks, free_port, report_and_exit), makes `tmp`,
# and exits 77 (skipped) when nginx is not installed. Then:
#   make_router_certs            a throwaway CA ($tmp/ca.crt) and the router's certificate for
#                                127.0.0.1 and localhost ($tmp/router-tls/tls.{crt,key})
#   start_recogd NAME LISTEN [ARGS...]   a recogd with its store in $tmp/NAME, serving when it
#                                returns; its pid in pid_NAME
#   write_router_conf TLS_PORT HEALTH_PORT   nginx.conf around the shipped router configuration
#                                (routing files in $tmp/router/, which the test writes, and the
#                                certificate), checked with `nginx -t`; sets `router`, the
#                                recog flags that reach the TLS port: "${router[@]}"
#   start_router                 nginx in the foreground of a background job, as this user
#   wait_serving ADDRESS [RECOG_FLAGS...]   until `recog admin health` answers SERVING (15 s)
set -u
nginx_bin=$(command -v nginx || echo /usr/sbin/nginx)
if [ ! -x "$nginx_bin" ]; then
  echo "SKIP: nginx is not installed (Debian: apt-get install nginx)"
  exit 77
fi
tmp=$(mktemp -d)
pids=()
cleanup() {
  for pid in "${pids[@]}"; do { kill -KILL "$pid" && wait "$pid"; } 2>/dev/null; done
  rm -rf "$tmp"
}
trap cleanup EXIT
# shellcheck source=../../tools/recog/cli_test_lib.sh
source "$project/tools/recog/cli_test_lib.sh"
mkdir -p "$tmp/router" "$tmp/router-tls" "$tmp/nginx"

# make_ca NAME: a self-signed CA, $tmp/NAME.crt and $tmp/NAME.key (EC P-256: fast to make).
make_ca() {
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 2 \
    -subj "/CN=$1" -keyout "$tmp/$1.key" -out "$tmp/$1.crt" 2>"$tmp/openssl.log" \
    || fail "openssl makes the CA $1: $(cat "$tmp/openssl.log")"
}
make_router_certs() {
  make_ca ca
  openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -subj /CN=localhost \
    -keyout "$tmp/router-tls/tls.key" -out "$tmp/router.csr" 2>"$tmp/openssl.log" &&
    openssl x509 -req -in "$tmp/router.csr" -CA "$tmp/ca.crt" -CAkey "$tmp/ca.key" \
      -CAcreateserial -days 2 -out "$tmp/router-tls/tls.crt" \
      -extfile <(printf 'subjectAltName=DNS:localhost,IP:127.0.0.1\n') 2>>"$tmp/openssl.log" \
    || fail "openssl makes the router's certificate: $(cat "$tmp/openssl.log")"
}

wait_serving() {
  local address=$1; shift
  for _ in $(seq 150); do
    "$recog" admin health --server "$address" --timeout-ms 500 "$@" >/dev/null 2>&1 && return 0
    sleep 0.1
  done
  return 1
}

start_recogd() {
  local name=$1 listen=$2; shift 2
  "$recogd" --listen "$listen" --data-dir "$tmp/$name" --metrics-listen "" --workers 2 "$@" \
    >>"$tmp/$name.log" 2>&1 &
  pids+=($!)
  eval "pid_$name=$!"
  wait_serving "$listen" || fail "recogd $name did not come up on $listen: $(tail -3 "$tmp/$name.log")"
}

write_router_conf() {
  router=(--server "127.0.0.1:$1" --tls-ca "$tmp/ca.crt")
  [ -f "$tmp/router/resolver.conf" ] || echo "# no host names here" >"$tmp/router/resolver.conf"
  # The shipped router configuration, with its files and ports moved here.
  sed -e "s|/etc/recogd/router/|$tmp/router/|g" -e "s|/etc/recogd/router-tls/|$tmp/router-tls/|g" \
    -e "s|listen 50050 ssl http2;|listen 127.0.0.1:$1 ssl http2;|" \
    -e "s|listen 50049 http2;|listen 127.0.0.1:$2 http2;|" \
    "$project/deploy/nginx/recogd-router.conf" >"$tmp/router/recogd-router.conf"
  grep -E "/etc/recogd|listen [0-9]+ " "$tmp/router/recogd-router.conf" >"$tmp/unmoved" \
    && fail "the test moves every path and port of the router: left $(cat "$tmp/unmoved")" || pass
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
}

start_router() {
  "$nginx_bin" -p "$tmp/nginx" -c "$tmp/nginx.conf" >"$tmp/nginx/stdout.log" 2>&1 &
  pids+=($!)
}

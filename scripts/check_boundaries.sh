#!/usr/bin/env bash
# Enforces the dependency rules of ARCHITECTURE: core/ never includes gRPC or RocksDB headers
# (nor generated protobuf code), only storage/ includes RocksDB, and in server/ only the api/
# converters and the services (the RPC handlers) see generated protobuf types; the server's
# infrastructure (config, auth, metrics, runtime) does not; the client library (client/) sees the
# generated API only, never core/, storage/ or server/ (its tests may, to start a server); core's
# modules include only the layers below them (no cycles). The RPC handlers and converters stay
# thin: they never reach into a place map's lock, deleted flag or loop detector (PlaceMap's
# Add/Detect/Query own that).
set -euo pipefail
cd "$(dirname "$0")/.."
status=0
if git grep -n -E '#include\s*[<"](grpcpp?/|rocksdb/|google/protobuf/)|\.pb\.h|#include\s*"wire/' -- 'core/' ; then
  echo "check_boundaries: core/ must not include gRPC, RocksDB, protobuf or wire/ headers" >&2
  status=1
fi
if git grep -n -E '#include\s*[<"]rocksdb/' -- ':!storage/' ':!*.md' ; then
  echo "check_boundaries: only storage/ may include RocksDB headers" >&2
  status=1
fi
if git grep -n -E '\.pb\.h' -- 'server/config/' 'server/auth/' 'server/metrics/' 'server/runtime/'; then
  echo "check_boundaries: server/config, auth, metrics and runtime must not see protobuf types" >&2
  status=1
fi
if git grep -n -E '#include\s*"(core|storage|server|tools|tests)/' -- 'client/' ':!*_test.cc' \
    ':!*_test_fixture.h'; then
  echo "check_boundaries: the client library must not include core/, storage/ or server/ headers" >&2
  status=1
fi
# core's modules form layers, each including only the ones below it (tests may include anything):
# common < bow < vocabulary, geometry < features, index < place, object.
declare -A core_layer_deps=(
  [common]=""
  [bow]="common"
  [vocabulary]="common bow"
  [geometry]="common bow"
  [features]="common bow vocabulary"
  [index]="common bow vocabulary"
  [place]="common bow vocabulary geometry features index"
  [object]="common bow vocabulary geometry features index"
)
for dir in core/*/; do
  module=$(basename "$dir")
  if [ -z "${core_layer_deps[$module]+set}" ]; then
    echo "check_boundaries: core/$module/ has no place in the layer list of this script" >&2
    status=1
    continue
  fi
  allowed="$module ${core_layer_deps[$module]}"
  while IFS=: read -r file line include; do
    used=$(sed -E 's#.*"core/([a-z_]+)/.*#\1#' <<<"$include")
    if ! grep -qw -- "$used" <<<"$allowed"; then
      echo "$file:$line: core/$module/ may not include core/$used/ (allowed: $allowed)" >&2
      status=1
    fi
  done < <(git grep -n -E '#include\s*"core/' -- "core/$module/" ':!*_test.cc')
done
if git grep -n -E '(\.|->)(mutex|deleted|detector)\b' -- 'server/services/' 'server/api/'; then
  echo "check_boundaries: server/services and server/api must not take a map's lock, read its" \
    "deleted flag or drive its detector: call PlaceMap instead" >&2
  status=1
fi
[ $status -eq 0 ] && echo "check_boundaries: ok"
exit $status

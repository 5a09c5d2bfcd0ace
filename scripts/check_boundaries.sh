#!/usr/bin/env bash
# Enforces the dependency rules that docs/index.md ("Layout") states: core/ never includes gRPC or
# RocksDB headers (nor generated protobuf code), only storage/ includes RocksDB, and in server/
# only the api/ converters, the services (the RPC handlers) and the web console (an adapter of the
# same services) see generated protobuf types; the server's infrastructure (config, auth, http,
# metrics, runtime) does not; the client library (client/) sees the generated API only, never
# core/, storage/ or server/ (its tests may, to start a server); core's modules include only the
# layers below them (no cycles); wire/ (what both ends of the API implement) sees only the
# generated API; tools/ never sees the server, its folders are layers too (bag, common <
# evaluation < load < recog) and only `recog` opens a store offline; nothing but bench/ includes
# bench/; and the web console's pages import only its leaf modules, never each other
# (docs/console.md, the paragraph on server/console/web/). The RPC handlers and converters stay thin, and so
# does the console: they never reach into a place map's lock, deleted flag or loop detector
# (PlaceMap's Add/Detect/Query own that).
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
if git grep -n -E '\.pb\.h' -- 'server/config/' 'server/auth/' 'server/http/' 'server/metrics/' \
    'server/runtime/'; then
  echo "check_boundaries: server/config, auth, http, metrics and runtime must not see protobuf types" >&2
  status=1
fi
if git grep -n -E '#include\s*"(core|storage|server|tools|tests)/' -- 'client/' ':!*_test.cc' \
    ':!*_test_fixture.h'; then
  echo "check_boundaries: the client library must not include core/, storage/ or server/ headers" >&2
  status=1
fi
# check_includes DIR PREFIX FOLDERS ALLOWED: the product files of DIR (not its tests nor test
# helpers) include, of the folders PREFIX<f>/ for f in FOLDERS (an extended regex), only those
# whose f is in ALLOWED.
check_includes() {
  local dir=$1 prefix=$2 folders=$3 allowed=$4 file line include used
  while IFS=: read -r file line include; do
    used=$(sed -E "s#.*\"$prefix([a-z_0-9]+)/.*#\\1#" <<<"$include")
    if ! grep -qw -- "$used" <<<"$allowed"; then
      echo "$file:$line: $dir/ may not include $prefix$used/ (allowed: $allowed)" >&2
      status=1
    fi
  done < <(git grep -n -E "#include\s*\"$prefix($folders)/" -- "$dir/" ':!*_test.cc' ':!*test*.h')
}
# check_layers ROOT DEPS: every folder ROOT/<m>/ includes from ROOT/ only <m> itself and the
# folders DEPS (the name of an associative array: folder -> allowed folders) lists for it; tests
# may include anything. A folder missing from DEPS is an error too.
check_layers() {
  local root=$1
  local -n deps=$2
  local dir module
  for dir in "$root"/*/; do
    module=$(basename "$dir")
    if [ -z "${deps[$module]+set}" ]; then
      echo "check_boundaries: $root/$module/ has no place in the layer list of this script" >&2
      status=1
      continue
    fi
    check_includes "$root/$module" "$root/" "[a-z_]+" "$module ${deps[$module]}"
  done
}
# core's modules form layers, each including only the ones below it:
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
check_layers core core_layer_deps
# core/object/ is layered the same way, one folder a concern: the model, its file formats, the
# builders, recognition, the versioned repository, tracking and learning.
declare -A object_layer_deps=(
  [model]=""
  [formats]="model"
  [builder]="model formats"
  [recognition]="model formats"
  [repository]="model formats recognition"
  [tracking]="model formats builder recognition"
)
check_layers core/object object_layer_deps
if [ -n "$(git ls-files 'core/object/*.h' 'core/object/*.cc' | grep -v '^core/object/[a-z_]*/')" ]; then
  echo "check_boundaries: core/object/ keeps its files in its concern folders" >&2
  status=1
fi
# check_roots DIR ALLOWED: of the repository's top folders and the generated API (recognition/,
# grpc/), DIR's product files include only those ALLOWED.
check_roots() {
  check_includes "$1" "" "core|storage|server|tools|client|wire|tests|bench|recognition|grpc" "$2"
}
check_roots wire "wire recognition"
check_roots tools/bag "tools core"
check_roots tools/common "tools core client wire"
check_roots tools/evaluation "tools core"
check_roots tools/load "tools core client wire recognition"
check_roots tools/recog "tools core client wire recognition storage"
for dir in core storage server client tools wire; do
  if git grep -n -E '#include\s*"bench/' -- "$dir/"; then
    echo "check_boundaries: only bench/ includes bench/ headers" >&2
    status=1
  fi
done
# tools' folders are layers: bag and common at the bottom, then evaluation, load, recog.
declare -A tools_layer_deps=(
  [bag]=""
  [common]=""
  [evaluation]="common bag"
  [load]="common evaluation"
  [recog]="common evaluation load bag"
)
check_layers tools tools_layer_deps
# The web console's modules (server/console/web): the pages import only the leaves (the API
# client, the DOM and format helpers, the line charts and the inlier pairs) and three.js, and a
# leaf imports only other leaves. main.js loads the pages by dynamic import() (not checked here).
console_leaves="api dom format linechart pairs"
for module in server/console/web/*.js; do
  while IFS= read -r imported; do
    case "$imported" in
      three | three/*) continue ;;
    esac
    imported=$(basename "$imported" .js)
    if ! grep -qw -- "$imported" <<<"$console_leaves"; then
      echo "$module: imports $imported, which is not a leaf module (leaves: $console_leaves)" >&2
      status=1
    fi
  done < <(sed -n -E "s#^import .* from '([^']+)';#\1#p" "$module")
done
if git grep -n -E '(\.|->)(mutex|deleted|detector)\b' -- 'server/services/' 'server/api/' 'server/console/'; then
  echo "check_boundaries: server/services and server/api must not take a map's lock, read its" \
    "deleted flag or drive its detector: call PlaceMap instead" >&2
  status=1
fi
[ $status -eq 0 ] && echo "check_boundaries: ok"
exit $status

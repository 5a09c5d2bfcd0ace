#!/usr/bin/env bash
# Enforces the dependency rules of ARCHITECTURE: core/ never includes gRPC or RocksDB headers
# (nor generated protobuf code), and only storage/ includes RocksDB.
set -euo pipefail
cd "$(dirname "$0")/.."
status=0
if git grep -n -E '#include\s*[<"](grpcpp?/|rocksdb/|google/protobuf/)|\.pb\.h' -- 'core/' ; then
  echo "check_boundaries: core/ must not include gRPC, RocksDB or protobuf headers" >&2
  status=1
fi
if git grep -n -E '#include\s*[<"]rocksdb/' -- ':!storage/' ':!*.md' ; then
  echo "check_boundaries: only storage/ may include RocksDB headers" >&2
  status=1
fi
[ $status -eq 0 ] && echo "check_boundaries: ok"
exit $status

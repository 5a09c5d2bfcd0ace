#!/usr/bin/env bash
# The installed package, used as another project would: `cmake --install` of the build into a
# fresh prefix; its layout (binaries, vocabularies, headers at the paths the sources include them
# by, the CMake package, nothing of the tests); deploy/systemd/install.sh --root; the example consumer (examples/cpp_consumer, copied
# out of the source tree) configured with CMAKE_PREFIX_PATH=<prefix> only, checked to find the
# package and headers there and nowhere in the source or build tree, and built; the installed
# recogd started on a free port with the installed vocabularies; the consumer streams
# tests/data/corridor into it and must get an answer for every frame, and, into a map that does not
# leave recent frames out, the same loops as `recog stream` reports for the same frames; the
# consumer pointed at a closed port must fail.
# Usage: install_test.sh BUILD_DIR PROJECT_DIR CMAKE CXX_COMPILER [LAUNCHER] [FLAGS]
# (LAUNCHER: ccache or empty; FLAGS: the sanitizer flags of the build, for the consumer too).
set -u
build=$(realpath "$1")
project=$(realpath "$2")
cmake=$3
cxx=$4
launcher=${5:-}
flags=${6:-}
# A fixed folder in the build tree, so that a repeated run compiles the consumer from ccache.
work=$build/install_test
rm -rf "$work"
mkdir -p "$work"
tmp=$work  # cli_test_lib.sh writes each command's output to $tmp/out and $tmp/err
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill -KILL "$pid" 2>/dev/null; done
  [ "$failures" -eq 0 ] && rm -rf "$work"  # kept for a look when a check failed
}
trap cleanup EXIT
# shellcheck source=../../tools/recog/cli_test_lib.sh
source "$project/tools/recog/cli_test_lib.sh"
prefix=$work/prefix
images=$project/tests/data/corridor

expect_ok "cmake --install" "$cmake" --install "$build" --prefix "$prefix"
[ "$failures" -eq 0 ] || report_and_exit
for file in bin/recog bin/recogd lib/recog/librecog_video.so \
  share/recog/vocabularies/place_orb_k10_l5.rvoc \
  share/recog/vocabularies/object_orb_t12_k10_l4.rvoc lib/cmake/recog/recogConfig.cmake \
  lib/cmake/recog/recogConfigVersion.cmake include/recog/client/cpp/frame_stream.h \
  include/recog/recognition/v1/place.grpc.pb.h include/recog/grpc/health/v1/health.pb.h \
  include/recog/core/place/loop_detector.h include/recog/storage/rocksdb_index_store.h; do
  [ -s "$prefix/$file" ] && pass || fail "installed: $file"
done
leftovers=$(find "$prefix" -name '*_test*' -o -name '*fixture*' -o -name 'bench_*')
[ -z "$leftovers" ] && pass || fail "nothing of the tests or benchmarks is installed: $leftovers"
leaks=$(grep -rlF -e "$project" -e "$build" "$prefix/lib/cmake")
[ -z "$leaks" ] && pass || fail "the package names no path of the source or build tree: $leaks"

# deploy/systemd/install.sh stages the runtime component (binaries, vocabularies) with the rest.
expect_ok "install.sh --root" env RECOG_BUILD_DIR="$build" bash "$project/deploy/systemd/install.sh" \
  --root "$work/root"
for file in usr/local/bin/recogd usr/local/bin/recog \
  usr/local/share/recog/vocabularies/place_orb_k10_l5.rvoc etc/recogd/recogd.yaml \
  etc/systemd/system/recogd.service etc/sysusers.d/recogd.conf; do
  [ -s "$work/root/$file" ] && pass || fail "install.sh --root staged $file"
done
staged_libraries=$(cd "$work/root/usr/local" && find lib -type f 2>/dev/null)
[ ! -e "$work/root/usr/local/include" ] && [ "$staged_libraries" = lib/recog/librecog_video.so ] \
  && pass || fail "install.sh installs no headers and no library but recog's video module: $staged_libraries"
# Installed and staged, recog finds its video module (a file that is no video is then refused
# as such, not for a missing module).
echo "not a video" >"$work/garbage.avi"
for installed_recog in "$prefix/bin/recog" "$work/root/usr/local/bin/recog"; do
  expect_error "$installed_recog loads its video module" "neither a folder, an image list nor a video" \
    "$installed_recog" eval place --images "$work/garbage.avi" -q
done

# The consumer, out of the source tree, against the prefix alone.
mkdir -p "$work/consumer"
cp "$project/examples/cpp_consumer/CMakeLists.txt" "$project/examples/cpp_consumer/main.cc" \
  "$work/consumer/"
expect_ok "the consumer configures against the prefix" "$cmake" -S "$work/consumer" \
  -B "$work/consumer-build" -G Ninja -DCMAKE_PREFIX_PATH="$prefix" \
  -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF -DCMAKE_CXX_COMPILER="$cxx" \
  -DCMAKE_CXX_COMPILER_LAUNCHER="$launcher" -DCMAKE_CXX_FLAGS="$flags" \
  -DCMAKE_EXE_LINKER_FLAGS="$flags"
[ "$failures" -eq 0 ] || report_and_exit
grep -qx "recog_DIR:PATH=$prefix/lib/cmake/recog" "$work/consumer-build/CMakeCache.txt" && pass \
  || fail "find_package(recog) took the prefix's: $(grep '^recog_DIR' "$work/consumer-build/CMakeCache.txt")"
# Every include folder of the consumer's compile is the prefix's or the system's.
foreign=$(grep -oE -- '-(I|isystem )[^ ]+' "$work/consumer-build/build.ninja" | sed -E 's/^-(I|isystem )//' \
  | sort -u | grep -v -e "^$prefix/" -e '^/usr/')
[ -z "$foreign" ] && pass || fail "the consumer includes only the prefix and the system: $foreign"
if "$cmake" --build "$work/consumer-build" >"$tmp/out" 2>&1; then
  pass
else
  fail "the consumer builds: $(grep -m5 -e 'error' -e 'undefined' "$tmp/out")"
  report_and_exit
fi
consumer=$work/consumer-build/stream_folder

# The installed recogd, with the installed vocabularies.
port=$(free_port)
RECOG_VOCABULARY_DIR=$prefix/share/recog/vocabularies "$prefix/bin/recogd" \
  --listen "127.0.0.1:$port" --data-dir "$work/data" --metrics-listen "" --workers 2 \
  >"$work/recogd.log" 2>&1 &
pids+=($!)
disown
serving=false
for _ in $(seq 300); do
  "$prefix/bin/recog" admin health --server "127.0.0.1:$port" --timeout-ms 500 >/dev/null 2>&1 \
    && { serving=true; break; }
  sleep 0.1
done
$serving && pass || { fail "recogd did not come up: $(tail -3 "$work/recogd.log")"; report_and_exit; }

frames=$(find "$images" -maxdepth 1 -name '*.jpg' | wc -l)
expect_ok "the consumer streams the corridor" "$consumer" "127.0.0.1:$port" "$images" corridor
cp "$tmp/out" "$work/consumer.out"
tail -1 "$work/consumer.out" | grep -Eq "^streamed $frames frames, $frames answered, [0-9]+ loops\$" \
  && pass || fail "every frame streamed and answered: $(tail -1 "$work/consumer.out")"
expect_ok "the map holds every frame" "$prefix/bin/recog" maps stats corridor --json \
  --server "127.0.0.1:$port"
json_check "corridor has $frames frames" "assert d['frames']==$frames, d"

# Loops: the corridor's four photos close two loops once recent frames are not left out. Into two
# maps created alike, the consumer and `recog stream` must report the same loops.
for map in loops loops-cli; do
  expect_ok "maps create $map" "$prefix/bin/recog" maps create "$map" --recent-frames 0 \
    --temporal-matches 1 --server "127.0.0.1:$port"
done
expect_ok "the consumer streams into a map of loops" "$consumer" "127.0.0.1:$port" "$images" loops
grep '^loop: ' "$tmp/out" >"$work/consumer.loops"
expect_ok "recog stream" "$prefix/bin/recog" stream --map loops-cli --images "$images" --json -q \
  --server "127.0.0.1:$port"
/usr/bin/python3 -c '
import json, sys
for line in open(sys.argv[1]):
    d = json.loads(line)
    if d["event"] == "loop":
        print("loop: %s -> %s (%d inliers)" % (d["frame_file"], d["match_file"], d["inliers"]))
' "$tmp/out" >"$work/recog.loops"
[ -s "$work/recog.loops" ] && pass || fail "recog stream finds loops in the corridor: $(cat "$tmp/out")"
cmp -s "$work/consumer.loops" "$work/recog.loops" && pass \
  || fail "the consumer's loops equal recog stream's: $(diff "$work/consumer.loops" "$work/recog.loops")"
echo "consumer, default settings: $(tail -1 "$work/consumer.out")"
echo "consumer, recent frames not left out: $(tr '\n' ';' <"$work/consumer.loops")"

# A server that is not there: the consumer fails, saying so.
closed=$(free_port)
"$consumer" "127.0.0.1:$closed" "$images" >"$tmp/out" 2>"$tmp/err"
code=$?
[ "$code" -eq 1 ] && grep -q "stream_folder: " "$tmp/err" && pass \
  || fail "the consumer fails without a server: exit $code, $(cat "$tmp/err")"

report_and_exit

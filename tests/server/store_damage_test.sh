#!/usr/bin/env bash
# Issue 24's experiment against a real recogd: two maps streamed in, recogd killed (the frames are
# in the store's write-ahead log; a clean stop would write them out to table files), one byte of
# the log flipped among m1's frames.
# Expected: recogd refuses to start (exit 1, one line naming the log file and the damaged bytes)
# and changes nothing; with --recover point-in-time it starts, keeps a copy of the damaged files,
# logs m1's missing frame ids and m2 lost whole, counts them in recog_store_recovery_lost, and
# serves the consistent prefix; the store then starts again without --recover. Then a byte
# flipped in a table file under the running recogd is found by the background check, by
# `recog admin verify`, by `recog admin checkpoint` (the copy is checked when taken) and by
# `recogd --verify`.
# Usage: store_damage_test.sh RECOG RECOGD PROJECT_DIR
set -u
recog=$1
recogd=$2
project=$3
tmp=$(mktemp -d)
server_pid=
cleanup() {
  [ -n "$server_pid" ] && kill -KILL "$server_pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
# shellcheck source=../../tools/recog/cli_test_lib.sh
source "$project/tools/recog/cli_test_lib.sh"

images=$project/tests/data/corridor
port=$(free_port)
metrics_port=$(free_port)
server=(--server "127.0.0.1:$port")

# start_recogd ARGS...: recogd on the test's data directory, in the background, until it serves
# (true) or exits (false; its status in $exit_status).
start_recogd() {
  "$recogd" --listen "127.0.0.1:$port" --data-dir "$tmp/data" --workers 2 \
    --metrics-listen "127.0.0.1:$metrics_port" "$@" >"$tmp/recogd.log" 2>&1 &
  server_pid=$!
  for _ in $(seq 300); do
    "$recog" admin health "${server[@]}" --timeout-ms 500 >/dev/null 2>&1 && return 0
    if ! kill -0 "$server_pid" 2>/dev/null; then
      wait "$server_pid"
      exit_status=$?
      server_pid=
      return 1
    fi
    sleep 0.1
  done
  return 1
}
stop_recogd() {
  kill -TERM "$server_pid" && wait "$server_pid"
  server_pid=
}
kill_recogd() {
  kill -KILL "$server_pid" && wait "$server_pid" 2>/dev/null
  server_pid=
}

start_recogd || { echo "FAIL: recogd did not start: $(cat "$tmp/recogd.log")"; exit 1; }
for map in m1 m2; do
  expect_ok "create $map" "$recog" maps create "$map" "${server[@]}"
  for _ in 1 2 3; do
    expect_ok "stream into $map" "$recog" stream --map "$map" --images "$images" -q "${server[@]}"
  done
done
kill_recogd

log=$(ls "$tmp"/data/store/*.log | head -1)
python3 - "$log" <<'PY'
import os, sys
path = sys.argv[1]
with open(path, "r+b") as f:
    at = os.path.getsize(path) // 4  # among m1's frames
    f.seek(at); b = f.read(1); f.seek(at); f.write(bytes([b[0] ^ 0x10]))
PY
cp "$log" "$tmp/damaged.log"

# Refused, naming the file and the damage; nothing changed.
if start_recogd; then
  fail "recogd started on a damaged log"
  stop_recogd
else
  [ "$exit_status" -eq 1 ] && pass || fail "a damaged log: exit $exit_status, expected 1"
  grep -q "DATA_LOSS.*$(basename "$log"): dropping [0-9]* bytes.*--recover point-in-time" \
    "$tmp/recogd.log" && pass || fail "the refusal names the log file and the damage: $(tail -2 "$tmp/recogd.log")"
  cmp -s "$log" "$tmp/damaged.log" && pass || fail "the refused start changed the log"
  ls -d "$tmp"/data/store.damaged-* >/dev/null 2>&1 && fail "a refused start copied files" || pass
fi

# Point-in-time recovery: starts, reports the loss, keeps the damaged files.
start_recogd --recover point-in-time || fail "recogd --recover point-in-time: $(tail -3 "$tmp/recogd.log")"
grep -q "map 'm1': [0-9]* -> [0-9]* entries, missing ids [0-9,]*11$" "$tmp/recogd.log" && pass \
  || fail "the log lists m1's missing frames: $(grep "map '" "$tmp/recogd.log")"
grep -q "map 'm2' lost whole: 12 -> 0 entries" "$tmp/recogd.log" && pass \
  || fail "the log says m2 is lost: $(grep "map '" "$tmp/recogd.log")"
copy=$(ls -d "$tmp"/data/store.damaged-* 2>/dev/null | head -1)
[ -n "$copy" ] && cmp -s "$copy/$(basename "$log")" "$tmp/damaged.log" && pass \
  || fail "the damaged log is kept in data/store.damaged-*: $(ls "$tmp/data")"
expect_ok "maps list after the recovery" "$recog" maps list --json "${server[@]}"
json_check "only m1 is left, with fewer than 12 frames" \
  "assert [m['name'] for m in d]==['m1'] and 0 < d[0]['frames'] < 12, d"
python3 - "$metrics_port" >"$tmp/metrics" 2>&1 <<'PY'
import sys, urllib.request
print(urllib.request.urlopen(f"http://127.0.0.1:{sys.argv[1]}/metrics", timeout=5).read().decode())
PY
grep -q '^recog_store_recovery_lost{kind="maps"} 1$' "$tmp/metrics" && pass \
  || fail "recog_store_recovery_lost counts m2: $(grep recovery_lost "$tmp/metrics")"
# The same report from `recog admin status`, for operators without the log at hand.
expect_ok "admin status after the recovery" "$recog" admin status --json "${server[@]}"
json_check "admin status reports m1's missing frames, m2 lost, the copy and no check yet" "
r = d['recovery']; maps = {m['name']: m for m in r['maps']}
assert d['recovered'] and r['damaged_copy'].startswith('$tmp/data/store.damaged-'), d
m1 = maps['m1']  # frames_before: those whose records are readable (not in the damaged bytes)
assert m1['frames_before'] <= 12 and 0 < m1['frames_after'] < m1['frames_before'], d
assert len(m1['missing_frame_ids']) == m1['frames_before'] - m1['frames_after'], d
assert maps['m2']['map_lost'] and maps['m2']['frames_after'] == 0, d
assert 'last_check' not in d and r['damage'][0].startswith('$log: dropping'), d"
expect_ok "admin status in text" "$recog" admin status "${server[@]}"
grep -q "^  map 'm2' lost whole: 12 -> 0 entries" "$tmp/out" && pass \
  || fail "admin status says m2 is lost: $(cat "$tmp/out")"
stop_recogd

# The recovered store is whole: it starts without --recover, and its files check out, online
# and offline.
start_recogd && pass || fail "the recovered store does not start again: $(tail -2 "$tmp/recogd.log")"
expect_ok "admin verify of the recovered store" "$recog" admin verify --json "${server[@]}"
json_check "admin verify read table files" "assert d['files'] >= 1 and d['bytes'] > 0, d"
expect_ok "admin status after a check" "$recog" admin status --json "${server[@]}"
json_check "admin status: opened whole, checked without damage" \
  "assert not d['recovered'] and d['last_check']['error'] == '' and d['last_check']['files'] >= 1, d"
[ -n "$server_pid" ] && stop_recogd
expect_ok "recogd --verify of the recovered store" "$recogd" --verify --data-dir "$tmp/data"
grep -q "no damage" "$tmp/out" && pass || fail "recogd --verify: $(cat "$tmp/out")"

# A byte flipped in a table file while recogd runs is found by the background check (every
# second here): the metric, the log naming the file, `recog admin verify` and, offline,
# `recogd --verify` all say so.
printf 'store:\n  verify_interval_s: 1\n' >"$tmp/recogd.yaml"
start_recogd --config "$tmp/recogd.yaml" || fail "recogd with a 1 s check: $(tail -2 "$tmp/recogd.log")"
table=$(ls -S "$tmp"/data/store/*.sst | head -1)
python3 - "$table" <<'PY'
import os, sys
path = sys.argv[1]
with open(path, "r+b") as f:
    at = os.path.getsize(path) // 2
    f.seek(at); b = f.read(1); f.seek(at); f.write(bytes([b[0] ^ 0x10]))
PY
found=
for _ in $(seq 50); do
  python3 - "$metrics_port" >"$tmp/metrics" 2>/dev/null <<'PY'
import sys, urllib.request
print(urllib.request.urlopen(f"http://127.0.0.1:{sys.argv[1]}/metrics", timeout=5).read().decode())
PY
  grep -q '^recog_store_damaged 1$' "$tmp/metrics" && found=1 && break
  sleep 0.1
done
[ -n "$found" ] && pass || fail "the background check did not report the damage within 5 s"
grep -q "store check failed: DATA_LOSS.*$(basename "$table") is damaged" "$tmp/recogd.log" && pass \
  || fail "the log names the damaged file: $(grep -i "check" "$tmp/recogd.log" | tail -2)"
expect_error "admin verify of a damaged store" "DATA_LOSS" "$recog" admin verify "${server[@]}"
"$recog" admin status "${server[@]}" >"$tmp/out" 2>"$tmp/err"
code=$?
[ "$code" -eq 1 ] && grep -q "^last check .*DATA_LOSS.*$(basename "$table") is damaged" "$tmp/out" \
  && pass || fail "admin status after damage was found: exit $code: $(cat "$tmp/out" "$tmp/err")"
# A backup taken now is read back when taken, and refused: the damage came with the copy.
expect_error "admin checkpoint of a damaged store" "DATA_LOSS.*$(basename "$table") is damaged" \
  "$recog" admin checkpoint --to "$tmp/backup" -q "${server[@]}"
stop_recogd
"$recogd" --verify --data-dir "$tmp/data" >"$tmp/out" 2>"$tmp/err"
code=$?
[ "$code" -eq 1 ] && grep -q "DATA_LOSS.*$(basename "$table") is damaged" "$tmp/err" && pass \
  || fail "recogd --verify of a damaged store: exit $code: $(cat "$tmp/err")"

report_and_exit

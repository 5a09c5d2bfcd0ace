# Checks shared by the shell tests of the recog binary (recog_cli_test.sh,
# recog_server_cli_test.sh); sourced, not run. The test sets `tmp` (a scratch folder) first; each
# check writes the command's stdout to $tmp/out and its stderr to $tmp/err, and counts itself in
# `checks` and, when it fails, in `failures`. report_and_exit prints the counts and exits 1 when a
# check failed.
failures=0
checks=0

pass() { checks=$((checks + 1)); }
fail() { checks=$((checks + 1)); failures=$((failures + 1)); echo "FAIL: $*"; }
# skip_shared WHAT: a part of the test whose shared data is missing is skipped, saying so; with
# RECOG_REQUIRE_SHARED_DATA=1 (CI, with the shared data beside the clone) it fails instead.
skip_shared() {
  if [ "${RECOG_REQUIRE_SHARED_DATA:-}" = 1 ]; then
    fail "$* (RECOG_REQUIRE_SHARED_DATA=1)"
  else
    echo "skipping $*"
  fi
}

# expect_ok DESCRIPTION CMD...: the command exits 0.
expect_ok() {
  local what=$1; shift
  if "$@" >"$tmp/out" 2>"$tmp/err"; then pass; else fail "$what (exit $?): $(cat "$tmp/err")"; fi
}
# expect_error DESCRIPTION PATTERN CMD...: refused by the command itself: exit status 1 and
# exactly one stderr line, matching PATTERN.
expect_error() {
  local what=$1 pattern=$2; shift 2
  "$@" >"$tmp/out" 2>"$tmp/err"
  local code=$?
  if [ "$code" -ne 1 ]; then fail "$what: exit $code, expected 1: $(tail -c 2000 "$tmp/err")"; return; fi
  one_error_line "$what" "$pattern"
}
# expect_usage_error DESCRIPTION PATTERN CMD...: refused by the command line parser (unknown
# subcommand or flag, missing or bad value): exit status 2 and exactly one stderr line, matching
# PATTERN.
expect_usage_error() {
  local what=$1 pattern=$2; shift 2
  "$@" >"$tmp/out" 2>"$tmp/err"
  local code=$?
  if [ "$code" -ne 2 ]; then fail "$what: exit $code, expected 2: $(tail -c 2000 "$tmp/err")"; return; fi
  one_error_line "$what" "$pattern"
}
# expect_version DESCRIPTION NAME CMD...: exit status 0 and one stdout line
# "NAME <major.minor.patch> (<commit>, <build type>)".
expect_version() {
  local what=$1 name=$2; shift 2
  if ! "$@" >"$tmp/out" 2>"$tmp/err"; then fail "$what: exit $?"; return; fi
  if [ "$(wc -l <"$tmp/out")" -eq 1 ] && grep -Eq "^$name [0-9]+\.[0-9]+\.[0-9]+ \([^,]+, [^)]+\)\$" "$tmp/out"; then
    pass
  else
    fail "$what: '$(cat "$tmp/out")'"
  fi
}
one_error_line() {
  local what=$1 pattern=$2
  local lines; lines=$(wc -l <"$tmp/err")
  if [ "$lines" -ne 1 ]; then fail "$what: expected one error line, got $lines: $(cat "$tmp/err")"; return; fi
  if grep -q -- "$pattern" "$tmp/err"; then pass; else fail "$what: '$(cat "$tmp/err")' lacks '$pattern'"; fi
}
# json_check DESCRIPTION PYTHON: runs PYTHON with `d`, the JSON document in $tmp/out.
json_check() {
  /usr/bin/python3 -c "import json; d=json.load(open('$tmp/out')); $2" && pass || fail "$1"
}

# free_port: a free loopback TCP port (bound, read, released: another process may take it, rarely).
free_port() {
  /usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'
}

report_and_exit() {
  echo "$((checks - failures)) passed, $failures failed"
  [ "$failures" -eq 0 ]
  exit
}

# wait_for_recogd PID: waits up to 10 s for the recogd of process PID to answer
# `recog maps list "${server[@]}"` (the test sets `recog` and `server`); 1 when it never does.
wait_for_recogd() {
  for _ in $(seq 100); do
    "$recog" maps list "${server[@]}" >/dev/null 2>&1 && return 0
    kill -0 "$1" 2>/dev/null || return 1
    sleep 0.1
  done
  "$recog" maps list "${server[@]}" >/dev/null 2>&1
}

# photo_tiles SRC DST: every JPEG of SRC cut into 3x3 grey tiles DST/<name>_<0..8>.png, enough
# photos for `recog seqgen rig` from the 4 bundled corridor frames.
photo_tiles() {
  mkdir -p "$2"
  /usr/bin/python3 - "$1" "$2" <<'PYTHON'
import glob, os, sys
import cv2
source, target = sys.argv[1], sys.argv[2]
for path in sorted(glob.glob(os.path.join(source, "*.jpg"))):
    photo = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    h, w = photo.shape[0] // 3, photo.shape[1] // 3
    name = os.path.splitext(os.path.basename(path))[0]
    for q in range(9):
        tile = photo[(q // 3) * h:(q // 3 + 1) * h, (q % 3) * w:(q % 3 + 1) * w]
        cv2.imwrite(os.path.join(target, f"{name}_{q}.png"), tile)
PYTHON
}

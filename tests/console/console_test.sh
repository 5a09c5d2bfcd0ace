#!/usr/bin/env bash
# The acceptance of the web console, end to end: a real recogd with `console.listen` and tokens,
# the shared corridor streamed into a map that keeps thumbnails (`recog stream --keep-thumbnails`),
# two RoboEarth models pushed (lion, and cabinet_small, which the real lab photo
# scenes/lab1-rect.png shows), then console_browser_test.py in headless Chromium with a read-only
# token: the map and its loops with inlier lines, the lion's 3D points, the photo recognised, a
# corridor photo found in the map, the live charts, and the corridor's precision-recall curve
# (`recog eval place --plot`) on the Charts page. Screenshots go to $RECOG_CONSOLE_SCREENSHOTS (default: a temporary folder).
# The shared data: $RECOG_SHARED_DATA, default ../shared/data next to the project (PROJECT_DIR).
# Skips (77) when it has no corridor or RoboEarth data, or without Chromium, chromedriver and
# Selenium.
# Usage: console_test.sh RECOG_BINARY RECOGD_BINARY PROJECT_DIR
set -u
recog=$1
recogd=$2
project=$3
data=${RECOG_SHARED_DATA:-$project/../shared/data}
if [ ! -d "$data/places/corridor" ] || [ ! -d "$data/objects/roboearth" ]; then
  echo "skip: the corridor or RoboEarth data is not under $data (set RECOG_SHARED_DATA)"
  [ "${RECOG_REQUIRE_SHARED_DATA:-}" = 1 ] && { echo "FAIL: RECOG_REQUIRE_SHARED_DATA=1"; exit 1; }
  exit 77
fi
for tool in /usr/bin/chromium /usr/bin/chromedriver; do
  [ -x "$tool" ] || { echo "skip: $tool is missing"; exit 77; }
done
tmp=$(mktemp -d)
server_pid=
cleanup() {
  [ -n "$server_pid" ] && kill -KILL "$server_pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
# shellcheck source=../../tools/recog/cli_test_lib.sh
source "$project/tools/recog/cli_test_lib.sh"

writer=writer-token-0123456789
reader=reader-token-0123456789
cat >"$tmp/tokens.yaml" <<TOKENS
tokens:
  - name: robot
    token: $writer
    rights: [write]
  - name: visitor
    token: $reader
    rights: [read]
TOKENS
echo "$writer" >"$tmp/writer.token"
# A chart for the Charts page: the corridor's precision-recall curve, as `recog eval place` draws it.
mkdir -p "$tmp/charts"
expect_ok "eval place --sweep alpha --plot" "$recog" eval place --images "$data/places/corridor/images" \
  --ground-truth "$data/places/corridor/ground_truth.txt" --sweep alpha \
  --plot "$tmp/charts/corridor_pr.png"
[ -s "$tmp/charts/corridor_pr.json" ] && pass || fail "the plot's chart was not written beside it"
port=$(free_port)
console_port=$(free_port)
server=(--server "127.0.0.1:$port" --token-file "$tmp/writer.token")
"$recogd" --listen "127.0.0.1:$port" --data-dir "$tmp/data" --metrics-listen "" --workers 2 \
  --token-file "$tmp/tokens.yaml" --console-listen "127.0.0.1:$console_port" \
  --console-charts-dir "$tmp/charts" \
  >"$tmp/recogd.log" 2>&1 &
server_pid=$!
if ! wait_for_recogd "$server_pid"; then
  echo "FAIL: recogd did not start: $(cat "$tmp/recogd.log")"
  exit 1
fi

expect_ok "stream the corridor into a map that keeps thumbnails" "$recog" stream --map corridor \
  --create --keep-thumbnails --images "$data/places/corridor/images" -q "${server[@]}"
grep -q "^84 frames, [1-9][0-9]* loops, 0 errors" "$tmp/out" && pass || fail "stream: $(cat "$tmp/out")"
for model in lion cabinet_small; do
  expect_ok "build $model" "$recog" model build --roboearth "$data/objects/roboearth/models/$model" \
    -o "$tmp/$model.robj"
  expect_ok "push $model" "$recog" models push "$tmp/$model.robj" "${server[@]}"
done

shots=${RECOG_CONSOLE_SCREENSHOTS:-$tmp/screenshots}
/usr/bin/python3 "$project/tests/console/console_browser_test.py" \
  --url "http://127.0.0.1:$console_port" --token "$reader" --map corridor --min-loops 10 \
  --model lion --photo "$data/objects/roboearth/scenes/lab1-rect.png" \
  --camera 525,525,319.5,239.5 --expect-object cabinet_small \
  --place-photo "$data/places/corridor/images/41.jpg" --expect-chart corridor_pr --screenshots "$shots"
browser=$?
[ "$browser" -eq 77 ] && exit 77
[ "$browser" -eq 0 ] && pass || fail "the browser test (exit $browser); recogd's log: $(tail -5 "$tmp/recogd.log")"
report_and_exit

#!/usr/bin/env bash
# deploy/monitoring/ holds together: Prometheus accepts the alert rules (`promtool check rules`),
# they fire when their unit tests say (`promtool test rules recogd-alerts-test.yml`), the Grafana
# dashboard is valid JSON with a query per panel, and every metric the rules and the dashboard
# name is one a real recogd exports on /metrics (after a stream, so that every labelled series
# exists), `up` aside (Prometheus records it per scrape).
# Usage: monitoring_test.sh RECOG RECOGD PROJECT_DIR. Exits 77 (skipped) after the metric check
# when promtool is missing (Debian: apt-get install prometheus; CI installs it).
set -u
recog=$1
recogd=$2
project=$3
monitoring=$project/deploy/monitoring
tmp=$(mktemp -d)
server_pid=
cleanup() {
  [ -n "$server_pid" ] && kill -KILL "$server_pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
# shellcheck source=../../tools/recog/cli_test_lib.sh
source "$project/tools/recog/cli_test_lib.sh"

# A recogd with data: a streamed map, so that the per-map, per-stream and per-method series exist.
port=$(free_port)
metrics_port=$(free_port)
server=(--server "127.0.0.1:$port")
"$recogd" --listen "127.0.0.1:$port" --metrics-listen "127.0.0.1:$metrics_port" \
  --data-dir "$tmp/data" --workers 2 >"$tmp/recogd.log" 2>&1 &
server_pid=$!
wait_for_recogd "$server_pid" && pass || fail "recogd did not start: $(cat "$tmp/recogd.log")"
expect_ok "stream the corridor frames" "$recog" stream --map corridor --create \
  --images "$project/tests/data/corridor" -q "${server[@]}"
expect_error "a call that fails, for the error series" "NOT_FOUND" "$recog" query --map nowhere \
  "$project/tests/data/corridor/1.jpg" "${server[@]}"

if /usr/bin/python3 - "$monitoring" "$metrics_port" >"$tmp/names.log" 2>&1 <<'PYTHON'
import json, re, sys, urllib.request
import yaml
monitoring, port = sys.argv[1], sys.argv[2]
text = urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=10).read().decode()
exported = set()
for name, kind in re.findall(r"^# TYPE (\S+) (\S+)$", text, re.M):
    exported.add(name)
    if kind == "histogram":
        exported.update(name + suffix for suffix in ("_bucket", "_sum", "_count"))
assert "recog_store_disk_available_bytes" in exported, "recogd does not export the disk metrics"

def names(expr):
    # Metric names: identifiers followed by a selector, a range or the end of a term, that are not
    # functions, keywords, label names or aggregation modifiers.
    words = set(re.findall(r"\b([a-zA-Z_:][a-zA-Z0-9_:]*)\b(?!\s*\()", re.sub(r'"[^"]*"', "", expr)))
    return {w for w in words if w.startswith(("recog_", "grpc_server_")) or w == "up"}

used = {}
rules = yaml.safe_load(open(f"{monitoring}/recogd-alerts.yml"))
for group in rules["groups"]:
    for rule in group["rules"]:
        for name in names(rule["expr"]):
            used.setdefault(name, []).append("alert " + rule["alert"])
dashboard = json.load(open(f"{monitoring}/recogd-dashboard.json"))
assert dashboard["panels"], "the dashboard has no panels"
for panel in dashboard["panels"]:
    assert panel["targets"], f"panel '{panel['title']}' has no query"
    for target in panel["targets"]:
        found = names(target["expr"])
        assert found, f"panel '{panel['title']}' queries no recogd metric: {target['expr']}"
        for name in found:
            used.setdefault(name, []).append("panel " + panel["title"])
missing = {n: where for n, where in used.items() if n != "up" and n not in exported}
assert not missing, f"not exported by recogd: {missing}"
assert len(used) >= 15, sorted(used)
print(f"{len(used)} metric names, all exported: {sorted(used)}")
PYTHON
then pass; else fail "the rules and the dashboard name only recogd's metrics: $(cat "$tmp/names.log")"; fi

if ! command -v promtool >/dev/null; then
  [ "$failures" -eq 0 ] || report_and_exit
  echo "SKIP: promtool not found (apt-get install prometheus): the rules were not checked"
  exit 77
fi
expect_ok "promtool check rules" promtool check rules "$monitoring/recogd-alerts.yml"
(cd "$monitoring" && promtool test rules recogd-alerts-test.yml) >"$tmp/out" 2>&1 \
  && pass || fail "promtool test rules: $(cat "$tmp/out")"
report_and_exit

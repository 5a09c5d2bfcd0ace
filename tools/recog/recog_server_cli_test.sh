#!/usr/bin/env bash
# End-to-end test of the recog subcommands that use recogd (stream, query, maps, models, admin,
# recognize --server) against a real recogd on a free port with a temporary data directory: their
# results, their one-line errors and exit statuses, and the server's clean exit on SIGTERM. With
# the shared data ($RECOG_SHARED_DATA/places/corridor), `recog stream` must find exactly the loops
# of `recog eval place` on the same 84 images.
# Usage: recog_server_cli_test.sh RECOG_BINARY RECOGD_BINARY PROJECT_DIR
set -u
recog=$1
recogd=$2
project=$3
tmp=$(mktemp -d)
server_pid=
restored_pid=
cleanup() {
  [ -n "$server_pid" ] && kill -KILL "$server_pid" 2>/dev/null
  [ -n "$restored_pid" ] && kill -KILL "$restored_pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
# shellcheck source=cli_test_lib.sh
source "$(dirname "$0")/cli_test_lib.sh"

images=$project/tests/data/corridor

# recogd's own exit statuses: 0 for --help and --version, 2 for a command line it refuses.
expect_ok "recogd --help" "$recogd" --help
expect_version "recogd --version" recogd "$recogd" --version
expect_usage_error "recogd with an unknown flag" "--frobnicate" "$recogd" --frobnicate
expect_usage_error "recogd with a bad value" "--workers" "$recogd" --workers many
expect_usage_error "recogd with a missing --config file" "NOT_FOUND" "$recogd" --config "$tmp/none.yaml"

port=$(free_port)
server=(--server "127.0.0.1:$port")
"$recogd" --listen "127.0.0.1:$port" --data-dir "$tmp/data" --metrics-listen "" --workers 2 \
  >"$tmp/recogd.log" 2>&1 &
server_pid=$!
if ! wait_for_recogd "$server_pid"; then
  echo "FAIL: recogd did not start: $(cat "$tmp/recogd.log")"
  exit 1
fi

for sub in "stream" "query" "maps list" "maps create" "maps delete" "maps stats" \
    "maps remove-frame" "models push" \
    "models pull" "models list" "models delete" "models watch"; do
  # shellcheck disable=SC2086
  expect_ok "help of $sub" "$recog" $sub --help
done

# Maps.
expect_ok "maps create" "$recog" maps create lab --alpha 0.25 --min-inliers 15 --geometry exhaustive \
  --json "${server[@]}"
json_check "maps create --json shows the settings given and the server's defaults" \
  "s=d['settings']; assert d['name']=='lab' and d['frames']==0 and s['alpha']==0.25 and s['min_inliers']==15 and s['geometry']=='exhaustive' and s['temporal_matches']==3, d"
expect_error "maps create of an existing map" "ALREADY_EXISTS" "$recog" maps create lab "${server[@]}"
expect_usage_error "maps create with a bad geometry" "geometry" "$recog" maps create lab2 --geometry homography "${server[@]}"
expect_error "maps create with too few inliers" "INVALID_ARGUMENT" "$recog" maps create lab2 --min-inliers 3 "${server[@]}"
expect_ok "maps create --preset keyframes" "$recog" maps create kf --preset keyframes --json "${server[@]}"
json_check "maps create --preset keeps the preset" "assert d['settings']['preset']=='keyframes', d"
expect_usage_error "maps create with an unknown preset" "--preset: video" "$recog" maps create kf2 --preset video "${server[@]}"
expect_ok "maps delete kf" "$recog" maps delete kf "${server[@]}"
expect_ok "maps list" "$recog" maps list --json "${server[@]}"
json_check "maps list shows the map" "assert [m['name'] for m in d]==['lab'], d"
expect_ok "maps stats" "$recog" maps stats lab "${server[@]}"
grep -q "^alpha *0.25" "$tmp/out" && pass || fail "maps stats prints the settings: $(cat "$tmp/out")"
expect_error "maps stats of an unknown map" "NOT_FOUND" "$recog" maps stats nowhere "${server[@]}"
expect_ok "maps delete" "$recog" maps delete lab "${server[@]}"
expect_error "maps delete of an unknown map" "NOT_FOUND" "$recog" maps delete lab "${server[@]}"

# The connection from the environment; a flag given wins over its variable.
expect_ok "maps list with RECOG_SERVER" env RECOG_SERVER="127.0.0.1:$port" "$recog" maps list
expect_ok "--server wins over RECOG_SERVER" env RECOG_SERVER=127.0.0.1:1 "$recog" maps list \
  "${server[@]}"
expect_error "RECOG_TOKEN_FILE is read" "NOT_FOUND.*$tmp/no-token" env RECOG_TOKEN_FILE="$tmp/no-token" \
  "$recog" maps list "${server[@]}"

# Stream the four bundled frames, then relocalise one of them.
expect_error "stream into an unknown map" "NOT_FOUND" "$recog" stream --map corridor \
  --images "$images" -q "${server[@]}"
expect_ok "stream the bundled frames" "$recog" stream --map corridor --create --images "$images" \
  --rate 50 -q "${server[@]}"
grep -q "^4 frames, 0 loops, 0 errors" "$tmp/out" && pass || fail "stream summary: $(cat "$tmp/out")"
# Two robots of a fleet: robot B's frames are looked up in robot A's map (the corridor above).
expect_ok "maps create --group" "$recog" maps create robot-b --group fleet --json "${server[@]}"
json_check "maps create --group keeps the group" "assert d['settings']['group']=='fleet', d"
expect_ok "stream --search-maps" "$recog" stream --map robot-b --images "$images/41.jpg" \
  --search-maps corridor --json -q "${server[@]}"
/usr/bin/python3 -c "
import json; events=[json.loads(l) for l in open('$tmp/out')]
found=[e for e in events if e['event']=='inter_map_loop']
assert [(e['map'], e['match']) for e in found]==[('corridor', 2)], events  # the same image
assert found[0]['frame_file'].startswith('41.jpg'), found
assert events[-1]['event']=='summary' and events[-1]['inter_map_loops']==1, events[-1]" \
  && pass || fail "stream --search-maps reports the inter-map loop: $(cat "$tmp/out")"
expect_error "stream --search-group of an unknown group" "NOT_FOUND.*'armada'" "$recog" stream \
  --map robot-b --images "$images/41.jpg" --search-group armada -q "${server[@]}"
# A robot that lost itself relocalises from two images in the fleet's maps.
expect_ok "relocalize" "$recog" relocalize "$images/41.jpg" "$images/60.jpg" --maps corridor \
  --group fleet "${server[@]}"
grep -q "^map 'corridor': .* is frame [23], .* inliers .*; 2 of 2 images recognised" "$tmp/out" \
  && pass || fail "relocalize names the map and counts the images: $(cat "$tmp/out")"
expect_ok "relocalize --json" "$recog" relocalize "$images/41.jpg" --maps corridor --json \
  "${server[@]}"
json_check "relocalize --json finds 41.jpg as frame 2" \
  "p=d['places']; assert len(p)==1 and p[0]['map']=='corridor' and p[0]['result']['match']==2 and p[0]['frames_recognised']==1, d"
expect_error "relocalize in an unknown group" "NOT_FOUND.*'armada'" "$recog" relocalize \
  "$images/41.jpg" --group armada "${server[@]}"
expect_error "relocalize without maps" "INVALID_ARGUMENT.*maps or a group" "$recog" relocalize \
  "$images/41.jpg" "${server[@]}"
expect_error "relocalize with fewer depth images than images" \
  "INVALID_ARGUMENT.*one depth image per image: 1 for 2" "$recog" relocalize "$images/41.jpg" \
  "$images/60.jpg" --maps corridor --camera 500,500,320,240 --depth "$images/41.jpg" \
  "${server[@]}"
expect_error "relocalize with a missing depth image" \
  "NOT_FOUND.*'$tmp/no-depth.png' does not exist" "$recog" relocalize "$images/41.jpg" \
  --maps corridor --camera 500,500,320,240 --depth "$tmp/no-depth.png" "${server[@]}"
expect_error "query with a missing depth image" \
  "NOT_FOUND.*'$tmp/no-depth.png' does not exist" "$recog" query --map corridor \
  "$images/41.jpg" --camera 500,500,320,240 --depth "$tmp/no-depth.png" "${server[@]}"
expect_ok "maps stats robot-b" "$recog" maps stats robot-b --json "${server[@]}"
json_check "the refused stream added nothing" "assert d['frames']==1, d"
expect_ok "maps delete robot-b" "$recog" maps delete robot-b "${server[@]}"
expect_ok "query" "$recog" query --map corridor "$images/41.jpg" --json "${server[@]}"
json_check "query of 41.jpg finds frame 2" \
  "assert d['status']=='loop_detected' and d['match']==2 and d['inliers']>=12 and 'frame' not in d, d"
expect_ok "query with a camera" "$recog" query --map corridor "$images/41.jpg" --camera 500,500,256,192 "${server[@]}"
grep -q "^status *loop_detected" "$tmp/out" && pass || fail "query prints the status: $(cat "$tmp/out")"
expect_ok "query --add" "$recog" query --map corridor "$images/60.jpg" --add --json "${server[@]}"
json_check "query --add adds frame 4" "assert d['frame']==4, d"
# Metric loops: a 16-bit PNG of a plane 2 m away, aligned with the 512x384 corridor images.
/usr/bin/python3 -c "
import struct, zlib
def chunk(k, d): return struct.pack('>I', len(d)) + k + d + struct.pack('>I', zlib.crc32(k + d))
rows = (b'\\x00' + struct.pack('>H', 2000) * 512) * 384
open('$tmp/depth.png', 'wb').write(b'\\x89PNG\\r\\n\\x1a\\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', 512, 384, 16, 0, 0, 0, 0))
    + chunk(b'IDAT', zlib.compress(rows)) + chunk(b'IEND', b''))"
expect_ok "maps create rgbd" "$recog" maps create rgbd "${server[@]}"
expect_ok "query --add --depth" "$recog" query --map rgbd "$images/41.jpg" --add \
  --camera 500,500,256,192 --depth "$tmp/depth.png" --json "${server[@]}"
json_check "query --add --depth adds frame 0" "assert d['frame']==0, d"
expect_ok "query with a camera in a map with depth" "$recog" query --map rgbd "$images/41.jpg" \
  --camera 500,500,256,192 --json "${server[@]}"
json_check "the loop's pose is metric" \
  "m=d['metric']; assert m['verified'] and len(m['covariance'])==36 and max(map(abs, m['pose']['translation']))<0.01, d"
expect_error "query --depth without --camera" "INVALID_ARGUMENT.*intrinsics" "$recog" query --map rgbd \
  "$images/41.jpg" --add --depth "$tmp/depth.png" "${server[@]}"
expect_error "query --right without --baseline" "baseline" "$recog" query --map rgbd \
  "$images/41.jpg" --add --camera 500,500,256,192 --right "$images/41.jpg" "${server[@]}"
expect_ok "stream the same frames as features" "$recog" stream --map corridor --images "$images" \
  --features-on-client --timestamps --json -q "${server[@]}"
/usr/bin/python3 -c "
import json; e=[json.loads(l) for l in open('$tmp/out')]
assert e[-1]['event']=='summary' and e[-1]['frames']==4 and e[-1]['errors']==0, e" \
  && pass || fail "stream --json ends with the summary"
expect_ok "maps stats after streaming" "$recog" maps stats corridor --json "${server[@]}"
json_check "the map has the 9 frames" "assert d['frames']==9 and d['next_frame_id']==9, d"
expect_ok "stream the first 2 frames only" "$recog" stream --map corridor --images "$images" \
  --frames 2 -q "${server[@]}"
grep -q "^2 frames, " "$tmp/out" && pass || fail "stream --frames 2: $(cat "$tmp/out")"
expect_error "stream from a camera that is not there" "NOT_FOUND.*camera 99" "$recog" stream \
  --map corridor --images camera:99 -q "${server[@]}"
# Ctrl-C ends a stream (a camera's way to end) cleanly: answers taken, summary printed, exit 0.
"$recog" stream --map corridor --images "$images" --rate 1 -q "${server[@]}" >"$tmp/out" 2>&1 &
streamer=$!
sleep 1.5
kill -INT "$streamer"
wait "$streamer"
code=$?
if [ "$code" -eq 0 ] && grep -qE "^[1-3] frames, .* 0 errors" "$tmp/out"; then pass
else fail "SIGINT ends the stream: exit $code, $(cat "$tmp/out")"; fi
expect_error "query of an unknown map" "NOT_FOUND" "$recog" query --map nowhere "$images/41.jpg" "${server[@]}"
expect_error "query of a missing image" "NOT_FOUND" "$recog" query --map corridor "$tmp/none.jpg" "${server[@]}"

# A rig map: a front + rear rig driven out and back (seqgen rig over tiles of the corridor photos),
# streamed with --rig; the way back's cameras find what the other camera saw on the way out.
photo_tiles "$images" "$tmp/tiles"
expect_ok "seqgen rig for the rig map" "$recog" seqgen rig --images "$tmp/tiles" -o "$tmp/rig" \
  --frames-per-leg 8 --width 320 --height 240 --focal 160 --depth -q
expect_ok "stream --rig into a new rig map" "$recog" stream --map rig --create --preset keyframes \
  --rig "$tmp/rig" --draw "$tmp/rig_loops" --json -q "${server[@]}"
/usr/bin/python3 -c "
import json; e=[json.loads(l) for l in open('$tmp/out')]
loops=[l for l in e if l['event']=='loop']; s=e[-1]
assert s['frames']==16 and s['errors']==0 and len(loops)>=6, e
back=[l for l in loops if l['frame']>=16]
assert len(back)>=6 and all(l['match']<16 and l['frame']%2==0 for l in back), back
assert any({'query_camera':'rear','match_camera':'front'}.items()<=p.items() for l in back for p in l['rig']['pairs']), back
assert all(len(p['inlier_correspondences'])==p['inliers'] for l in back for p in l['rig']['pairs']), back" \
  && pass || fail "stream --rig finds the way back's loops across cameras: $(head -c 600 "$tmp/out")"
ls "$tmp/rig_loops"/loop_*.png >/dev/null 2>&1 && pass || fail "stream --rig --draw writes the loops"
expect_ok "maps stats of the rig map" "$recog" maps stats rig --json "${server[@]}"
json_check "the rig map has 16 rig frames" "assert d['frames']==16 and d['next_frame_id']==32, d"
expect_ok "query --rig" "$recog" query --map rig --rig "$tmp/rig/rig.yaml" \
  "$tmp/rig/front/rgb/000011.png" "$tmp/rig/rear/rgb/000011.png" --json "${server[@]}"
json_check "query --rig finds the rig frame and the body pose" \
  "assert d['status']=='loop_detected' and d['match']==22 and d['rig']['posed'] \
   and len(d['rig']['pairs'])==2, d"
expect_error "stream --rig of a missing folder" "NOT_FOUND" "$recog" stream --map rig2 --create \
  --rig "$tmp/no-rig" -q "${server[@]}"
printf 'cameras:\n  - {name: front, width: 320}\n' >"$tmp/broken_rig.yaml"
expect_error "query --rig with a malformed rig file" "INVALID_ARGUMENT.*broken_rig.yaml" "$recog" \
  query --map rig --rig "$tmp/broken_rig.yaml" "$tmp/rig/front/rgb/000011.png" "${server[@]}"
expect_usage_error "stream with both --images and --rig" "excludes" "$recog" stream --map rig \
  --images "$images" --rig "$tmp/rig" "${server[@]}"
expect_usage_error "stream --keep-thumbnails without --create" "--create" "$recog" stream --map corridor \
  --keep-thumbnails --images "$images" "${server[@]}"
expect_ok "maps create --keep-thumbnails" "$recog" maps create thumbs --keep-thumbnails --json "${server[@]}"
json_check "maps create --keep-thumbnails shows the setting" "assert d['settings']['keep_thumbnails'] is True, d"
expect_ok "maps list after the refused rig streams" "$recog" maps list --json "${server[@]}"
json_check "no map was created by a refused rig stream" \
  "assert 'rig2' not in [m['name'] for m in d] and 'rig' in [m['name'] for m in d], d"
expect_error "query --rig with an image short" "one image per camera" "$recog" query --map rig \
  --rig "$tmp/rig/rig.yaml" "$tmp/rig/front/rgb/000011.png" "${server[@]}"
expect_error "a single image into a rig map" "INVALID_ARGUMENT.*rig map" "$recog" query --map rig \
  "$tmp/rig/front/rgb/000011.png" "${server[@]}"
cp "$tmp/rig/rear/rgb/000003.png" "$tmp/small.png"
/usr/bin/python3 -c "import cv2; cv2.imwrite('$tmp/small.png', cv2.imread('$tmp/small.png')[:120, :160])"
expect_error "a camera image of the wrong size" "INVALID_ARGUMENT.*rig camera 'rear'.*160x120" \
  "$recog" query --map rig --add --rig "$tmp/rig/rig.yaml" "$tmp/rig/front/rgb/000011.png" \
  "$tmp/small.png" "${server[@]}"
expect_ok "maps stats of the rig map" "$recog" maps stats rig --json "${server[@]}"
json_check "the refused rig frames added nothing" "assert d['frames']==16, d"

# A SLAM's keyframes: its own ids come back with the match and the candidates; culling.
expect_ok "maps create slam" "$recog" maps create slam "${server[@]}"
for n in 1 20 41 60; do
  expect_ok "query --add with a client frame id" "$recog" query --map slam "$images/$n.jpg" --add \
    --client-frame-id "kf-$n" "${server[@]}"
done
expect_ok "query --top-k --correspondences" "$recog" query --map slam "$images/41.jpg" --top-k 2 \
  --correspondences --json "${server[@]}"
json_check "the match's client id, the top 2 candidates and the inlier pixels" \
  "c=d['candidates']; assert d['match']==2 and d['match_client_frame_id']=='kf-41' and len(c)==2 and c[0]['frame']==2 and c[0]['client_frame_id']=='kf-41' and c[0]['inliers']==d['inliers'] and 'inliers' not in c[1] and c[0]['score']>=c[1]['score'] and len(d['inlier_correspondences'])==d['inliers'], d"
expect_ok "query prints the match's client id" "$recog" query --map slam "$images/41.jpg" "${server[@]}"
grep -q "^match id *kf-41" "$tmp/out" && pass || fail "query prints the match id: $(cat "$tmp/out")"
expect_usage_error "query --top-k above 50" "top-k" "$recog" query --map slam "$images/41.jpg" \
  --top-k 51 "${server[@]}"
expect_ok "maps remove-frame --frame" "$recog" maps remove-frame slam --frame 2 --json "${server[@]}"
json_check "remove-frame reports the frame" "assert d['removed_frames']==[2], d"
expect_ok "maps remove-frame --client-frame-id" "$recog" maps remove-frame slam \
  --client-frame-id kf-60 "${server[@]}"
grep -q "^removed from map slam: frame 3$" "$tmp/out" && pass || fail "remove-frame: $(cat "$tmp/out")"
expect_error "maps remove-frame of a removed frame" "NOT_FOUND" "$recog" maps remove-frame slam \
  --frame 2 "${server[@]}"
expect_error "maps remove-frame of an unknown map" "NOT_FOUND" "$recog" maps remove-frame nowhere \
  --frame 0 "${server[@]}"
expect_error "maps remove-frame without a frame" "INVALID_ARGUMENT" "$recog" maps remove-frame slam \
  "${server[@]}"
expect_ok "query after the removal" "$recog" query --map slam "$images/41.jpg" --top-k 50 --json \
  "${server[@]}"
json_check "a removed frame is no candidate" \
  "assert d.get('match')!=2 and all(c['frame']<2 for c in d.get('candidates', [])), d"

# Models: push, list, pull, recognise on the server, delete.
expect_ok "model build of a planar poster" "$recog" model build --planar "$images/1.jpg" \
  --width 0.64 --height 0.48 --name poster -o "$tmp/poster.robj"
"$recog" models watch --prefix watched --count 1 --json "${server[@]}" >"$tmp/watch.out" 2>"$tmp/watch.err" &
watch_pid=$!
expect_ok "models push" "$recog" models push "$tmp/poster.robj" --tag lab --json "${server[@]}"
json_check "models push reports version 1" "assert d[0]['name']=='poster' and d[0]['version']==1, d"
expect_ok "models list" "$recog" models list --tag lab --json "${server[@]}"
json_check "models list shows the poster" "assert [(m['name'], m['type'], m['tags']) for m in d]==[('poster', 'planar', ['lab'])], d"
expect_ok "models list by another class" "$recog" models list --class nothing --json "${server[@]}"
json_check "models list filters by class" "assert d==[], d"
expect_ok "models pull" "$recog" models pull poster -o "$tmp/pulled.robj" "${server[@]}"
cmp -s "$tmp/poster.robj" "$tmp/pulled.robj" && pass || fail "the pulled model is the pushed file"
expect_error "models pull of an unknown version" "NOT_FOUND" "$recog" models pull poster --version 7 \
  -o "$tmp/v7.robj" "${server[@]}"
expect_ok "recognize --server" "$recog" recognize --server "127.0.0.1:$port" --image "$images/1.jpg" \
  --camera 500,500,256,192 --json --draw "$tmp/poster.png"
json_check "recognize --server finds the poster" \
  "assert [(x['name'], x['version']) for x in d['detections']]==[('poster', 1)] and 'recognition' in d['timing_ms'], d"
/usr/bin/python3 -c "assert open('$tmp/poster.png', 'rb').read(8) == b'\\x89PNG\\r\\n\\x1a\\n'" \
  && pass || fail "recognize --server --draw writes a PNG"
expect_ok "recognize --server --inliers --covariance" "$recog" recognize --server "127.0.0.1:$port" \
  --image "$images/1.jpg" --camera 500,500,256,192 --json --inliers --covariance
json_check "recognize --server --json reports inliers_2d3d and covariance" \
  "x=d['detections'][0]; i=x['inliers_2d3d']; assert len(i)==x['inliers'] and sorted(i[0])==['pixel', 'point', 'point_id'] and len(x['covariance'])==36, x"
expect_ok "recognize --server --explain" "$recog" recognize --server "127.0.0.1:$port" \
  --image "$images/1.jpg" --camera 500,500,256,192 --json --explain
json_check "recognize --server --explain says where each object of the repository ended" \
  "e=d['explanation']; assert [(x['name'], x['outcome']) for x in e]==[('poster', 'detected')] and e[0]['inliers']>=e[0]['min_inliers']>0 and e[0]['regions']>=1, e"
expect_ok "recognize --server without --explain" "$recog" recognize --server "127.0.0.1:$port" \
  --image "$images/1.jpg" --camera 500,500,256,192 --json
json_check "recognize --server explains nothing unless asked" "assert 'explanation' not in d, d"
expect_ok "recognize stays offline with RECOG_SERVER set" env RECOG_SERVER=127.0.0.1:1 \
  RECOG_TOKEN_FILE="$tmp/no-token" "$recog" recognize --models "$tmp/poster.robj" \
  --image "$images/1.jpg" --camera 500,500,256,192 --json
json_check "offline recognize finds the poster" "assert [x['name'] for x in d['detections']]==['poster'], d"
expect_usage_error "recognize with --models and --server" "excludes" "$recog" recognize --models "$tmp/poster.robj" \
  --server "127.0.0.1:$port" --image "$images/1.jpg" --camera 500,500,256,192
expect_error "recognize with neither --models nor --server" "--models" "$recog" recognize \
  --image "$images/1.jpg" --camera 500,500,256,192
expect_ok "models delete" "$recog" models delete poster "${server[@]}"
expect_error "models delete of an unknown model" "NOT_FOUND" "$recog" models delete poster "${server[@]}"
expect_error "models push of a folder without models" "INVALID_ARGUMENT" "$recog" models push "$images" "${server[@]}"

# The watcher registers shortly after it starts: push until it has seen a change.
for i in $(seq 50); do
  kill -0 "$watch_pid" 2>/dev/null || break
  "$recog" models push "$tmp/poster.robj" --name "watched-$i" "${server[@]}" >/dev/null 2>&1
  sleep 0.2
done
wait "$watch_pid" && pass || fail "models watch --count 1 exits 0: $(cat "$tmp/watch.err")"
/usr/bin/python3 -c "
import json; e=[json.loads(l) for l in open('$tmp/watch.out')]
assert len(e)==1 and e[0]['change']=='put' and e[0]['model']['name'].startswith('watched-'), e" \
  && pass || fail "models watch prints the push: $(cat "$tmp/watch.out")"

# The shared corridor sequence: the same loops as recog eval place.
shared=${RECOG_SHARED_DATA:-$project/../shared/data}
if [ -d "$shared/places/corridor/images" ]; then
  expect_ok "stream the shared corridor" "$recog" stream --map shared-corridor --create \
    --images "$shared/places/corridor/images" --json -q "${server[@]}"
  mv "$tmp/out" "$tmp/stream.jsonl"
  expect_ok "eval place on the shared corridor" "$recog" eval place \
    --images "$shared/places/corridor/images" --ground-truth "$shared/places/corridor/ground_truth.txt" --json -q
  /usr/bin/python3 -c "
import json, os
events = [json.loads(l) for l in open('$tmp/stream.jsonl')]
streamed = [(e['frame'], e['match'], e['frame_file'], e['match_file']) for e in events if e['event'] == 'loop']
d = json.load(open('$tmp/out'))
evaluated = [(l['query'] - 1, l['match'] - 1, os.path.basename(l['query_file']), os.path.basename(l['match_file']))
             for l in d['loops'] if l['status'] == 'loop_detected']
assert events[-1]['frames'] == 84 and evaluated and streamed == evaluated, (streamed, evaluated)" \
    && pass || fail "stream finds exactly the loops of eval place"
else
  skip_shared "the shared corridor: $shared/places/corridor/images not found (set RECOG_SHARED_DATA)"
fi

# Operation: health, and an online checkpoint restored into a second server.
expect_ok "admin health" "$recog" admin health "${server[@]}"
grep -q "^SERVING" "$tmp/out" && pass || fail "admin health prints SERVING: $(cat "$tmp/out")"
"$recog" maps list --json "${server[@]}" >"$tmp/maps.json"
"$recog" models list --json "${server[@]}" >"$tmp/models.json"
expect_ok "admin checkpoint" "$recog" admin checkpoint --to "$tmp/backup" -q --json "${server[@]}"
json_check "admin checkpoint reports the maps and models, and read its table files back" \
  "assert d['maps']>=1 and d['models']>=1 and d['bytes']>0 and d['verified_table_files']>=1, d"
expect_error "admin checkpoint to an existing folder" "ALREADY_EXISTS" "$recog" admin checkpoint \
  --to "$tmp/backup" -q "${server[@]}"
cp -r "$tmp/backup" "$tmp/damaged-backup"
expect_ok "admin restore" "$recog" admin restore --from "$tmp/backup" --data-dir "$tmp/restored"
grep -q "^restored .* files, .* MiB checked" "$tmp/out" && pass \
  || fail "admin restore checks what it restored: $(cat "$tmp/out")"
table=$(ls -S "$tmp"/damaged-backup/*.sst | head -1)
python3 -c "import sys; p=sys.argv[1]; f=open(p,'r+b'); f.seek(0,2); n=f.tell()//2; f.seek(n); b=f.read(1); f.seek(n); f.write(bytes([b[0]^16]))" "$table"
expect_error "admin restore of a damaged checkpoint" "DATA_LOSS.*is damaged; nothing restored" \
  "$recog" admin restore --from "$tmp/damaged-backup" --data-dir "$tmp/from-damaged"
[ -e "$tmp/from-damaged/store" ] && fail "a damaged checkpoint was left in place" || pass
expect_error "admin restore over a store" "ALREADY_EXISTS" "$recog" admin restore \
  --from "$tmp/backup" --data-dir "$tmp/restored"
expect_error "admin restore of a missing checkpoint" "NOT_FOUND" "$recog" admin restore \
  --from "$tmp/none" --data-dir "$tmp/other"
port2=$(free_port)
"$recogd" --listen "127.0.0.1:$port2" --data-dir "$tmp/restored" --metrics-listen "" --workers 2 \
  >"$tmp/restored.log" 2>&1 &
restored_pid=$!
for _ in $(seq 100); do
  "$recog" admin health --server "127.0.0.1:$port2" >/dev/null 2>&1 && break
  sleep 0.1
done
"$recog" maps list --json --server "127.0.0.1:$port2" >"$tmp/maps2.json"
"$recog" models list --json --server "127.0.0.1:$port2" >"$tmp/models2.json"
/usr/bin/python3 -c "
import json
def load(p): return json.load(open(p))
assert load('$tmp/maps.json') == load('$tmp/maps2.json'), 'maps differ'
assert load('$tmp/models.json') == load('$tmp/models2.json'), 'models differ'
assert load('$tmp/maps.json') and load('$tmp/models.json')" \
  && pass || fail "the restored server has every map and model: $(cat "$tmp/restored.log" | tail -3)"
kill -TERM "$restored_pid"
wait "$restored_pid" && pass || fail "the restored server exits 0 on SIGTERM"
restored_pid=

# A server that is not there, then the server's exit on SIGTERM.
closed=$(free_port)
expect_error "maps list of a closed port" "UNAVAILABLE" "$recog" maps list --server "127.0.0.1:$closed"
kill -TERM "$server_pid"
wait "$server_pid"
code=$?
server_pid=
[ "$code" -eq 0 ] && pass || fail "recogd exits 0 on SIGTERM (exit $code): $(tail -5 "$tmp/recogd.log")"

report_and_exit

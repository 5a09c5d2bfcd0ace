#!/usr/bin/env bash
# End-to-end test of --bag (ROS 1 bags written by Debian's python3-rosbag through
# tests/testing/write_bag.py) in `recog eval place`, `recog stream` and `recog load`, against a
# real recogd on a free port: every bad bag is one named error line and nothing is streamed; the
# bundled frames with depth and camera info give metric loops; a bag replays at its own pace. With
# the shared data ($RECOG_SHARED_DATA/places/corridor), the corridor as a bag (JPEG bytes as they
# are, and mono8 pixels) gives exactly the loops of its folder in eval place (100 % precision,
# 81.8 % recall), in stream and in load --verify. Frames are stamped 0.97 s apart: tau_c's 20 s
# then leave out the 20 frames before each, as its 20 frames do for a folder without timestamps.
# ROS 2 bags: `recog bag info` and `bag extract` on the MCAP and sqlite3 fixtures of
# tests/data/bags, bad ROS 2 bags refused by name, and with the shared data every rosbag2 test bag
# (bags/rosbag2) listed as its metadata.yaml says.
# Usage: recog_bag_cli_test.sh RECOG_BINARY RECOGD_BINARY PROJECT_DIR
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
# shellcheck source=cli_test_lib.sh
source "$(dirname "$0")/cli_test_lib.sh"

images=$project/tests/data/corridor
shared=${RECOG_SHARED_DATA:-$project/../shared/data}
topic=/camera/image_raw
write_bag() {
  /usr/bin/python3 "$project/tests/testing/write_bag.py" "$@" >"$tmp/write.log" 2>&1 \
    || { echo "FAIL: write_bag.py $*: $(cat "$tmp/write.log")"; exit 1; }
}
if ! /usr/bin/python3 -c "import rosbag, sensor_msgs.msg" 2>/dev/null; then
  echo "FAIL: python3-rosbag and python3-sensor-msgs are needed (scripts/install_deps.sh)"
  exit 1
fi

# The four bundled frames: as JPEG bytes, with a depth image (a plane 2 m away, millimetres) and
# camera info per frame; and the bad bags.
mkdir -p "$tmp/depth"
/usr/bin/python3 -c "
import cv2, numpy
for k in range(4): cv2.imwrite('$tmp/depth/%d.png' % k, numpy.full((384, 512), 2000, numpy.uint16))"
write_bag "$tmp/small.bag" --images "$images" --encoding jpeg --period 0.2 \
  --camera-info-topic /camera/camera_info --camera 500,500,256,192 --depth-images "$tmp/depth"
write_bag "$tmp/yuv.bag" --images "$images" --encoding yuv422
write_bag "$tmp/late_depth.bag" --images "$images" --depth-images "$tmp/depth" --depth-offset 0.05
write_bag "$tmp/unindexed.bag" --images "$images" --unindexed
head -c 100000 "$tmp/small.bag" >"$tmp/truncated.bag"

# Bad bags and flags: one line each, exit 1 (2 for the command line).
expect_error "a bag without --topic lists its image topics" \
  "INVALID_ARGUMENT: --bag needs --topic, one of the bag's image topics: /camera/depth/image_raw (sensor_msgs/Image, 4 messages), $topic (sensor_msgs/CompressedImage, 4 messages)$" \
  "$recog" eval place --bag "$tmp/small.bag" -q
expect_error "an unknown topic lists the bag's topics" \
  "NOT_FOUND: bag '$tmp/small.bag' has no topic /cam (the image topic); its topics: /camera/camera_info (sensor_msgs/CameraInfo, 4 messages), /camera/depth/image_raw (sensor_msgs/Image, 4 messages), $topic" \
  "$recog" eval place --bag "$tmp/small.bag" --topic /cam -q
expect_error "a truncated bag" "DATA_LOSS: bag '$tmp/truncated.bag' is truncated" \
  "$recog" eval place --bag "$tmp/truncated.bag" --topic "$topic" -q
expect_error "an unindexed bag" "DATA_LOSS: .* is unindexed: its recording was not closed .*rosbag reindex" \
  "$recog" eval place --bag "$tmp/unindexed.bag" --topic "$topic" -q
expect_error "an unsupported encoding" \
  "INVALID_ARGUMENT: topic $topic, message 1 at stamp 1000.000000000 of bag '$tmp/yuv.bag': encoding 'yuv422' is not supported" \
  "$recog" eval place --bag "$tmp/yuv.bag" --topic "$topic" -q
expect_error "a frame without depth within the offset" \
  "INVALID_ARGUMENT: bag '$tmp/late_depth.bag': frame 1 (stamp 1000.000000000) of $topic has no depth image on /camera/depth/image_raw within 0.02 s" \
  "$recog" eval place --bag "$tmp/late_depth.bag" --topic "$topic" --depth-topic /camera/depth/image_raw -q
expect_error "a depth topic without the camera" "INVALID_ARGUMENT: --depth-topic and --right-topic need" \
  "$recog" eval place --bag "$tmp/small.bag" --topic "$topic" --depth-topic /camera/depth/image_raw -q
expect_error "--camera and --camera-info-topic" "INVALID_ARGUMENT: give the camera with --camera or --camera-info-topic" \
  "$recog" eval place --bag "$tmp/small.bag" --topic "$topic" --camera-info-topic /camera/camera_info \
  --camera 500,500,256,192 -q
expect_usage_error "--bag with --images" "excludes" "$recog" eval place --bag "$tmp/small.bag" \
  --images "$images" --topic "$topic"
expect_usage_error "--topic without --bag" "requires --bag" "$recog" eval place --images "$images" \
  --topic "$topic"
expect_usage_error "--bag-speed without --bag" "requires --bag" "$recog" load --sequences "$images" \
  --robots 1 --frames 1 --bag-speed 1
expect_error "a depth offset that is not a number" \
  "INVALID_ARGUMENT: BagReadOptions.max_depth_offset = nan: must be finite and >= 0" \
  "$recog" eval place --bag "$tmp/small.bag" --topic "$topic" --max-depth-offset nan -q
for speed in nan -1 inf; do
  expect_error "--bag-speed $speed" "INVALID_ARGUMENT: --bag-speed must be 0 or a positive factor" \
    "$recog" load --bag "$tmp/small.bag" --topic "$topic" --robots 1 --frames 1 --bag-speed "$speed"
done

# The bundled frames from the bag: depth and camera info give 3D points and metric loops.
expect_ok "eval place --bag with depth and camera info" "$recog" eval place --bag "$tmp/small.bag" \
  --topic "$topic" --camera-info-topic /camera/camera_info --depth-topic /camera/depth/image_raw \
  --json -q
json_check "the frames are the bag's, with 3D points" \
  "assert d['frames']==4 and d['layout']=='bag' and 'points' in d['timing_ms'], d"

# ROS 2 bags: the fixtures written by real writers (tests/data/bags, its README: 6 frames 64 x 48,
# mono8 and PNG images, 16UC1 and compressedDepth depth, CameraInfo).
fixtures=$project/tests/data/bags
expect_ok "bag info --json of an MCAP file" "$recog" bag info --json "$fixtures/fixture.mcap"
json_check "bag info --json: storage, compression, topics, counts, encodings and sizes" "
t = {x['name']: x for x in d['topics']}
assert d['storage'] == 'mcap' and d['compression'] == 'zstd' and d['messages'] == 30, d
assert d['start_ns'] == 1700000000000000000 and d['end_ns'] == 1700000000500000000, d
assert all(x['messages'] == 6 and x['serialization'] == 'cdr' for x in d['topics']), d
assert (t['/camera/image_raw']['encoding'], t['/camera/image_raw']['width']) == ('mono8', 64), t
assert t['/camera/depth/image_raw/compressedDepth']['encoding'] == '16UC1; compressedDepth png', t
assert t['/camera/depth/image_raw/compressedDepth']['height'] == 48, t"
expect_ok "bag info of a rosbag2 sqlite3 folder" "$recog" bag info "$fixtures/fixture_sqlite3"
grep -q "^storage: *sqlite3$" "$tmp/out" &&
  grep -Eq "^  /camera/image_raw/compressed +sensor_msgs/msg/CompressedImage +6 messages  cdr  mono8; png compressed mono8 \(64 x 48\)$" "$tmp/out" &&
  pass || fail "bag info's text: $(cat "$tmp/out")"
expect_ok "eval place --bag on an MCAP file with compressedDepth and camera info" \
  "$recog" eval place --bag "$fixtures/fixture_lz4.mcap" --topic /camera/image_raw \
  --camera-info-topic /camera/camera_info --depth-topic /camera/depth/image_raw/compressedDepth \
  --json -q
json_check "the MCAP file's frames, with 3D points" \
  "assert d['frames']==6 and d['layout']=='bag' and 'points' in d['timing_ms'], d"
expect_ok "bag extract of a rosbag2 folder" "$recog" bag extract "$fixtures/fixture_sqlite3" \
  --topic /camera/image_raw/compressed -o "$tmp/extracted"
[ "$(grep -vc '^#' "$tmp/extracted/rgb.txt")" = 6 ] &&
  grep -q "^1700000000.500000000 rgb/000005.png$" "$tmp/extracted/rgb.txt" &&
  cmp -s <(/usr/bin/python3 -c "import cv2; print(cv2.imread('$tmp/extracted/rgb/000002.png', 0)[20, 10])") <(echo 210) &&
  pass || fail "bag extract: rgb.txt and the PNG files as the bag holds them: $(cat "$tmp/extracted/rgb.txt")"
expect_ok "eval place on the extracted folder (the TUM layout)" "$recog" eval place \
  --images "$tmp/extracted" --json -q
json_check "the extracted folder's frames" "assert d['frames']==6 and d['layout']=='tum', d"
# Bad ROS 2 bags: one line each, naming the file and the record.
head -c 5000 "$fixtures/fixture.mcap" >"$tmp/cut.mcap"
expect_error "an MCAP file cut short" "DATA_LOSS: MCAP file '$tmp/cut.mcap' does not end with the MCAP magic" \
  "$recog" eval place --bag "$tmp/cut.mcap" --topic /camera/image_raw -q
/usr/bin/python3 -c "
data = bytearray(open('$fixtures/fixture.mcap', 'rb').read()); data[3000] ^= 0xff
open('$tmp/crc.mcap', 'wb').write(data)"
expect_error "a chunk whose CRC does not match" "DATA_LOSS: MCAP file '$tmp/crc.mcap', Chunk record at byte [0-9]*: its records' CRC is" \
  "$recog" eval place --bag "$tmp/crc.mcap" --topic /camera/image_raw -q
mkdir -p "$tmp/no_db3"
cp "$fixtures/fixture_sqlite3/metadata.yaml" "$tmp/no_db3/"
expect_error "a metadata.yaml naming a file that is not there" \
  "NOT_FOUND: '$tmp/no_db3/metadata.yaml' names the file 'fixture_0.db3', which is not there" \
  "$recog" bag info "$tmp/no_db3"
expect_error "a file that is no bag" "INVALID_ARGUMENT: '$images/1.jpg' is not a bag: it starts with ff d8 ff" \
  "$recog" bag info "$images/1.jpg"

# The rosbag2 test bags (shared data, bags/rosbag2): bag info lists the topics and counts of each
# bag's metadata.yaml (or of its tables, with no metadata.yaml; topics without messages too), the
# sqlite3 and MCAP twins alike; the bags of an unknown serialization format are refused by name.
rosbag2=$shared/bags/rosbag2
if [ -d "$rosbag2" ]; then
  for bag in "$rosbag2"/*; do
    name=$(basename "$bag")
    [ -f "$bag/$name" ] && bag=$bag/$name  # a lone file in a folder of its name
    if [[ $name == *wrong_rmw_test ]]; then
      expect_error "bag info $name" "INVALID_ARGUMENT: .*'wrong_format' (only cdr is read)" \
        "$recog" bag info "$bag"
      continue
    fi
    expect_ok "bag info $name" "$recog" bag info --json "$bag"
    cp "$tmp/out" "$tmp/$name.json"
    [ -f "$bag/metadata.yaml" ] || continue
    json_check "bag info $name: the topics and counts of its metadata.yaml" "
import yaml
info = yaml.safe_load(open('$bag/metadata.yaml'))['rosbag2_bagfile_information']
listed = {t.get('topic_metadata', t.get('topic_and_type'))['name']: t['message_count'] for t in info['topics_with_message_count']}
found = {t['name']: t['messages'] for t in d['topics']}
assert all(found.get(n) == c for n, c in listed.items()), (listed, found)
assert all(n in listed or c == 0 for n, c in found.items()), (listed, found)
assert d['messages'] == info['message_count'], (d['messages'], info['message_count'])"
  done
  for db3 in "$tmp"/db3_*.json; do
    mcap=$tmp/mcap_${db3#"$tmp"/db3_}
    [ -f "$mcap" ] || continue
    /usr/bin/python3 -c "
import json
topics = lambda f: [(t['name'], t['type'], t['messages']) for t in json.load(open(f))['topics']]
assert topics('$db3') == topics('$mcap'), (topics('$db3'), topics('$mcap'))" &&
      pass || fail "the sqlite3 and MCAP twins $(basename "$db3" .json) give the same topics and counts"
  done
else
  skip_shared "the rosbag2 test bags: $rosbag2 not found (set RECOG_SHARED_DATA)"
fi

port=$(free_port)
server=(--server "127.0.0.1:$port")
"$recogd" --listen "127.0.0.1:$port" --data-dir "$tmp/data" --metrics-listen "" --workers 2 \
  >"$tmp/recogd.log" 2>&1 &
server_pid=$!
if ! wait_for_recogd "$server_pid"; then
  echo "FAIL: recogd did not start: $(cat "$tmp/recogd.log")"
  exit 1
fi

# Nothing is streamed from a bad bag: the map is not even created.
for bag in truncated unindexed yuv; do
  expect_error "stream --bag $bag" "recog stream: " "$recog" stream --map "bad-$bag" --create \
    --bag "$tmp/$bag.bag" --topic "$topic" -q "${server[@]}"
done
expect_error "stream --bag with a late depth" "frame 1 (stamp 1000.000000000)" "$recog" stream \
  --map bad-depth --create --bag "$tmp/late_depth.bag" --topic "$topic" \
  --depth-topic /camera/depth/image_raw -q "${server[@]}"
expect_ok "maps list" "$recog" maps list --json "${server[@]}"
json_check "no map was created from a bad bag" "assert d==[], d"
expect_error "load --bag of a truncated bag" "DATA_LOSS" "$recog" load --bag "$tmp/truncated.bag" \
  --topic "$topic" --robots 1 --frames 1 "${server[@]}"

# Metric frames streamed: intrinsics and depth from the bag.
expect_ok "stream --bag with depth" "$recog" stream --map small --create --bag "$tmp/small.bag" \
  --topic "$topic" --camera-info-topic /camera/camera_info --depth-topic /camera/depth/image_raw \
  --json -q "${server[@]}"
/usr/bin/python3 -c "
import json; e=[json.loads(l) for l in open('$tmp/out')]
assert e[-1]['event']=='summary' and e[-1]['frames']==4 and e[-1]['errors']==0, e" \
  && pass || fail "stream --bag --depth-topic streams the 4 frames: $(cat "$tmp/out")"

# The bag's own pace: 4 frames 0.2 s apart take at least 0.6 s at speed 1, half at speed 2.
expect_ok "load --bag --bag-speed 1" "$recog" load --bag "$tmp/small.bag" --topic "$topic" \
  --robots 1 --frames 4 --bag-speed 1 --json -q "${server[@]}"
json_check "at the bag's pace" "assert d['frames_answered']==4 and d['wall_s']>=0.6 and d['options']['bag_speed']==1, d"
expect_ok "load --bag --bag-speed 2" "$recog" load --bag "$tmp/small.bag" --topic "$topic" \
  --robots 1 --frames 4 --bag-speed 2 --json -q "${server[@]}"
json_check "at twice the bag's pace" "assert d['frames_answered']==4 and 0.3<=d['wall_s']<0.6, d"
expect_ok "load --bag with depth --verify" "$recog" load --bag "$tmp/small.bag" --topic "$topic" \
  --camera-info-topic /camera/camera_info --depth-topic /camera/depth/image_raw --robots 2 \
  --frames 4 --verify --json -q "${server[@]}"
json_check "load --bag --verify" "assert d['verified'] and d['frames_answered']==8, d"

# The shared corridor as a bag: exactly its folder's loops, offline, streamed and under load.
corridor=$shared/places/corridor
if [ -d "$corridor/images" ]; then
  write_bag "$tmp/corridor.bag" --images "$corridor/images" --encoding jpeg --period 0.97
  write_bag "$tmp/corridor_mono8.bag" --images "$corridor/images" --encoding mono8 --period 0.97 \
    --compression lz4 --reverse
  expect_ok "eval place on the corridor's folder" "$recog" eval place --images "$corridor/images" \
    --ground-truth "$corridor/ground_truth.txt" --json -q
  mv "$tmp/out" "$tmp/folder.json"
  for bag in corridor corridor_mono8; do
    expect_ok "eval place on $bag.bag" "$recog" eval place --bag "$tmp/$bag.bag" --topic "$topic" \
      --ground-truth "$corridor/ground_truth.txt" --json -q
    /usr/bin/python3 -c "
import json
folder, bag = json.load(open('$tmp/folder.json')), json.load(open('$tmp/out'))
loops = lambda d: [(l['query'], l['match'], l['status'], l['inliers']) for l in d['loops']]
assert loops(bag) == loops(folder) and bag['correct'] == 36 and bag['detections'] == 36, (loops(bag), loops(folder))
assert abs(bag['recall'] - 36 / 44) < 1e-9 and bag['precision'] == 1 and bag['layout'] == 'bag', bag
assert bag['loops'][0]['query_file'].startswith('$bag.bag#'), bag['loops'][0]" \
      && pass || fail "eval place --bag $bag.bag gives exactly the folder's loops"
  done
  cp "$tmp/out" "$tmp/eval.json"
  expect_ok "stream --bag the corridor" "$recog" stream --map bag-corridor --create \
    --bag "$tmp/corridor_mono8.bag" --topic "$topic" --json -q "${server[@]}"
  /usr/bin/python3 -c "
import json
events = [json.loads(l) for l in open('$tmp/out')]
streamed = [(e['frame'], e['match']) for e in events if e['event'] == 'loop']
d = json.load(open('$tmp/eval.json'))
evaluated = [(l['query'] - 1, l['match'] - 1) for l in d['loops'] if l['status'] == 'loop_detected']
assert events[-1]['frames'] == 84 and len(evaluated) == 36 and streamed == evaluated, (streamed, evaluated)" \
    && pass || fail "stream --bag finds exactly the loops of eval place"
  expect_ok "load --bag --verify on the corridor" "$recog" load --bag "$tmp/corridor.bag" \
    --topic "$topic" --robots 2 --frames 84 --verify --json -q "${server[@]}"
  json_check "load --bag --verify on the corridor" \
    "assert d['verified'] and d['loops']==72 and all(r['verification']['offline_loops']==36 for r in d['robots']), d"
else
  skip_shared "the shared corridor: $corridor/images not found (set RECOG_SHARED_DATA)"
fi

kill -TERM "$server_pid"
wait "$server_pid"
code=$?
server_pid=
[ "$code" -eq 0 ] && pass || fail "recogd exits 0 on SIGTERM (exit $code): $(tail -5 "$tmp/recogd.log")"

report_and_exit

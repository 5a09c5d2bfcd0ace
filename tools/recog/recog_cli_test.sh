#!/usr/bin/env bash
# End-to-end test of the recog binary: every subcommand on good input, and a one-line error on bad
# input with exit status 1 (the command refuses it) or 2 (the command line parser does).
# Usage: recog_cli_test.sh RECOG_BINARY PROJECT_DIR
set -u
recog=$1
project=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# shellcheck source=cli_test_lib.sh
source "$(dirname "$0")/cli_test_lib.sh"

images=$project/tests/data/corridor

expect_ok "top-level help" "$recog" --help
for sub in "vocab train" "vocab info" "vocab convert" "bow" "demo"; do
  # shellcheck disable=SC2086
  expect_ok "help of $sub" "$recog" $sub --help
done
expect_version "--version" recog "$recog" --version
# Usage errors (the command line) exit 2, errors of the command on its input exit 1.
expect_usage_error "no subcommand" "subcommand" "$recog"
expect_usage_error "unknown subcommand" "recog" "$recog" frobnicate
expect_usage_error "unknown flag" "--frobnicate" "$recog" vocab info --frobnicate "$tmp/v.rvoc"
expect_usage_error "train without images" "images" "$recog" vocab train -o "$tmp/v.rvoc"
expect_usage_error "a bad value" "--k" "$recog" vocab train --images "$images" --k many -o "$tmp/v.rvoc"
expect_error "train on a missing folder" "NOT_FOUND" "$recog" vocab train --images "$tmp/none" -o "$tmp/v.rvoc"
expect_error "train with k=1" "INVALID_ARGUMENT" "$recog" vocab train --images "$images" --k 1 -o "$tmp/v.rvoc"

expect_ok "train a small vocabulary" "$recog" vocab train --images "$images" --k 5 --levels 3 \
  --features 300 --threads 2 --seed 7 -q -o "$tmp/v.rvoc"
grep -q "words" "$tmp/out" && pass || fail "train prints a summary"
expect_ok "train again with one thread" "$recog" vocab train --images "$images" --k 5 --levels 3 \
  --features 300 --threads 1 --seed 7 -q -o "$tmp/v1.rvoc"
cmp -s "$tmp/v.rvoc" "$tmp/v1.rvoc" && pass || fail "training is deterministic across thread counts"

expect_ok "train a float (SIFT, L2 k-means) vocabulary" "$recog" vocab train --images "$images" \
  --feature-type sift --k 4 --levels 2 --features 200 --threads 2 -q -o "$tmp/sift.rvoc"
"$recog" vocab info --json "$tmp/sift.rvoc" >"$tmp/sift.json" 2>/dev/null
grep -q '"descriptor": "float-128"' "$tmp/sift.json" && pass || fail "SIFT vocabulary has float-128 descriptors"
expect_ok "bow with the SIFT vocabulary" "$recog" bow "$images/1.jpg" --vocab "$tmp/sift.rvoc"
expect_error "DBoW2 export of a float vocabulary" "INVALID_ARGUMENT" "$recog" vocab convert "$tmp/sift.rvoc" "$tmp/sift.txt"

expect_ok "info --json" "$recog" vocab info --json "$tmp/v.rvoc"
/usr/bin/python3 -c "import json,sys; d=json.load(open('$tmp/out')); assert d['k']==5 and d['levels']==3 and d['words']>0, d" \
  && pass || fail "info --json is valid JSON with k, levels, words"

expect_ok "convert to DBoW2 text" "$recog" vocab convert "$tmp/v.rvoc" "$tmp/v.txt"
expect_ok "convert back" "$recog" vocab convert "$tmp/v.txt" "$tmp/back.rvoc"
"$recog" bow "$images/41.jpg" --vocab "$tmp/v.rvoc" --json >"$tmp/a.json" 2>/dev/null
"$recog" bow "$images/41.jpg" --vocab "$tmp/back.rvoc" --json >"$tmp/b.json" 2>/dev/null
/usr/bin/python3 -c "
import json; a=json.load(open('$tmp/a.json')); b=json.load(open('$tmp/b.json'))
assert a['features']>0 and a['bow']==b['bow'], 'bow differs after DBoW2 round trip'" \
  && pass || fail "bow is the same after a DBoW2 text round trip"

printf 'not a vocabulary' >"$tmp/garbage.rvoc"
expect_error "info on garbage" "DATA_LOSS" "$recog" vocab info "$tmp/garbage.rvoc"
head -c 200 "$tmp/v.rvoc" >"$tmp/cut.rvoc"
expect_error "info on a truncated file" "truncated" "$recog" vocab info "$tmp/cut.rvoc"
expect_error "info on a missing file" "NOT_FOUND" "$recog" vocab info "$tmp/none.rvoc"
expect_error "convert to an unknown format" "unknown output format" "$recog" vocab convert "$tmp/v.rvoc" "$tmp/x" --to jpeg
printf 'garbage' >"$tmp/garbage.jpg"
expect_error "bow of a corrupt image" "INVALID_ARGUMENT" "$recog" bow "$tmp/garbage.jpg" --vocab "$tmp/v.rvoc"
expect_error "bow of a missing image" "NOT_FOUND" "$recog" bow "$tmp/none.jpg" --vocab "$tmp/v.rvoc"

expect_ok "demo with the small vocabulary" "$recog" demo --vocab "$tmp/v.rvoc"
grep -q "41.jpg" "$tmp/out" && pass || fail "demo lists the frames"

# seqgen: a tiny sequence (4 places x 2 frames + 2 revisits x 2 frames = 12 frames).
expect_ok "help of seqgen" "$recog" seqgen --help
expect_ok "seqgen a tiny sequence" "$recog" seqgen --images "$images" -o "$tmp/seq" --places 4 \
  --allow-duplicate-places --frames-per-place 2 --revisit-fraction 0.5 --width 160 --height 120 --seed 3 -q
[ -f "$tmp/seq/images/000001.png" ] && [ -f "$tmp/seq/images/000012.png" ] && [ ! -e "$tmp/seq/images/000013.png" ] \
  && pass || fail "seqgen writes frames 000001.png .. 000012.png"
[ "$(wc -l <"$tmp/seq/ground_truth.txt")" -eq 12 ] && [ "$(awk '{print NF}' "$tmp/seq/ground_truth.txt" | sort -u)" = "12" ] \
  && pass || fail "seqgen writes a 12 x 12 dense ground truth"
[ "$(grep -c 1 "$tmp/seq/ground_truth.txt")" -eq 4 ] && pass || fail "seqgen ground truth has 4 query frames with matches"
expect_error "seqgen into a non-empty folder" "not empty" "$recog" seqgen --images "$images" -o "$tmp/seq" \
  --places 4 --allow-duplicate-places --frames-per-place 2 -q
# seqgen lens: the corridor frames (512x384) through a fisheye, as PNG of the same names and size.
expect_ok "seqgen lens through an equidistant fisheye" "$recog" seqgen lens --images "$images" \
  -o "$tmp/fisheye" --source-camera 400,400,255.5,191.5 --camera equidistant:300,300,255.5,191.5,0,0,0,0 -q
[ "$(ls "$tmp/fisheye" | wc -l)" -eq "$(ls "$images" | wc -l)" ] && [ -f "$tmp/fisheye/1.png" ] \
  && [ "$(od -An -tx1 -j12 -N12 "$tmp/fisheye/1.png" | tr -d ' \n')" = "494844520000020000000180" ] \
  && pass || fail "seqgen lens writes every frame as PNG (IHDR) of the input's size, 512 x 384"
expect_error "seqgen lens with a lens of the wrong coefficient count" "equidistant takes fx,fy,cx,cy" \
  "$recog" seqgen lens --images "$images" -o "$tmp/fisheye2" --source-camera 400,400,255.5,191.5 \
  --camera equidistant:300,300,255.5,191.5,0.1 -q
[ -f "$tmp/seq/ground_truth.txt" ] && [ ! -e "$tmp/seq/images/000013.png" ] && pass || fail "seqgen rerun leaves the folder alone"
expect_ok "seqgen jpg, sparse truth, json" "$recog" seqgen --images "$images" -o "$tmp/seq2" --places 4 \
  --allow-duplicate-places --frames-per-place 2 --revisit-fraction 0.5 --width 160 --height 120 --format jpg --sparse-truth --json
/usr/bin/python3 -c "import json; d=json.load(open('$tmp/out')); assert d['frames']==12 and d['queries_with_matches']==4, d" \
  && pass || fail "seqgen --json reports 12 frames and 4 query frames with matches"
head -1 "$tmp/seq2/ground_truth.sparse.txt" | grep -qx "# recog sparse ground truth v1 12" && [ -f "$tmp/seq2/images/000012.jpg" ] \
  && pass || fail "seqgen writes JPEG frames and a sparse ground truth"
expect_error "seqgen with too few distinct scenes" "distinct" "$recog" seqgen --images "$images" -o "$tmp/seq3" --places 4 -q
expect_error "seqgen from a missing folder" "NOT_FOUND" "$recog" seqgen --images "$tmp/none" -o "$tmp/seq3"
expect_error "seqgen with a bad revisit fraction" "INVALID_ARGUMENT" "$recog" seqgen --images "$images" -o "$tmp/seq3" --revisit-fraction 1.5
expect_error "seqgen with an unknown format" "unknown image format" "$recog" seqgen --images "$images" -o "$tmp/seq3" --format gif
[ ! -e "$tmp/seq3" ] && pass || fail "seqgen creates nothing on bad input"

# seqgen rig: a front + rear rig out and back, 2 frames a leg, over 36 tiles of the photos.
photo_tiles "$images" "$tmp/tiles"
expect_ok "seqgen rig" "$recog" seqgen rig --images "$tmp/tiles" -o "$tmp/rig" --frames-per-leg 2 \
  --width 160 --height 120 --focal 80 --depth --json
json_check "seqgen rig writes 4 rig frames, 2 of them revisits" \
  "assert d['frames']==4 and d['revisiting_frames']==2 and d['cameras']==['front','rear'], d"
[ -f "$tmp/rig/rig.yaml" ] && [ "$(grep -vc '^#' "$tmp/rig/rear/rgb.txt")" -eq 4 ] \
  && [ -f "$tmp/rig/front/depth/000003.png" ] && [ "$(wc -l <"$tmp/rig/ground_truth.txt")" -eq 4 ] \
  && pass || fail "seqgen rig writes the rig file, a TUM folder per camera and the ground truth"
cat >"$tmp/side.yaml" <<'YAML'
cameras:
  - {name: left, width: 160, height: 120, fx: 90, fy: 90, cx: 79.5, cy: 59.5, distortion: [],
     body_from_camera: {rotation: [0, 0, -1, 0, 1, 0, 1, 0, 0], translation: [-0.2, 0, 0]}}
YAML
expect_ok "seqgen rig --rig" "$recog" seqgen rig --images "$tmp/tiles" -o "$tmp/rig_side" \
  --frames-per-leg 2 --rig "$tmp/side.yaml" --json
json_check "seqgen rig --rig drives the rig of the file" "assert d['cameras']==['left'], d"
[ -f "$tmp/rig_side/left/rgb/000003.png" ] && grep -q "name: left" "$tmp/rig_side/rig.yaml" \
  && pass || fail "seqgen rig --rig writes the file's camera"
sed 's/rotation: \[0, 0, -1,/rotation: [0, 0, 1,/' "$tmp/side.yaml" >"$tmp/mirror.yaml"
expect_error "seqgen rig with a reflected camera" "rig camera 'left'.* not a rotation" "$recog" \
  seqgen rig --images "$tmp/tiles" -o "$tmp/rig2" --rig "$tmp/mirror.yaml"
expect_error "seqgen rig with too few photos" "needs 28 photos, .* has 4" "$recog" seqgen rig \
  --images "$images" -o "$tmp/rig2" --frames-per-leg 2
expect_error "seqgen rig with one frame a leg" "frames_per_leg must be at least 2" "$recog" seqgen rig \
  --images "$tmp/tiles" -o "$tmp/rig2" --frames-per-leg 1
[ ! -e "$tmp/rig2" ] && pass || fail "seqgen rig creates nothing on bad input"

# Video files: recog reads them through its video module (librecog_video.so, next to it as built
# and as installed), which it loads only for a video or a camera; OpenCV's videoio is not among
# the libraries every run loads.
if ldd "$recog" | grep -q libopencv_videoio; then fail "recog links OpenCV's videoio"; else pass; fi
/usr/bin/python3 - "$tmp/corridor.avi" "$images" <<'PY' && pass || fail "write a video of three frames"
import sys, cv2
writer = cv2.VideoWriter(sys.argv[1], cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (512, 384))
for name in ("1.jpg", "20.jpg", "41.jpg"):
    writer.write(cv2.imread(sys.argv[2] + "/" + name))
writer.release()
PY
expect_ok "eval place on a video file" "$recog" eval place --images "$tmp/corridor.avi" --json -q
json_check "eval place reads the video's three frames" "assert d['frames']==3, d"
expect_error "a video without the video module" "video module .*missing.so" \
  env RECOG_VIDEO_MODULE="$tmp/missing.so" "$recog" eval place --images "$tmp/corridor.avi" -q
expect_error "a video module that is no shared library" "video module .*corridor.avi.*invalid ELF header" \
  env RECOG_VIDEO_MODULE="$tmp/corridor.avi" "$recog" eval place --images "$tmp/corridor.avi" -q
echo "not a video" >"$tmp/garbage.avi"
expect_error "eval place on a file that is no video" "neither a folder, an image list nor a video" \
  "$recog" eval place --images "$tmp/garbage.avi" -q

# eval place --rig: the rig sequence just written (4 rig frames), the control, and bad input.
expect_ok "eval place --rig" "$recog" eval place --rig "$tmp/rig" --ground-truth \
  "$tmp/rig/ground_truth.txt" --body-poses "$tmp/rig/body_poses.txt" --json -q
json_check "eval place --rig reads both cameras and scores rig frames" \
  "assert d['frames']==4 and d['cameras']==['front','rear'] and d['layout']=='plain' \
   and d['query_frames_with_truth']==2 and 'pose_error' in d and d['detections']==d['correct'] \
   and d['misses']==[] and sum(d['miss_reasons'].values())==0, d"
# The rig's misses: a truth that makes rig frame 4 revisit 1 instead of 2 (its loop is wrong), and
# 1000 inliers that no camera pair reaches (no candidate list, no rank, and no inliers kept).
printf '0 0 0 0\n0 0 0 0\n1 1 0 0\n1 0 0 0\n' >"$tmp/rig_gt_wrong.txt"
expect_ok "eval place --rig with a wrong loop" "$recog" eval place --rig "$tmp/rig" \
  --ground-truth "$tmp/rig_gt_wrong.txt" --json -q
json_check "eval place --rig says rig frame 4's loop to 2 is a wrong loop" "
assert [(m['query'], m['reason'], m['candidate'], m['true_rank']) for m in d['misses']] \
    == [(4, 'wrong_loop', 2, None)] and d['misses'][0]['inliers'] > 0, d['misses']"
printf 'min_inliers: 1000\nstrong_min_inliers: 1000\n' >"$tmp/rig_params.yaml"
expect_ok "eval place --rig with 1000 inliers" "$recog" eval place --rig "$tmp/rig" \
  --ground-truth "$tmp/rig/ground_truth.txt" --params "$tmp/rig_params.yaml" -q
if grep -q "^missed 2 of 2: failed geometry 2$" "$tmp/out" \
  && grep -q "^missed 3: failed geometry with [12]$" "$tmp/out"; then
  pass
else
  fail "eval place --rig sums up and lists the failed geometry: $(cat "$tmp/out")"
fi
# A report reproduces itself: its "parameters" (every setting, typed, and the rig's own) given
# back as --params over the default preset give the same report but for the timings.
same_but_timings() {  # DESCRIPTION A B: the two JSON reports are equal once timing_ms is dropped
  /usr/bin/python3 - "$2" "$3" <<'PYTHON' && pass || fail "$1"
import json, sys
def untimed(d):
    if isinstance(d, dict): return {k: untimed(v) for k, v in d.items() if k != 'timing_ms'}
    if isinstance(d, list): return [untimed(v) for v in d]
    return d
a, b = (untimed(json.load(open(path))) for path in sys.argv[1:])
assert a == b, {k: (a.get(k), b.get(k)) for k in set(a) | set(b) if a.get(k) != b.get(k)}
PYTHON
}
printf 'alpha: 0.2\nmax_verified_frames: 3\nmin_consistent_ratio: 0.8\n' >"$tmp/rig_own.yaml"
expect_ok "eval place --rig with the rig's own settings" "$recog" eval place --rig "$tmp/rig" \
  --ground-truth "$tmp/rig/ground_truth.txt" --params "$tmp/rig_own.yaml" --json -q
cp "$tmp/out" "$tmp/rig_report.json"
json_check "eval place --rig reports every setting and the rig's own" "
p = d['parameters']
assert (p['preset'], p['alpha'], p['max_verified_frames'], p['min_consistent_ratio']) \
    == ('default', 0.2, 3, 0.8), p
assert p['max_rotation_disagreement_deg'] == 3.0 and p['mutual'] is False and p['ratio'] == 0.6, p
assert (p['features'], p['scoring'], p['direct_index_levels_up']) == (1000, 'l1', 2), p
assert p['vocabulary'] == d['vocabulary'] and d['detections'] > 0, d"
expect_ok "eval place --rig given its report as --params" "$recog" eval place --rig "$tmp/rig" \
  --ground-truth "$tmp/rig/ground_truth.txt" --params "$tmp/rig_report.json" --json -q
same_but_timings "eval place --rig reproduces its report from it" "$tmp/rig_report.json" \
  "$tmp/out"
expect_ok "eval place --rig as text with its settings" "$recog" eval place --rig "$tmp/rig" \
  --params "$tmp/rig_own.yaml" -q
grep -qx "settings: preset default, alpha 0.2" "$tmp/out" && pass \
  || fail "eval place --rig prints the settings that differ from the preset: $(cat "$tmp/out")"
expect_error "eval place --images with a rig report's settings" \
  "rig_report.json': 'max_rotation_disagreement_deg' is a setting of --rig" "$recog" eval place \
  --images "$images" --params "$tmp/rig_report.json" -q
printf 'max_verified_frames: 0\n' >"$tmp/rig_bad_own.yaml"
expect_error "eval place --rig with no frame to verify" \
  "rig_bad_own.yaml': RigLoopParams.max_verified_frames = 0: must be >= 1" "$recog" eval place \
  --rig "$tmp/rig" --params "$tmp/rig_bad_own.yaml" -q
expect_ok "eval place --rig --cameras front" "$recog" eval place --rig "$tmp/rig/rig.yaml" \
  --cameras front --json -q
json_check "eval place --rig --cameras front keeps the front camera" \
  "assert d['cameras']==['front'] and d['frames']==4 and 'recall' not in d, d"
expect_error "eval place --rig with an unknown camera" "no camera 'side' .*front, rear" "$recog" \
  eval place --rig "$tmp/rig" --cameras side -q
expect_error "eval place with --rig and --images" "either --images or --rig" "$recog" eval place \
  --rig "$tmp/rig" --images "$images" -q
expect_error "eval place --body-poses without --rig" "need --rig" "$recog" eval place \
  --images "$images" --body-poses "$tmp/rig/body_poses.txt" -q
cp -r "$tmp/rig" "$tmp/rig_bad"
/usr/bin/python3 -c "import cv2, numpy; cv2.imwrite('$tmp/rig_bad/rear/rgb/000001.png', numpy.zeros((100, 100), numpy.uint8))"
expect_error "eval place --rig with an image of the wrong size" \
  "rig camera 'rear': '.*000001.png' is 100x100, its camera's images are 160x120" "$recog" eval \
  place --rig "$tmp/rig_bad" -q
expect_error "eval place --rig with a missing rig" "NOT_FOUND" "$recog" eval place \
  --rig "$tmp/no_such_rig" -q
printf '0.0 1 2 3 0 0 0 1\n0.5 not a pose\n' >"$tmp/bad_poses.txt"
expect_error "eval place --rig with a malformed trajectory" "bad_poses.txt' line 2: expected" \
  "$recog" eval place --rig "$tmp/rig" --body-poses "$tmp/bad_poses.txt" -q
head -n 3 "$tmp/rig/body_poses.txt" >"$tmp/short_poses.txt"
expect_error "eval place --rig with too few body poses" "body poses cover 2 frames but the rig sequence has 4" \
  "$recog" eval place --rig "$tmp/rig" --body-poses "$tmp/short_poses.txt" -q

# seqgen objects: a tiny poster sequence, a model of its face and eval sequence --truth.
mkdir -p "$tmp/object_photos" "$tmp/background_photos"
cp "$images/1.jpg" "$tmp/object_photos/" && cp "$images/20.jpg" "$images/60.jpg" "$tmp/background_photos/"
expect_ok "seqgen objects a tiny poster sequence" "$recog" seqgen objects --object-photos "$tmp/object_photos" \
  --background-photos "$tmp/background_photos" -o "$tmp/objseq" --frames 6 --training-views 1 --min-fraction 0.1 --json
/usr/bin/python3 -c "import json; d=json.load(open('$tmp/out')); assert d['frames']==6 and d['object']=='synthetic-poster' and d['camera']==[525,525,319.5,239.5], d" \
  && [ -f "$tmp/objseq/images/000006.png" ] && [ -f "$tmp/objseq/depth/000006.png" ] && [ -f "$tmp/objseq/masks/000006.png" ] \
  && [ -f "$tmp/objseq/faces/front.png" ] && [ -f "$tmp/objseq/views.txt" ] && grep -q "recog eval sequence" "$tmp/objseq/README.txt" \
  && pass || fail "seqgen objects writes frames, depth, masks, faces, views and a README"
expect_ok "model build of the sequence's poster" "$recog" model build --planar "$tmp/objseq/faces/front.png" \
  --width 0.3 --height 0.21 --name synthetic-poster -o "$tmp/objseq.robj"
expect_ok "eval sequence --truth --json" "$recog" eval sequence --models "$tmp/objseq.robj" --images "$tmp/objseq/images" \
  --camera 525,525,319.5,239.5 --expect synthetic-poster --truth "$tmp/objseq/truth.txt" --size-recall "$tmp/size" --json -q
/usr/bin/python3 -c "
import json
d = json.load(open('$tmp/out'))
s = d['size_recall']
assert set(s) == {'visible_frames', 'found', 'correct', 'recall', 'found_not_visible', 'other_objects',
                  'max_rotation_error_deg', 'max_translation_error', 'bins', 'csv', 'plot'}, s
assert set(s['bins'][0]) == {'area_lo', 'area_hi', 'median_area', 'frames', 'found', 'correct', 'recall',
                             'found_rate', 'median_rotation_error_deg', 'median_translation_error_m'}, s
assert s['bins'][-1]['frames'] > 0 and s['bins'][-1]['recall'] > 0, s
assert set(d['per_frame'][0]['truth']) == {'visible', 'area_fraction', 'found', 'correct_pose',
                                           'rotation_error_deg', 'translation_error_m'}, d['per_frame'][0]
assert open('$tmp/size.csv').readline().startswith('area_lo,area_hi,median_area,frames,found,correct,recall')
assert open('$tmp/size.png', 'rb').read(4) == b'\x89PNG'
" && pass || fail "eval sequence --truth reports recall per size bin (JSON, CSV, PNG)"
# eval sequence --poses: a pose list of frames 1-5 made from the truth (frame 6 has no pose),
# frame 2 excluded.
awk '$1 == "frame" && $2 != "000006.png" {
  sub(/[.]png$/, "", $2); line = $2; for (i = 6; i <= 17; ++i) line = line " " $i; print line }' \
  "$tmp/objseq/truth.txt" >"$tmp/objseq-poses.txt"
expect_ok "eval sequence --poses --json" "$recog" eval sequence --models "$tmp/objseq.robj" \
  --images "$tmp/objseq/images" --camera 525,525,319.5,239.5 --expect synthetic-poster \
  --poses "$tmp/objseq-poses.txt" --pose-errors "$tmp/pose_errors" --exclude 000002 --json -q
json_check "eval sequence --poses reports recall and pose errors over the frames with a pose" "
import csv
p = d['poses']
assert set(p) == {'frames_with_pose', 'frames_without_pose', 'found', 'recall', 'wrong_objects',
                  'median_rotation_error_deg', 'median_translation_error_m', 'correct_pose',
                  'max_rotation_error_deg', 'max_translation_error', 'csv', 'plot'}, p
assert p['frames_with_pose'] == 4 and p['frames_without_pose'] == 1, p
scored = [f for f in d['per_frame'] if not f.get('excluded') and f['frame'] != '000006.png']
found = [f for f in scored if 'synthetic-poster' in f['objects']]
assert p['found'] == len(found) and 0 <= p['correct_pose'] <= p['found'], p
assert abs(p['recall'] - p['found'] / 4) < 1e-12, p
assert p['wrong_objects'] == sum(o != 'synthetic-poster' for f in scored for o in f['objects']), p
assert all('rotation_error_deg' in f and 'translation_error_m' in f for f in found), found
assert all('rotation_error_deg' not in f for f in d['per_frame'] if f not in found), d['per_frame']
rows = list(csv.DictReader(open('$tmp/pose_errors.csv')))
assert [r['frame'] for r in rows] == ['1', '3', '4', '5'], rows
assert sum(r['found'] == '1' for r in rows) == p['found'], rows
assert sum(int(r['wrong_objects']) for r in rows) == p['wrong_objects'], rows
assert p['csv'] == '$tmp/pose_errors.csv' and open(p['plot'], 'rb').read(4) == b'\x89PNG', p
"
printf '# frame pose\n1 1 0 0 0 1 0 0 0 1 0 0\n' >"$tmp/garbage-poses.txt"
expect_error "eval sequence --poses of a malformed list" "INVALID_ARGUMENT.*garbage-poses.txt:2: .*12 fields" \
  "$recog" eval sequence --models "$tmp/objseq.robj" --images "$tmp/objseq/images" \
  --camera 525,525,319.5,239.5 --expect synthetic-poster --poses "$tmp/garbage-poses.txt" -q
expect_error "eval sequence --poses of a missing file" "NOT_FOUND" "$recog" eval sequence \
  --models "$tmp/objseq.robj" --images "$tmp/objseq/images" --camera 525,525,319.5,239.5 \
  --expect synthetic-poster --poses "$tmp/none.txt" -q
expect_usage_error "eval sequence with --poses and --truth" "excludes" "$recog" eval sequence \
  --models "$tmp/objseq.robj" --images "$tmp/objseq/images" --camera 525,525,319.5,239.5 \
  --expect synthetic-poster --poses "$tmp/objseq-poses.txt" --truth "$tmp/objseq/truth.txt" -q
# model build --rgbd-recording: the sequence's images/ and depth/, from frame 1's pose.
rec_args=(--camera 525,525,319.5,239.5 --box 0.3,0.21,0.02 --name synthetic-poster --no-images -q)
expect_ok "model build --rgbd-recording" "$recog" model build --rgbd-recording "$tmp/objseq" \
  --pose "$tmp/objseq-poses.txt" "${rec_args[@]}" -o "$tmp/rec.robj"
grep -Eq "^[1-9][0-9]* views \(000001[,0-9]*\); the object was found in [0-5] of the 5 frames that follow 000001\$" "$tmp/out" \
  && grep -q "^synthetic-poster: 3D object" "$tmp/out" && pass \
  || fail "model build --rgbd-recording prints the views it chose: $(cat "$tmp/out")"
mkdir -p "$tmp/rec-bad"
cp -r "$tmp/objseq/images" "$tmp/objseq/depth" "$tmp/rec-bad/"
rm "$tmp/rec-bad/depth/000003.png"
expect_error "model build --rgbd-recording with a frame without depth" "NOT_FOUND.*no depth image of frame 3" \
  "$recog" model build --rgbd-recording "$tmp/rec-bad" --pose "$tmp/objseq-poses.txt" "${rec_args[@]}" -o "$tmp/m.robj"
cp "$tmp/objseq/depth/000003.png" "$tmp/rec-bad/depth/"
cp "$tmp/objseq/masks/000001.png" "$tmp/rec-bad/depth/000001.png"
expect_error "model build --rgbd-recording with an 8-bit depth image" "INVALID_ARGUMENT.*must be CV_16UC1" \
  "$recog" model build --rgbd-recording "$tmp/rec-bad" --pose "$tmp/objseq-poses.txt" "${rec_args[@]}" -o "$tmp/m.robj"
expect_error "model build --rgbd-recording of a missing folder" "NOT_FOUND" "$recog" model build \
  --rgbd-recording "$tmp/none" --pose "$tmp/objseq-poses.txt" "${rec_args[@]}" -o "$tmp/m.robj"
expect_error "model build --rgbd-recording with a missing pose file" "NOT_FOUND" "$recog" model build \
  --rgbd-recording "$tmp/objseq" --pose "$tmp/none.txt" "${rec_args[@]}" -o "$tmp/m.robj"
expect_error "model build --rgbd-recording with a malformed pose file" "garbage-poses.txt:2: " "$recog" model build \
  --rgbd-recording "$tmp/objseq" --pose "$tmp/garbage-poses.txt" "${rec_args[@]}" -o "$tmp/m.robj"
grep -v '^000001 ' "$tmp/objseq-poses.txt" >"$tmp/later-poses.txt"
expect_error "model build --rgbd-recording without the first frame's pose" "NOT_FOUND.*no line for frame 1" \
  "$recog" model build --rgbd-recording "$tmp/objseq" --pose "$tmp/later-poses.txt" "${rec_args[@]}" -o "$tmp/m.robj"
expect_ok "model build --rgbd-recording --views" "$recog" model build --rgbd-recording "$tmp/objseq" \
  --pose "$tmp/objseq-poses.txt" --views 1,3 "${rec_args[@]}" -o "$tmp/views.robj"
expect_ok "model info of the --views model" "$recog" model info "$tmp/views.robj" --json
/usr/bin/python3 -c "import json; d=json.load(open('$tmp/out')); assert d['views']==2, d" \
  && pass || fail "model build --rgbd-recording --views 1,3 builds from two views"
expect_error "model build --rgbd-recording --views of a frame without a pose" "NOT_FOUND.*frame 1 has no pose" \
  "$recog" model build --rgbd-recording "$tmp/objseq" --pose "$tmp/later-poses.txt" --views 1 "${rec_args[@]}" -o "$tmp/m.robj"
expect_error "model build --rgbd-recording --views that are not frame numbers" "frame numbers" \
  "$recog" model build --rgbd-recording "$tmp/objseq" --pose "$tmp/objseq-poses.txt" --views 1.5 "${rec_args[@]}" -o "$tmp/m.robj"
expect_error "model build --rgbd-recording without --box" "needs --camera, --pose and --box" "$recog" model build \
  --rgbd-recording "$tmp/objseq" --pose "$tmp/objseq-poses.txt" --camera 525,525,319.5,239.5 -o "$tmp/m.robj"
expect_error "model build --rgbd-recording with --image" "go with --cad" "$recog" model build \
  --rgbd-recording "$tmp/objseq" --pose "$tmp/objseq-poses.txt" "${rec_args[@]}" \
  --image "$tmp/objseq/images/000001.png" -o "$tmp/m.robj"
expect_error "model build --rgbd-recording with --cad" "exactly one of" "$recog" model build \
  --rgbd-recording "$tmp/objseq" --cad "$tmp/none.cao" --pose "$tmp/objseq-poses.txt" "${rec_args[@]}" -o "$tmp/m.robj"
expect_error "model build --rgbd-recording with --depth-camera" "need --rgbd" "$recog" model build \
  --rgbd-recording "$tmp/objseq" --pose "$tmp/objseq-poses.txt" "${rec_args[@]}" \
  --depth-camera 525,525,319.5,239.5 --depth-from-color 1,0,0,0,1,0,0,0,1,0,0,0 -o "$tmp/m.robj"
expect_usage_error "model build --depth-scale without --rgbd-recording" "--depth-scale" "$recog" model build \
  --planar "$images/1.jpg" --width 0.64 --height 0.48 --depth-scale 1000 -o "$tmp/m.robj"
[ ! -e "$tmp/m.robj" ] && pass || fail "model build --rgbd-recording writes nothing on bad input"
expect_error "seqgen objects from a missing folder" "NOT_FOUND" "$recog" seqgen objects --object-photos "$tmp/none" \
  --background-photos "$tmp/background_photos" -o "$tmp/objseq2"
expect_error "seqgen objects with a bad size" "object width" "$recog" seqgen objects --object-photos "$tmp/object_photos" \
  --background-photos "$tmp/background_photos" -o "$tmp/objseq2" --object-width 0
expect_error "seqgen objects with a bad shape" "unknown object shape" "$recog" seqgen objects --object-photos "$tmp/object_photos" \
  --background-photos "$tmp/background_photos" -o "$tmp/objseq2" --shape sphere
[ ! -e "$tmp/objseq2" ] && pass || fail "seqgen objects creates nothing on bad input"
expect_error "eval sequence with a missing truth" "NOT_FOUND" "$recog" eval sequence --models "$tmp/objseq.robj" \
  --images "$tmp/objseq/images" --camera 525,525,319.5,239.5 --expect synthetic-poster --truth "$tmp/none.txt" -q

# recog eval place on the 4 bundled frames (41 revisits 1, 60 revisits 20).
printf '0 0 0 0\n0 0 0 0\n1 0 0 0\n0 1 0 0\n' >"$tmp/gt4.txt"
printf '0 0\n0 0\n' >"$tmp/gt_robot_a.txt"
expect_ok "eval place on the bundled frames" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/gt4.txt" --vocab "$tmp/v.rvoc" --json -q --sweep alpha --plot "$tmp/pr.png" \
  --draw "$tmp/draw"
/usr/bin/python3 -c "
import json; d=json.load(open('$tmp/out'))
for k in ['frames','query_frames_with_truth','detections','correct','precision','recall','loops','sweep']: assert k in d, k
for s in ['features','conversion','query','islands','insertion','verification','total']:
    assert set(d['timing_ms'][s]) == {'mean','median','max'}, s
assert d['frames'] == 4 and d['query_frames_with_truth'] == 2, d
assert d['parameters']['preset'] == 'default' and d['parameters']['strong_acceptance'], d['parameters']
for l in d['loops']: assert l['acceptance'] in ('none', 'temporal_consistency', 'strong_evidence'), l" \
  && pass || fail "eval place --json has the documented keys"
/usr/bin/python3 -c "
import csv, json; d=json.load(open('$tmp/out')); rows=list(csv.reader(open('$tmp/pr.csv')))
assert rows[0] == ['series', 'recall', 'precision', 'point_label'], rows[0]
assert len(rows) == 1 + len(d['sweep']), rows
for r, s in zip(rows[1:], d['sweep']):
    assert r[0] == 'geometry: ' + s['geometry'], (r, s)
    assert abs(float(r[1]) - s['recall']) < 1e-9 and abs(float(r[2]) - s['precision']) < 1e-9, (r, s)" \
  && pass || fail "eval place writes the PR curve's points beside the plot (pr.csv)"
expect_ok "eval place with the old --mode" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/gt4.txt" --vocab "$tmp/v.rvoc" --json -q --mode thesis
grep -q "^recog eval place: --mode is deprecated, use --preset thesis$" "$tmp/err" && pass \
  || fail "eval place --mode says it is deprecated: $(cat "$tmp/err")"
expect_ok "eval place with the thesis preset" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/gt4.txt" --vocab "$tmp/v.rvoc" --json -q --preset thesis
/usr/bin/python3 -c "
import json; d=json.load(open('$tmp/out'))
assert d['parameters']['preset'] == 'thesis' and not d['parameters']['strong_acceptance'], d['parameters']
assert all(l['acceptance'] != 'strong_evidence' for l in d['loops']), d['loops']" \
  && pass || fail "eval place --preset thesis turns strong acceptance off"
[ -s "$tmp/pr.png" ] && [ -d "$tmp/draw" ] && pass || fail "eval place writes the PR plot and the draw folder"
expect_ok "eval place --split (two robots)" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/gt4.txt" --split 2 --json -q
json_check "eval place --split finds robot B's revisits in robot A's map" "
assert d['robot_a_frames'] == [1, 2] and d['robot_b_frames'] == [3, 4], d
i = d['inter_map']; assert i['query_frames_with_truth'] == 2 and i['detections'] == i['correct'] == 1, i
found = [l for l in i['loops'] if l['status'] == 'loop_detected']
assert [(l['query'], l['match'], l['acceptance']) for l in found] == [(3, 1, 'relocalisation')], i['loops']
assert d['own_map']['query_frames_with_truth'] == 0 and d['own_map']['detections'] == 0, d['own_map']"
json_check "eval place --split says why B's 60 missed A's 20: RANSAC, under the 16 inliers needed" "
i = d['inter_map']; assert d['own_map']['misses'] == [] and len(i['misses']) == 1, d
assert i['miss_reasons']['failed_geometry'] == 1 and sum(i['miss_reasons'].values()) == 1, i
m = i['misses'][0]
assert (m['query'], m['reason'], m['status'], m['candidate'], m['true_candidate'], m['true_rank']) \
    == (4, 'failed_geometry', 'failed_geometry', 2, 2, 1), m
assert m['query_file'].endswith('/60.jpg') and m['candidate_file'].endswith('/20.jpg'), m
assert 0 < m['inliers'] < 16 and m['correspondences'] > m['inliers'], m"
expect_ok "eval place --split as text" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/gt4.txt" --split 2 -q
if grep -q "^inter-map missed 1 of 2: failed geometry 1 (median [0-9]* inliers of [0-9]* matches)$" \
  "$tmp/out" && grep -Eq \
  "^inter-map missed .*/60.jpg: failed geometry, [0-9]+ inliers of [0-9]+ matches with .*/20.jpg$" \
  "$tmp/out" && ! grep -q "^own missed" "$tmp/out"; then
  pass
else
  fail "eval place --split sums up and lists the inter-map miss: $(cat "$tmp/out")"
fi
# The same two robots as two sequences: robot A's frames 1.jpg and 20.jpg, robot B's 41.jpg and
# 60.jpg, the ground truth across both (B's frames numbered after A's).
printf '%s\n' "$images/1.jpg" "$images/20.jpg" >"$tmp/robot_a.txt"
printf '%s\n' "$images/41.jpg" "$images/60.jpg" >"$tmp/robot_b.txt"
expect_ok "eval place --robot-b (two sequences)" "$recog" eval place --images "$tmp/robot_a.txt" \
  --robot-b "$tmp/robot_b.txt" --ground-truth "$tmp/gt4.txt" --json -q
json_check "eval place --robot-b scores B's revisits of A's places" "
assert d['robot_a_frames'] == [1, 2] and d['robot_b_frames'] == [3, 4], d
i = d['inter_map']; assert i['query_frames_with_truth'] == 2 and i['detections'] == i['correct'] == 1, i"
# Why each revisit was missed, one reason a frame (`misses`, `miss_reasons`): the 4 frames in one
# map, each case with its settings and truth, and the reasons expected for 41 and 60 (frames 3
# and 4; none for a frame whose loop is correct).
printf '0 0 0 0\n0 0 0 0\n1 0 0 0\n1 0 0 0\n' >"$tmp/gt_both_at_1.txt"
printf '0 0 0 0\n0 0 0 0\n0 1 0 0\n0 1 0 0\n' >"$tmp/gt_both_at_20.txt"
expect_misses() {  # DESCRIPTION TRUTH PARAMS EXPECTED (a Python dict frame -> reason)
  printf '%b' "$3" >"$tmp/miss_params.yaml"
  expect_ok "eval place: $1" "$recog" eval place --images "$images" --ground-truth "$2" \
    --params "$tmp/miss_params.yaml" --json -q
  json_check "eval place: $1 ($4)" "
got = {m['query']: m['reason'] for m in d['misses']}; assert got == $4, d['misses']
counts = {r: list(got.values()).count(r) for r in d['miss_reasons']}
assert d['miss_reasons'] == counts and len(counts) == 7, d['miss_reasons']
assert len(d['misses']) == d['query_frames_with_truth'] - d['correct'], d"
}
expect_misses "tau_c's 20 frames leave nothing to query" "$tmp/gt4.txt" 'alpha: 0.3\n' \
  "{3: 'no_candidate', 4: 'no_candidate'}"
expect_misses "frames with too few features are not queried" "$tmp/gt4.txt" \
  'min_features: 100000\n' "{3: 'not_queried', 4: 'not_queried'}"
expect_misses "no candidate reaches alpha" "$tmp/gt4.txt" 'recent_frames: 0\nalpha: 100\n' \
  "{3: 'low_score', 4: 'low_score'}"
expect_misses "60 waits for a third consistent query" "$tmp/gt4.txt" 'recent_frames: 0\n' \
  "{4: 'not_consistent'}"
json_check "eval place: 60's true place is its best candidate" "
m = d['misses'][0]; assert (m['candidate'], m['true_rank'], m['inliers']) == (2, 1, None), m
assert m['status'] == 'failed_temporal_consistency' and m['consistent_queries'] >= 0, m"
no_tau_c='recent_frames: 0\ntemporal_matches: 0\n'
expect_misses "1000 inliers fail 41 -> 1; 60's best, 20, is no true place" "$tmp/gt_both_at_1.txt" \
  "${no_tau_c}min_inliers: 1000\nstrong_min_inliers: 1000\n" \
  "{3: 'failed_geometry', 4: 'wrong_top_candidate'}"
json_check "eval place: 60's first true place, 1, is ranked third" "
m = {m['query']: m for m in d['misses']}
assert (m[3]['candidate'], m[3]['true_rank']) == (1, 1) and m[3]['correspondences'] > 0, m[3]
assert (m[4]['candidate'], m[4]['true_candidate'], m[4]['true_rank']) == (2, 1, 3), m[4]
assert m[4]['candidate_file'].endswith('/20.jpg') and m[4]['true_candidate_file'].endswith('/1.jpg'), m[4]"
expect_misses "a loop 41 -> 1 where the truth says 20 is a wrong loop" "$tmp/gt_both_at_20.txt" \
  "$no_tau_c" "{3: 'wrong_loop'}"
json_check "eval place: the wrong loop's true place ranked second" "
m = d['misses'][0]; assert (m['candidate'], m['true_candidate'], m['true_rank']) == (1, 2, 2), m
assert m['inliers'] > 0 and m['status'] == 'loop_detected', m"
printf '%b' "$no_tau_c" >"$tmp/miss_params.yaml"
expect_ok "eval place lists a wrong loop as a miss" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/gt_both_at_20.txt" --params "$tmp/miss_params.yaml" -q
if grep -q "^missed 1 of 2: wrong loop 1$" "$tmp/out" && grep -Eq "^missed .*/41.jpg: wrong loop \
to .*/1.jpg, [0-9]+ inliers of [0-9]+ matches, a true place at rank 2 \(.*/20.jpg\)$" "$tmp/out"; then
  pass
else
  fail "eval place sums up and lists the misses: $(cat "$tmp/out")"
fi
# The report of one map and of two: every setting (typed) with the evaluation's own, and given
# back as --params (over the default preset) the same report but for the timings; its vocabulary
# is skipped (--vocab's is used), other keys are settings.
printf 'preset: thesis\nrecent_frames: 0\ntemporal_matches: 0\nratio: 0.7\nfeatures: 800\nscoring: l2\n' \
  >"$tmp/replay.yaml"
expect_ok "eval place with settings over the thesis preset" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/gt4.txt" --vocab "$tmp/v.rvoc" --params "$tmp/replay.yaml" --json -q
cp "$tmp/out" "$tmp/report.json"
json_check "eval place --json lists every setting, typed, and the evaluation's own" "
p = d['parameters']
assert (p['preset'], p['recent_frames'], p['temporal_matches'], p['ratio']) == ('thesis', 0, 0, 0.7), p
assert (p['features'], p['scoring'], p['direct_index_levels_up']) == (800, 'l2', 2), p
assert p['strong_acceptance'] is False and p['geometry'] == 'direct_index', p
assert p['min_inliers'] == 12 and p['calibrated_min_spread'] == 0.125 and p['mutual'] is False, p
assert p['vocabulary'].endswith('/v.rvoc') and 'max_verified_frames' not in p, p
assert d['detections'] > 0, d"
expect_ok "eval place given its report as --params" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/gt4.txt" --vocab "$tmp/v.rvoc" --params "$tmp/report.json" --json -q
same_but_timings "eval place reproduces its report from it" "$tmp/report.json" "$tmp/out"
expect_ok "eval place as text with its settings" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/gt4.txt" --vocab "$tmp/v.rvoc" --params "$tmp/report.json" -q
grep -qx "settings: preset thesis, temporal_matches 0, recent_frames 0, ratio 0.7" "$tmp/out" \
  && pass || fail "eval place prints the settings that differ from the preset: $(cat "$tmp/out")"
expect_ok "eval place --split with settings" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/gt4.txt" --split 2 --params "$tmp/replay.yaml" --json -q
cp "$tmp/out" "$tmp/split_report.json"
json_check "eval place --split reports every setting" "
p = d['parameters']; assert (p['preset'], p['ratio'], p['features']) == ('thesis', 0.7, 800), p"
expect_ok "eval place --split given its report as --params" "$recog" eval place \
  --images "$images" --ground-truth "$tmp/gt4.txt" --split 2 --params "$tmp/split_report.json" \
  --json -q
same_but_timings "eval place --split reproduces its report from it" "$tmp/split_report.json" \
  "$tmp/out"
printf '{"parameters": [1, 2]}\n' >"$tmp/bad_report.json"
expect_error "eval place --params with a report whose parameters are no map" \
  "bad_report.json': 'parameters' is not a map" "$recog" eval place --images "$images" \
  --params "$tmp/bad_report.json" -q
printf 'vocabulary: %s\n' "$tmp/v.rvoc" >"$tmp/vocabulary_setting.yaml"
expect_error "eval place --params naming a vocabulary outside a report" \
  "unknown setting 'vocabulary'" "$recog" eval place --images "$images" \
  --params "$tmp/vocabulary_setting.yaml" -q
expect_error "eval place --robot-b with a ground truth of A's frames only" "INVALID_ARGUMENT" \
  "$recog" eval place --images "$tmp/robot_a.txt" --robot-b "$tmp/robot_b.txt" \
  --ground-truth "$tmp/gt_robot_a.txt" -q
expect_usage_error "eval place --robot-b with --split" "--split" "$recog" eval place \
  --images "$tmp/robot_a.txt" --robot-b "$tmp/robot_b.txt" --ground-truth "$tmp/gt4.txt" --split 1 -q
expect_error "eval place --robot-b of a missing folder" "NOT_FOUND" "$recog" eval place \
  --images "$tmp/robot_a.txt" --robot-b "$tmp/nowhere" --ground-truth "$tmp/gt4.txt" -q
expect_error "eval place --split without a ground truth" "--split needs --ground-truth" \
  "$recog" eval place --images "$images" --split 2 -q
expect_error "eval place --split that leaves robot B no frame" "INVALID_ARGUMENT.*split" \
  "$recog" eval place --images "$images" --ground-truth "$tmp/gt4.txt" --split 4 -q
expect_usage_error "eval place --split 0" "--split" \
  "$recog" eval place --images "$images" --ground-truth "$tmp/gt4.txt" --split 0 -q
expect_error "eval place --plot naming a .csv" "INVALID_ARGUMENT.*another extension" "$recog" eval place \
  --images "$images" --ground-truth "$tmp/gt4.txt" --vocab "$tmp/v.rvoc" -q --sweep alpha --plot "$tmp/pr.csv"
expect_error "eval place without ground truth file" "NOT_FOUND" "$recog" eval place --images "$images" \
  --ground-truth "$tmp/none.txt" -q
printf '0 0\n1 0\n' >"$tmp/gt2.txt"
expect_error "eval place with a ground truth of another length" "INVALID_ARGUMENT" "$recog" eval place \
  --images "$images" --ground-truth "$tmp/gt2.txt" --vocab "$tmp/v.rvoc" -q
printf '0 0 0\n1 0\n' >"$tmp/gtbad.txt"
expect_error "eval place with a malformed ground truth" "DATA_LOSS" "$recog" eval place \
  --images "$images" --ground-truth "$tmp/gtbad.txt" -q
printf 'alpha: 0.3\nalpah: 0.2\n' >"$tmp/params.yaml"
expect_error "eval place with an unknown parameter" "unknown setting 'alpah'" "$recog" eval place \
  --images "$images" --ground-truth "$tmp/gt4.txt" --params "$tmp/params.yaml" -q
printf 'geometry: homography\n' >"$tmp/params2.yaml"
expect_error "eval place with an unknown geometry check" "INVALID_ARGUMENT" "$recog" eval place \
  --images "$images" --ground-truth "$tmp/gt4.txt" --params "$tmp/params2.yaml" -q
expect_error "eval place with an unsupported sweep" "only supports" "$recog" eval place \
  --images "$images" --ground-truth "$tmp/gt4.txt" --sweep k -q
expect_error "eval place with an unknown preset" "setting preset = 'dloop'" "$recog" eval place \
  --images "$images" --ground-truth "$tmp/gt4.txt" --preset dloop -q
printf 'ratio: nan\n' >"$tmp/params3.yaml"
expect_error "eval place with a NaN ratio" "setting ratio = 'nan'" "$recog" eval place \
  --images "$images" --ground-truth "$tmp/gt4.txt" --params "$tmp/params3.yaml" -q
expect_usage_error "eval place with --mode and --preset" "excludes" "$recog" eval place \
  --images "$images" --ground-truth "$tmp/gt4.txt" --mode thesis --preset thesis -q

# A TUM RGB-D folder (the 4 bundled frames, 30 s apart), without a ground truth.
mkdir -p "$tmp/tum/rgb" && t=0
for f in 1 20 41 60; do t=$((t + 30)); cp "$images/$f.jpg" "$tmp/tum/rgb/"; echo "$t.5 rgb/$f.jpg" >>"$tmp/tum/rgb.txt"; done
expect_ok "eval place on a TUM folder without ground truth" "$recog" eval place --images "$tmp/tum" \
  --vocab "$tmp/v.rvoc" --json -q
/usr/bin/python3 -c "
import json; d=json.load(open('$tmp/out'))
assert d['layout'] == 'tum' and d['frames'] == 4 and d['ground_truth'] is None, d
assert 'precision' not in d and 'recall' not in d and 'misses' not in d, d" \
  && pass || fail "eval place --json names the layout and leaves precision out without ground truth"
expect_ok "eval place on a TUM folder without depth, with --camera" "$recog" eval place \
  --images "$tmp/tum" --camera 525,525,319.5,239.5 --json -q
/usr/bin/python3 -c "
import json; d = json.load(open('$tmp/out'))
assert d['frames'] == 4 and 'points' in d['timing_ms'], d['timing_ms'].keys()
assert all('metric' not in l for l in d['loops']), d['loops']
" && pass || fail "eval place --camera times the 3D points (none without depth images)"
expect_error "eval place --baseline without --camera" "need --camera" "$recog" eval place \
  --images "$tmp/tum" --baseline 0.1 -q
expect_usage_error "eval place with a bad --camera" "--camera" "$recog" eval place \
  --images "$tmp/tum" --camera 525,x,319.5,239.5 -q
expect_error "eval place with a layout the folder lacks" "times.txt" "$recog" eval place \
  --images "$tmp/tum" --layout kitti -q
expect_error "eval place with an unknown layout" "unknown dataset layout" "$recog" eval place \
  --images "$tmp/tum" --layout rosbag -q
echo "999.5 rgb/missing.jpg" >>"$tmp/tum/rgb.txt"
expect_error "eval place on a TUM list naming a missing image" "missing.jpg" "$recog" eval place \
  --images "$tmp/tum" -q

# Object models: a planar poster built from one bundled frame, recognised in that same frame.
for sub in "model build" "model info" "model export" "recognize" "eval objects"; do
  # shellcheck disable=SC2086
  expect_ok "help of $sub" "$recog" $sub --help
done
expect_ok "model build of a planar poster" "$recog" model build --planar "$images/1.jpg" \
  --width 0.64 --height 0.48 --name poster -o "$tmp/poster.robj"
expect_ok "model info --json" "$recog" model info "$tmp/poster.robj" --json
/usr/bin/python3 -c "import json; d=json.load(open('$tmp/out')); assert d['type']=='planar' and d['name']=='poster' and d['views']==1, d" \
  && pass || fail "model info --json shows a planar model named poster"
expect_ok "recognize the poster in its own image" "$recog" recognize --models "$tmp/poster.robj" \
  --image "$images/1.jpg" --camera 500,500,256,192 --json --draw "$tmp/poster.png"
/usr/bin/python3 -c "import json; d=json.load(open('$tmp/out')); assert [x['name'] for x in d['detections']]==['poster'], d" \
  && pass || fail "recognize --json reports the poster"
/usr/bin/python3 -c "assert open('$tmp/poster.png', 'rb').read(8) == b'\\x89PNG\\r\\n\\x1a\\n'" \
  && pass || fail "recognize --draw writes a PNG"
/usr/bin/python3 -c "import json; d=json.load(open('$tmp/out')); assert all('inliers_2d3d' not in x and 'covariance' not in x for x in d['detections']), d" \
  && pass || fail "recognize --json has no inliers or covariance unless asked"
expect_ok "recognize --inliers --covariance" "$recog" recognize --models "$tmp/poster.robj" \
  --image "$images/1.jpg" --camera 500,500,256,192 --json --inliers --covariance
/usr/bin/python3 -c "import json; x=json.load(open('$tmp/out'))['detections'][0]; i=x['inliers_2d3d']; assert len(i)==x['inliers'] and all(len(c['pixel'])==2 and len(c['point'])==3 and c['point_id']>=0 for c in i) and len(x['covariance'])==36 and all(x['covariance'][k*7]>0 for k in range(6)), x" \
  && pass || fail "recognize --json --inliers --covariance reports inliers_2d3d and covariance"
expect_ok "recognize --explain" "$recog" recognize --models "$tmp/poster.robj" \
  --image "$images/1.jpg" --camera 500,500,256,192 --json --explain
/usr/bin/python3 -c "import json; e=json.load(open('$tmp/out'))['explanation']; assert [(x['name'], x['outcome']) for x in e]==[('poster', 'detected')] and e[0]['inliers']>=e[0]['min_inliers'] and e[0]['regions']>=1, e" \
  && pass || fail "recognize --json --explain says the poster was detected"
/usr/bin/python3 -c "
import struct, zlib
w, h = 320, 240
def chunk(kind, data):
    return struct.pack('>I', len(data)) + kind + data + struct.pack('>I', zlib.crc32(kind + data))
rows = b''.join(b'\\x00' + b'\\x80' * w for _ in range(h))
open('$tmp/blank.png', 'wb').write(b'\\x89PNG\\r\\n\\x1a\\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', w, h, 8, 0, 0, 0, 0))
    + chunk(b'IDAT', zlib.compress(rows)) + chunk(b'IEND', b''))"
expect_ok "recognize --explain of a blank image" "$recog" recognize --models "$tmp/poster.robj" \
  --image "$tmp/blank.png" --camera 500,500,256,192 --explain
grep -q "^no object recognised\$" "$tmp/out" && grep -q "^poster: not_proposed (proposed by 0 regions" "$tmp/out" \
  && pass || fail "recognize --explain says why nothing was found: $(cat "$tmp/out")"
expect_error "model build without a source" "exactly one of" "$recog" model build -o "$tmp/m.robj"
expect_error "model build with two sources" "exactly one of" "$recog" model build --planar "$images/1.jpg" \
  --rgbd "$tmp/views.txt" --width 0.64 --height 0.48 -o "$tmp/m.robj"
expect_error "model build of a missing image" "NOT_FOUND" "$recog" model build --planar "$tmp/none.jpg" \
  --width 0.64 --height 0.48 -o "$tmp/m.robj"
expect_error "model build with a negative width" "INVALID_ARGUMENT" "$recog" model build \
  --planar "$images/1.jpg" --width -0.64 --height 0.48 -o "$tmp/m.robj"
[ ! -e "$tmp/m.robj" ] && pass || fail "model build writes nothing on bad input"
# RGB-D: a 512 x 384 view of the bundled frame with a constant depth of 1 m and a black mask.
/usr/bin/python3 - "$tmp" <<'PY'
import struct, sys, zlib
def png(path, depth_bits, value):
    w, h = 512, 384
    row = b"\0" + (struct.pack(">H", value) if depth_bits == 16 else bytes([value])) * w
    chunk = lambda t, d: struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))
    open(path, "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth_bits, 0, 0, 0, 0))
                           + chunk(b"IDAT", zlib.compress(row * h)) + chunk(b"IEND", b""))
png(sys.argv[1] + "/depth.png", 16, 1000)
png(sys.argv[1] + "/black.png", 8, 0)
PY
cp "$images/1.jpg" "$tmp/rgb.jpg"
echo "rgb.jpg depth.png 500 500 256 192 1000 1 0 0 0 1 0 0 0 1 0 0 1 black.png" >"$tmp/rgbd.txt"
expect_error "model build of RGB-D views with a black mask" "'rgb' gives no object point" \
  "$recog" model build --rgbd "$tmp/rgbd.txt" -o "$tmp/m.robj"
expect_error "model build --box without --rgbd" "--box needs --rgbd or --rgbd-recording" "$recog" model build \
  --planar "$images/1.jpg" --width 0.64 --height 0.48 --box 0.1,0.1,0.1 -o "$tmp/m.robj"
expect_usage_error "model build with a bad --box" "--box" "$recog" model build \
  --rgbd "$tmp/rgbd.txt" --box 0.1,-0.1,0.1 -o "$tmp/m.robj"
expect_usage_error "model build with a bad --depth-camera" "--depth-camera" "$recog" model build \
  --rgbd "$tmp/rgbd.txt" --depth-camera 500,x,256,192 -o "$tmp/m.robj"
expect_usage_error "model build with a fisheye --depth-camera" "radtan lenses only.*not equidistant" "$recog" model build \
  --rgbd "$tmp/rgbd.txt" --depth-camera equidistant:500,500,256,192,0.1,0,0,0 -o "$tmp/m.robj"
expect_usage_error "model build with a --depth-from-color that is no rotation" "rotation" \
  "$recog" model build --rgbd "$tmp/rgbd.txt" --depth-camera 500,500,256,192 \
  --depth-from-color 2,0,0,0,1,0,0,0,1,0,0,0 -o "$tmp/m.robj"
expect_error "model build with --depth-camera alone" "go together" "$recog" model build \
  --rgbd "$tmp/rgbd.txt" --depth-camera 500,500,256,192 -o "$tmp/m.robj"
echo "rgb.jpg depth.png 500 500 256 192 1000 1 0 0 0 1 0 0 0 1 0 0 1" >"$tmp/rgbd-box.txt"
expect_ok "model build of RGB-D views with a box and a depth camera" "$recog" model build \
  --rgbd "$tmp/rgbd-box.txt" --box 0.8,0.6,0.1 --depth-camera 500,500,256,192 \
  --depth-from-color 1,0,0,0,1,0,0,0,1,0,0,0 --no-images -o "$tmp/rgbd.robj"
expect_ok "model info of the RGB-D model" "$recog" model info "$tmp/rgbd.robj" --json
/usr/bin/python3 -c "import json; d=json.load(open('$tmp/out')); assert d['points']>100 and d['dimensions'][2]<0.01 and d['dimensions'][0]<0.8, d" \
  && pass || fail "the RGB-D model is flat and inside its box"
expect_error "model info of a missing file" "NOT_FOUND" "$recog" model info "$tmp/none.robj"
head -c 100 "$tmp/poster.robj" >"$tmp/cut.robj"
expect_error "model info of a truncated file" "DATA_LOSS" "$recog" model info "$tmp/cut.robj"
expect_error "recognize with a malformed camera" "--camera" "$recog" recognize --models "$tmp/poster.robj" \
  --image "$images/1.jpg" --camera 1,2,3
expect_error "recognize with a missing model" "NOT_FOUND" "$recog" recognize --models "$tmp/none.robj" \
  --image "$images/1.jpg" --camera 500,500,256,192
# --camera takes calibration files (docs/cli.md, "Cameras"): a Kalibr camchain's pinhole camera as
# the numbers above; its omni camera refused by name, and a file that does not exist.
printf '%s\n' 'cam0:' '  camera_model: pinhole' '  distortion_model: none' \
  '  intrinsics: [500, 500, 256, 192]' '  resolution: [512, 384]' 'cam1:' '  camera_model: omni' \
  '  distortion_model: radtan' '  distortion_coeffs: [-0.1, 0.01, 0, 0]' \
  '  intrinsics: [0.8, 500, 500, 256, 192]' '  resolution: [512, 384]' >"$tmp/camchain.yaml"
expect_ok "recognize with a Kalibr camchain's camera" "$recog" recognize \
  --models "$tmp/poster.robj" --image "$images/1.jpg" --camera "$tmp/camchain.yaml" --json
/usr/bin/python3 -c "import json; d=json.load(open('$tmp/out')); assert [x['name'] for x in d['detections']]==['poster'], d" \
  && pass || fail "recognize --camera CAMCHAIN reports the poster"
expect_error "recognize with a Kalibr omni camera" "cam1: camera_model 'omni' with distortion_model 'radtan' is not supported" \
  "$recog" recognize --models "$tmp/poster.robj" --image "$images/1.jpg" --camera "$tmp/camchain.yaml#cam1"
expect_error "recognize with a missing calibration file" "NOT_FOUND.*none.yaml' does not exist" \
  "$recog" recognize --models "$tmp/poster.robj" --image "$images/1.jpg" --camera "$tmp/none.yaml"
expect_error "eval objects on a missing folder" "NOT_FOUND" "$recog" eval objects --roboearth /nonexistent -q
expect_error "eval objects with an unknown method" "INVALID_ARGUMENT.*independent-views" "$recog" eval objects \
  --roboearth /nonexistent --method views -q
# A poster's training view is a frontal camera with the principal point at the image corner.
expect_error "model export of a camera RoboEarth cannot express" "principal point" "$recog" model export \
  "$tmp/poster.robj" --roboearth "$tmp/poster-export"
expect_error "model export of a missing file" "NOT_FOUND" "$recog" model export "$tmp/none.robj" \
  --roboearth "$tmp/none-export"
[ ! -e "$tmp/poster-export" ] && [ ! -e "$tmp/none-export" ] && pass || fail "model export creates nothing on bad input"

# A real RoboEarth model through build, export and build again (needs the shared data).
shared=${RECOG_SHARED_DATA:-$project/../shared/data}
if [ -d "$shared/objects/roboearth/models/box" ]; then
  expect_ok "model build of the RoboEarth box" "$recog" model build \
    --roboearth "$shared/objects/roboearth/models/box" -o "$tmp/box.robj"
  expect_ok "model export of the box" "$recog" model export "$tmp/box.robj" --roboearth "$tmp/export/box"
  [ -f "$tmp/export/box/meta.xml" ] && [ -f "$tmp/export/box/face_014.png" ] && [ -f "$tmp/export/box/face_014.txt" ] \
    && pass || fail "model export writes meta.xml and the 15 views"
  expect_ok "model build of the exported box" "$recog" model build --roboearth "$tmp/export/box" \
    -o "$tmp/box2.robj"
  expect_ok "model info of the rebuilt box" "$recog" model info "$tmp/box2.robj" --json
  /usr/bin/python3 -c "import json; d=json.load(open('$tmp/out')); assert d['name']=='box' and d['type']=='3D' and d['views']==15 and d['descriptors']>0, d" \
    && pass || fail "the rebuilt box has its name, type, 15 views and descriptors"
  expect_error "model export into a non-empty folder" "ALREADY_EXISTS" "$recog" model export \
    "$tmp/box.robj" --roboearth "$tmp/export/box"
else
  skip_shared "the RoboEarth box checks: $shared/objects/roboearth/models/box not found (set RECOG_SHARED_DATA)"
fi

# The --json of recog eval objects (both methods) and recog eval sequence, on small subsets: two
# RoboEarth folders (bio: 3D, 5 views, evaluated; bottle1: planar, a distractor) and the first 4
# visp-cube frames.
if [ -f "$shared/objects/roboearth/models/bio/meta.xml" ] && [ -f "$shared/objects/visp-cube/cube.cao" ]; then
  mkdir -p "$tmp/re" "$tmp/cube"
  ln -s "$shared/objects/roboearth/models/bio" "$shared/objects/roboearth/models/bottle1" "$tmp/re/"
  for method in merged independent-views; do
    expect_ok "eval objects --method $method --json" "$recog" eval objects --roboearth "$tmp/re" \
      --method "$method" --transforms none rot90 --json -q
    json_check "eval objects --method $method --json has the documented keys and consistent counts" "
import re
num = (int, float)
stages = ['orb', 'clustering', 'conversion', 'query', 'correspondences', 'ransac', 'second_pass', 'total']
def summary(s):
    assert isinstance(s['queries'], int) and isinstance(s['detections'], int), s
    assert isinstance(s['wrong_detections'], int) and 0 <= s['detections'] <= s['queries'], s
    assert abs(s['detection_rate'] - s['detections'] / s['queries']) < 1e-12, s
    assert isinstance(s['median_rotation_error_deg'], num) and isinstance(s['median_translation_error_ratio'], num), s
    assert all(isinstance(s['timing_ms'][k]['median'], num) and s['timing_ms'][k]['median'] >= 0 for k in stages), s
assert d['method'] == '$method' and d['transform'] == 'none', d['method']
summary(d)
assert sorted(d['by_transform']) == ['none', 'rot90'], d['by_transform'].keys()
for s in d['by_transform'].values(): summary(s)
assert d['by_transform']['none']['detections'] == d['detections']
q = d['per_query']
assert len(q) == 10 and sum(s['queries'] for s in d['by_transform'].values()) == len(q), len(q)
for t, s in d['by_transform'].items():
    mine = [x for x in q if x['transform'] == t]
    assert s['detections'] == sum(x['detected'] for x in mine), t
    assert s['wrong_detections'] == sum(len(x['wrong']) for x in mine), t
for x in q:
    assert x['object'] == 'bio' and 0 <= x['view'] < 5 and isinstance(x['detected'], bool), x
    assert isinstance(x['inliers'], int) and isinstance(x['total_ms'], num), x
    assert isinstance(x['rotation_error_deg'], num) and isinstance(x['translation_error_ratio'], num), x
    assert all(w == 'bottle1' for w in x['wrong']), x
    assert (x['matched'] != '') == x['detected'] and (not x['detected'] or x['inliers'] >= 6), x
if '$method' == 'merged':
    assert d['database'] == ['bio', 'bottle1'] and d['skipped_views'] == [], d['database']
    assert all(x['matched'] == 'bio' for x in q if x['detected']), q
else:
    assert d['database'] == ['bio.face_%03d' % v for v in range(5)] + ['bottle1.face_000'], d['database']
    assert all(re.fullmatch('bio[.]face_00[0-4]', x['matched']) and x['matched'] != 'bio.face_%03d' % x['view']
               for x in q if x['detected']), q
"
  done
  expect_ok "model build of the visp-cube" "$recog" model build --cad "$shared/objects/visp-cube/cube.cao" \
    --pose "$shared/objects/visp-cube/cube.0.pos" --image "$shared/objects/visp-cube/images/image0000.png" \
    --camera 547,547,338,234 --name visp-cube -o "$tmp/cube.robj"
  for i in 0 1 2 3; do ln -s "$shared/objects/visp-cube/images/image000$i.png" "$tmp/cube/"; done
  expect_ok "eval sequence --json" "$recog" eval sequence --models "$tmp/cube.robj" "$tmp/re" \
    --images "$tmp/cube" --camera 547,547,338,234 --expect visp-cube --json -q
  json_check "eval sequence --json has the documented keys and consistent counts" "
num = (int, float)
f = d['per_frame']
assert d['frames'] == 4 and len(f) == 4, d
assert [x['frame'] for x in f] == ['image000%d.png' % i for i in range(4)], f
assert all(isinstance(x['objects'], list) and isinstance(x['total_ms'], num) for x in f), f
assert d['detections'] == sum('visp-cube' in x['objects'] for x in f) <= d['frames'], d
assert d['false_positives'] == sum(o != 'visp-cube' for x in f for o in x['objects']), d
assert abs(d['recall'] - d['detections'] / d['frames']) < 1e-12, d
assert isinstance(d['median_inliers'], num) and isinstance(d['timing_ms']['total']['median'], num), d
assert 'visp-cube' in f[0]['objects'], 'the model was built from frame 0'
"
  expect_error "eval sequence expecting an object not among the models" "not among the models" "$recog" \
    eval sequence --models "$tmp/cube.robj" --images "$tmp/cube" --camera 547,547,338,234 --expect lion -q
  # Learning from the recording: frames 1-3 follow frame 0 (too close to become views), and
  # --exclude leaves frames out of the counts.
  expect_ok "model build --recording" "$recog" model build --cad "$shared/objects/visp-cube/cube.cao" \
    --pose "$shared/objects/visp-cube/cube.0.pos" --image "$tmp/cube/image0000.png" \
    --camera 547,547,338,234 --name visp-cube --recording "$tmp/cube" --no-images -q -o "$tmp/cube-rec.robj"
  grep -q "^1 views (image0000); the object was found in 3 of the 3 frames that follow image0000" "$tmp/out" \
    && pass || fail "model build --recording follows the cube through the frames after --image"
  expect_usage_error "model build with --view-angle 0" "--view-angle" "$recog" model build \
    --cad "$shared/objects/visp-cube/cube.cao" --pose "$shared/objects/visp-cube/cube.0.pos" \
    --image "$tmp/cube/image0000.png" --camera 547,547,338,234 --recording "$tmp/cube" \
    --view-angle 0 -o "$tmp/m.robj"
  expect_error "model build --recording of a missing folder" "NOT_FOUND" "$recog" model build \
    --cad "$shared/objects/visp-cube/cube.cao" --pose "$shared/objects/visp-cube/cube.0.pos" \
    --image "$tmp/cube/image0000.png" --camera 547,547,338,234 --recording "$tmp/none" -o "$tmp/m.robj"
  expect_ok "eval sequence --exclude" "$recog" eval sequence --models "$tmp/cube-rec.robj" \
    --images "$tmp/cube" --camera 547,547,338,234 --expect visp-cube --exclude image0000,image0002 --json -q
  json_check "eval sequence --exclude leaves the frames out of the counts" "
f = d['per_frame']
assert d['frames'] == 2 and d['frames_excluded'] == 2 and len(f) == 4, d
assert [x.get('excluded', False) for x in f] == [True, False, True, False], f
assert d['detections'] == sum('visp-cube' in x['objects'] for x in f if not x.get('excluded')), d
"
  expect_error "eval sequence --exclude of a frame not in --images" "no frame 'image9999'" "$recog" \
    eval sequence --models "$tmp/cube-rec.robj" --images "$tmp/cube" --camera 547,547,338,234 \
    --expect visp-cube --exclude image9999 -q
else
  skip_shared "the eval --json checks: bio or the visp-cube not found under $shared (set RECOG_SHARED_DATA)"
fi

# recog load refuses bad options before it connects (its runs: load/load_generator_test).
expect_ok "help of load" "$recog" load --help
expect_error "load with no robot" "INVALID_ARGUMENT" "$recog" load --sequences "$images" --robots 0 \
  --frames 1
expect_error "load without --frames or --duration" "INVALID_ARGUMENT" "$recog" load \
  --sequences "$images" --robots 2
expect_error "load of a missing folder" "NOT_FOUND" "$recog" load --sequences "$tmp/none" \
  --robots 1 --frames 1

report_and_exit

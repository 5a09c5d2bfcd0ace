#!/usr/bin/env bash
# Recall against object size on synthetic object sequences (issue 16): for a poster and a box,
# `recog seqgen objects` writes a 200-frame RGB-D sequence whose object shrinks from 30 % to 1 % of
# the frame, a model is built from its face images (and one from its RGB-D training views), and
# `recog eval sequence --truth` reports recall per size bin (table, CSV, PNG), with the 11
# RoboEarth models as distractors when the shared data holds them.
#
#   tools/evaluation/object_size_recall.sh [OUT_DIR]     (default /tmp/recog_object_size_recall)
#
# Environment: RECOG (the recog binary, default the checkout's build/bin/recog), RECOG_SHARED_DATA (default
# ../shared/data), FRAMES (200), SEED (1), CATEGORY (object photos, a Caltech-101 category;
# default pizza; the backgrounds come from BACKGROUND_Google). OUT_DIR must not exist.
set -euo pipefail
RECOG=${RECOG:-$(dirname "$0")/../../build/bin/recog}
DATA=${RECOG_SHARED_DATA:-../shared/data}
OUT=${1:-/tmp/recog_object_size_recall}
FRAMES=${FRAMES:-200}
SEED=${SEED:-1}
CATEGORY=${CATEGORY:-pizza}
PHOTOS=$DATA/training/caltech101
CAMERA=525,525,319.5,239.5
DISTRACTORS=()
[ -d "$DATA/objects/roboearth/models" ] && DISTRACTORS=("$DATA/objects/roboearth/models")
[ -e "$OUT" ] && { echo "$OUT exists; give a new folder" >&2; exit 1; }
mkdir -p "$OUT"

for shape in poster box; do
  dir=$OUT/$shape
  name=synthetic-$shape  # not "box": a RoboEarth distractor is called so
  echo "== $shape: recog seqgen objects --shape $shape --frames $FRAMES --seed $SEED"
  "$RECOG" seqgen objects --object-photos "$PHOTOS/$CATEGORY" \
    --background-photos "$PHOTOS/BACKGROUND_Google" --shape "$shape" --name "$name" \
    --frames "$FRAMES" --seed "$SEED" -o "$dir"
  if [ "$shape" = poster ]; then
    faces=(--planar "$dir/faces/front.png" --width 0.3 --height 0.21)
  else
    faces=(--face "front=$dir/faces/front.png" --face "left=$dir/faces/left.png"
           --face "right=$dir/faces/right.png" --face "top=$dir/faces/top.png"
           --width 0.3 --height 0.21 --depth 0.1)
  fi
  "$RECOG" model build "${faces[@]}" --name "$name" -o "$dir/$shape.robj"
  "$RECOG" model build --rgbd "$dir/views.txt" --name "$name" -o "$dir/${shape}_rgbd.robj"
  for model in "$shape" "${shape}_rgbd"; do
    echo "== $shape, model $model.robj: recog eval sequence --truth"
    "$RECOG" eval sequence --models "$dir/$model.robj" "${DISTRACTORS[@]}" --images "$dir/images" \
      --camera $CAMERA --expect "$name" --truth "$dir/truth.txt" \
      --size-recall "$dir/size_recall_$model" -q
  done
done

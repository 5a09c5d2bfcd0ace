#!/usr/bin/env python3
"""Makes a keyframe stream from a video sequence: every N-th frame, with its ground truth.

    every_nth_frame.py IMAGES GROUND_TRUTH N OFFSET OUT

IMAGES is a folder of frames named 1.jpg, 2.jpg, ... (the corridor's layout), GROUND_TRUTH its
dense N x N 0/1 matrix (line i, column j = 1: frame i revisits frame j). OUT receives
images/1.jpg, 2.jpg, ... (frames OFFSET+1, OFFSET+1+N, ... of IMAGES, copied as they are) and
ground_truth.txt, the matrix restricted to those frames. `recog eval place --images OUT/images
--ground-truth OUT/ground_truth.txt` then scores a detector on frames that overlap N times less.
"""
import os
import shutil
import sys


def main(argv):
    if len(argv) != 6:
        sys.exit(__doc__)
    images, truth_path, step, offset, out = argv[1], argv[2], int(argv[3]), int(argv[4]), argv[5]
    with open(truth_path) as f:
        truth = [line.split() for line in f if line.strip()]
    if step < 1 or not 0 <= offset < step:
        sys.exit("N must be >= 1 and OFFSET in [0, N)")
    kept = list(range(offset, len(truth), step))
    os.makedirs(os.path.join(out, "images"), exist_ok=True)
    for new, old in enumerate(kept, start=1):
        shutil.copyfile(os.path.join(images, f"{old + 1}.jpg"),
                        os.path.join(out, "images", f"{new}.jpg"))
    with open(os.path.join(out, "ground_truth.txt"), "w") as f:
        for i in kept:
            f.write(" ".join(truth[i][j] for j in kept) + "\n")
    revisits = sum(1 for i in kept if any(truth[i][j] == "1" for j in kept))
    print(f"{len(kept)} frames, {revisits} with a true match, in {out}")


if __name__ == "__main__":
    main(sys.argv)

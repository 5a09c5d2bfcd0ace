#!/usr/bin/python3
"""Writes the synthetic RGB-D sequence of the committed bag fixtures (tests/data/bags/README.md)
as a ViSP-like folder that make_manifest.py reads: OUT/images/image_K.png (mono8), OUT/depth/
depth_K.png (16-bit, mm) and OUT/camera.txt. Nothing random: every value is a formula, so tests
can assert any pixel.

  frames     K = 0..5, 64 wide x 48 high
  grey       I_K(x, y) = (3*x + 5*y + 40*K) mod 256
  depth (mm) D_K(x, y) = 1000 + 10*x + y + 100*K, except D_K(0, 0) = 0 (no depth)
  camera     fx = fy = 50, cx = 31.5, cy = 23.5, no distortion

Usage: synth_frames.py OUT
"""

import os
import sys

import cv2
import numpy

FRAMES, WIDTH, HEIGHT = 6, 64, 48


def grey(k):
    y, x = numpy.mgrid[0:HEIGHT, 0:WIDTH]
    return ((3 * x + 5 * y + 40 * k) % 256).astype(numpy.uint8)


def depth(k):
    y, x = numpy.mgrid[0:HEIGHT, 0:WIDTH]
    d = (1000 + 10 * x + y + 100 * k).astype(numpy.uint16)
    d[0, 0] = 0
    return d


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: synth_frames.py OUT")
    out = sys.argv[1]
    os.makedirs(os.path.join(out, "images"), exist_ok=True)
    os.makedirs(os.path.join(out, "depth"), exist_ok=True)
    for k in range(FRAMES):
        assert cv2.imwrite(os.path.join(out, "images", f"image_{k}.png"), grey(k))
        assert cv2.imwrite(os.path.join(out, "depth", f"depth_{k}.png"), depth(k))
    with open(os.path.join(out, "camera.txt"), "w") as f:
        f.write("# fx fy cx cy\n50 50 31.5 23.5\n")


if __name__ == "__main__":
    main()

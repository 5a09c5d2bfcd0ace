#!/usr/bin/python3
"""Writes a ROS 1 bag of camera frames from folders of images, with Debian's python3-rosbag and
python3-sensor-msgs (the real ROS 1 library), for the tests and benchmarks of the bag reader
(tools/evaluation/ros_bag.h) and of `recog eval place|stream|load --bag`.

Frames are the images of --images in natural order of their paths (as `recog` lists a folder),
the k-th stamped --start + k * --period seconds (header.stamp and the bag's record time alike),
one message each on --topic in --encoding:
  mono8, rgb8, bgr8, rgba8, bgra8  sensor_msgs/Image, decoded with OpenCV (mono8: the decoder's
                                   own grey, as `recog` reads image files)
  jpeg, png                        sensor_msgs/CompressedImage; a file already in that format goes
                                   as its bytes, any other is encoded with OpenCV
  any other name (e.g. yuv422)     sensor_msgs/Image with that encoding and mono8 pixels: a bag
                                   the reader must refuse
Optional: a CameraInfo per frame (--camera-info-topic, --camera fx,fy,cx,cy[,k1,k2,p1,p2,k3],
--distortion-model, plumb_bob by default: D is --camera's coefficients, 5 for plumb_bob), a
depth image per frame (--depth-images, 16-bit PNGs, in --depth-encoding 16UC1, 32FC1 (metres:
the PNG's units / --depth-units-per-metre), png, or compressedDepth (compressed_depth_image_
transport's 12-byte header, then the PNG) at --depth-offset seconds from its frame), the right
images of a stereo pair with their CameraInfo (P's Tx = -fx * --baseline). --reverse writes the
frames last first, their record times still increasing (header stamps then disagree with the
recording order); --unindexed leaves the bag as a recording killed before it closed (no index).

Usage: write_bag.py OUT.bag --images DIR [options]   (see --help)
"""

import argparse
import glob
import os
import re
import struct
import sys

import cv2
import numpy
import rosbag
import rospy
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

RAW_ENCODINGS = {"mono8": 1, "rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4}
EXTENSIONS = (".jpg", ".jpeg", ".png", ".bmp", ".pgm", ".ppm", ".tif", ".tiff")


def natural_key(path):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path)]


def list_images(folder):
    files = [p for p in glob.glob(os.path.join(folder, "**", "*"), recursive=True)
             if p.lower().endswith(EXTENSIONS)]
    if not files:
        sys.exit(f"write_bag.py: no images in '{folder}'")
    return sorted(files, key=natural_key)


def stamp_of(seconds):
    return rospy.Time.from_sec(seconds)


def image_message(path, encoding, stamp, frame_id):
    """The frame of one image file in `encoding`."""
    extension = os.path.splitext(path)[1].lower()
    if encoding in ("jpeg", "png"):
        message = CompressedImage()
        message.format = encoding
        same = (encoding == "jpeg" and extension in (".jpg", ".jpeg")) or \
            (encoding == "png" and extension == ".png")
        if same:
            with open(path, "rb") as f:
                message.data = f.read()
        else:
            ok, data = cv2.imencode("." + ("jpg" if encoding == "jpeg" else "png"),
                                    cv2.imread(path, cv2.IMREAD_UNCHANGED))
            assert ok, path
            message.data = data.tobytes()
    else:
        message = Image()
        if encoding == "mono8" or encoding not in RAW_ENCODINGS:
            pixels = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        else:
            bgr = cv2.imread(path, cv2.IMREAD_COLOR)
            pixels = {"bgr8": lambda: bgr,
                      "rgb8": lambda: cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB),
                      "bgra8": lambda: cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA),
                      "rgba8": lambda: cv2.cvtColor(bgr, cv2.COLOR_BGR2RGBA)}[encoding]()
        assert pixels is not None, path
        message.height, message.width = pixels.shape[:2]
        message.encoding = encoding
        message.step = pixels.strides[0]
        message.data = numpy.ascontiguousarray(pixels).tobytes()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    return message


def depth_message(path, encoding, units_per_metre, stamp):
    depth = cv2.imread(path, cv2.IMREAD_ANYDEPTH)
    assert depth is not None and depth.dtype == numpy.uint16, path
    if encoding in ("png", "compressedDepth"):
        message = CompressedImage()
        ok, png = cv2.imencode(".png", depth)
        assert ok, path
        if encoding == "png":
            message.format = "png"
            message.data = png.tobytes()
        else:
            message.format = "16UC1; compressedDepth png"
            message.data = struct.pack("<iff", 0, 0.0, 0.0) + png.tobytes()
    else:
        message = Image()
        if encoding == "32FC1":
            depth = depth.astype(numpy.float32) / units_per_metre
            depth[depth == 0] = numpy.nan
        message.height, message.width = depth.shape
        message.encoding = encoding
        message.step = depth.strides[0]
        message.data = depth.tobytes()
    message.header.stamp = stamp
    message.header.frame_id = "depth"
    return message


def camera_info(camera, model, size, stamp, tx=0.0):
    values = [float(v) for v in camera.split(",")]
    fx, fy, cx, cy = values[:4]
    info = CameraInfo()
    info.header.stamp = stamp
    info.width, info.height = size
    info.distortion_model = model
    # plumb_bob's five coefficients, the ones given padded with zeros; any other model's as given.
    info.D = (values[4:] + [0.0] * 5)[:5] if model == "plumb_bob" else values[4:]
    info.K = [fx, 0, cx, 0, fy, cy, 0, 0, 1]
    info.R = [1, 0, 0, 0, 1, 0, 0, 0, 1]
    info.P = [fx, 0, cx, tx, 0, fy, cy, 0, 0, 0, 1, 0]
    return info


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("output")
    parser.add_argument("--images", required=True)
    parser.add_argument("--topic", default="/camera/image_raw")
    parser.add_argument("--encoding", default="mono8")
    parser.add_argument("--start", type=float, default=1000.0)
    parser.add_argument("--period", type=float, default=1.0 / 30)
    parser.add_argument("--frames", type=int, default=0, help="only the first N images (0: all)")
    parser.add_argument("--camera-info-topic", default="")
    parser.add_argument("--camera", default="", help="fx,fy,cx,cy[,k1,k2,p1,p2,k3]")
    parser.add_argument("--distortion-model", default="plumb_bob",
                        help="CameraInfo's distortion_model; D is --camera's coefficients")
    parser.add_argument("--depth-images", default="")
    parser.add_argument("--depth-topic", default="/camera/depth/image_raw")
    parser.add_argument("--depth-encoding", default="16UC1",
                        choices=["16UC1", "32FC1", "png", "compressedDepth"])
    parser.add_argument("--depth-units-per-metre", type=float, default=1000.0)
    parser.add_argument("--depth-offset", type=float, default=0.0)
    parser.add_argument("--right-images", default="")
    parser.add_argument("--right-topic", default="/camera/right/image_raw")
    parser.add_argument("--right-camera-info-topic", default="")
    parser.add_argument("--baseline", type=float, default=0.0)
    parser.add_argument("--reverse", action="store_true")
    parser.add_argument("--compression", default="none", choices=["none", "bz2", "lz4"])
    parser.add_argument("--unindexed", action="store_true")
    args = parser.parse_args()

    images = list_images(args.images)
    if args.frames > 0:
        images = images[:args.frames]
    depths = list_images(args.depth_images)[:len(images)] if args.depth_images else []
    rights = list_images(args.right_images)[:len(images)] if args.right_images else []
    order = list(range(len(images)))
    if args.reverse:
        order.reverse()
    bag = rosbag.Bag(args.output, "w", compression=args.compression)
    for written, k in enumerate(order):
        stamp = stamp_of(args.start + k * args.period)
        record = stamp_of(args.start + written * args.period)
        message = image_message(images[k], args.encoding, stamp, "camera")
        bag.write(args.topic, message, record)
        size = (message.width, message.height) if isinstance(message, Image) else \
            cv2.imread(images[k], cv2.IMREAD_UNCHANGED).shape[1::-1]
        if args.camera_info_topic:
            bag.write(args.camera_info_topic, camera_info(args.camera, args.distortion_model, size,
                                                             stamp), record)
        if k < len(depths):
            depth_stamp = stamp_of(args.start + k * args.period + args.depth_offset)
            bag.write(args.depth_topic, depth_message(depths[k], args.depth_encoding,
                                                      args.depth_units_per_metre, depth_stamp),
                      record)
        if k < len(rights):
            bag.write(args.right_topic, image_message(rights[k], "mono8", stamp, "right"), record)
            if args.right_camera_info_topic:
                fx = float(args.camera.split(",")[0])
                bag.write(args.right_camera_info_topic,
                          camera_info(args.camera, args.distortion_model, size, stamp,
                                      -fx * args.baseline), record)
    if args.unindexed:
        bag._file.flush()  # what a killed `rosbag record` leaves: messages, no index
        os._exit(0)
    bag.close()


if __name__ == "__main__":
    main()

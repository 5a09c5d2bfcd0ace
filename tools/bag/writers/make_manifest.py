#!/usr/bin/python3
"""Lists the frames of one of the project's image folders as ROS 2 messages, for write_mcap.mjs.

Writes OUT/manifest.json and OUT/payload/NNNNNN.bin: per message its topic, ROS 2 type, log time
(ns), every field but `data`, and the file holding the bytes of its `data` field. Pixels are
decoded here with OpenCV (the decoder `recog` uses), so the bag holds exactly what `recog` reads
from the folder.

Folder layouts (--layout, detected by default like tools/evaluation/dataset_layouts.cc):
  visp    FOLDER/images/ and FOLDER/depth/ (16-bit PNG, mm), paired in name order, camera.txt
          ("fx fy cx cy", '#' comments): a ViSP RGB-D sequence such as objects/visp-rbt-cube
  tum     rgb.txt and depth.txt ("timestamp path"; depth within 0.02 s of the colour image)
  euroc   mav0/cam0/data.csv or cam0/data.csv ("timestamp [ns],file"); cam0/sensor.yaml camera
  kitti   times.txt and image_0/%06d.png; calib.txt's P0 camera
  folder  any other: the image files under FOLDER (recursively) in natural order of their paths,
          as `recog eval place --images` lists them; camera.txt if FOLDER has one
Layouts without times get invented ones: --start + k * --period seconds (default 10 Hz).

Topics (image_transport's names):
  /camera/image_raw                         sensor_msgs/msg/Image: mono8 for one-channel images
                                            (or --grey), else --colour-encoding (rgb8, bgr8)
  /camera/image_raw/compressed              sensor_msgs/msg/CompressedImage: the file's own JPEG
                                            or PNG bytes (format "<enc>; jpeg compressed <enc>")
  /camera/camera_info                       sensor_msgs/msg/CameraInfo (plumb_bob)
  /camera/depth/image_raw                   sensor_msgs/msg/Image 16UC1 (mm)
  /camera/depth/image_raw/compressedDepth   CompressedImage "16UC1; compressedDepth png": the
                                            12-byte header (int32 0, float32 0, float32 0, little
                                            endian) then the 16-bit PNG
Per frame the messages go in that order, all with log time = header stamp = the frame's time
(a TUM depth image carries the stamp of the colour frame it goes with).

Usage: make_manifest.py FOLDER OUT [--image-format raw|compressed|both] [--depth-format
       raw|compressedDepth|both|none] [--camera fx,fy,cx,cy[,k1,k2,p1,p2,k3]] [--frames N] ...
"""

import argparse
import decimal
import glob
import json
import os
import re
import shutil
import struct
import sys

import cv2
import numpy
import yaml

EXTENSIONS = (".jpg", ".jpeg", ".png", ".bmp", ".pgm", ".ppm", ".tif", ".tiff")
TUM_MAX_DEPTH_OFFSET_NS = 20_000_000


def fail(message):
    sys.exit(f"make_manifest.py: {message}")


def natural_key(path):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path)]


def list_images(folder):
    files = [p for p in glob.glob(os.path.join(folder, "**", "*"), recursive=True)
             if os.path.isfile(p) and p.lower().endswith(EXTENSIONS)]
    if not files:
        fail(f"no images under '{folder}'")
    return sorted(files, key=natural_key)


def seconds_to_ns(text):
    """Exact integer nanoseconds of a decimal time in seconds (a string, no float rounding)."""
    return int((decimal.Decimal(text) * 1_000_000_000).to_integral_value(decimal.ROUND_HALF_EVEN))


def list_lines(path):
    """The non-empty, non-comment lines of a list file."""
    with open(path) as f:
        return [line.strip() for line in f if line.strip() and not line.strip().startswith("#")]


def detect_layout(folder):
    if os.path.isdir(os.path.join(folder, "images")) and os.path.isdir(os.path.join(folder, "depth")):
        return "visp"
    if os.path.exists(os.path.join(folder, "rgb.txt")):
        return "tum"
    if os.path.exists(os.path.join(folder, "mav0", "cam0", "data.csv")) or \
            os.path.exists(os.path.join(folder, "cam0", "data.csv")):
        return "euroc"
    if os.path.exists(os.path.join(folder, "times.txt")) and \
            any(os.path.isdir(os.path.join(folder, f"image_{n}")) for n in range(4)):
        return "kitti"
    return "folder"


def read_camera_txt(path):
    """camera.txt: the first non-comment line, "fx fy cx cy"."""
    lines = list_lines(path)
    return [float(v) for v in lines[0].split()] if lines else None


def frames_of(folder, layout, args):
    """[(stamp ns or None, image path, depth path or None)] and the folder's camera (or None)."""
    camera = None
    if os.path.exists(os.path.join(folder, "camera.txt")):
        camera = read_camera_txt(os.path.join(folder, "camera.txt"))
    if layout == "visp":
        images = list_images(os.path.join(folder, "images"))
        depths = list_images(os.path.join(folder, "depth"))
        if len(depths) != len(images):
            fail(f"{len(images)} colour images but {len(depths)} depth images in '{folder}'")
        return [(None, i, d) for i, d in zip(images, depths)], camera
    if layout == "folder":
        return [(None, i, None) for i in list_images(folder)], camera
    if layout == "tum":
        def tum(name):
            path = os.path.join(folder, name)
            if not os.path.exists(path):
                return []
            return [(seconds_to_ns(t), os.path.join(folder, p))
                    for t, p in (line.split()[:2] for line in list_lines(path))]
        depth = tum("depth.txt")
        frames = []
        for stamp, image in tum("rgb.txt"):
            near = min(depth, key=lambda d: abs(d[0] - stamp), default=None)
            ok = near is not None and abs(near[0] - stamp) <= TUM_MAX_DEPTH_OFFSET_NS
            frames.append((stamp, image, near[1] if ok else None))
        return frames, camera
    if layout == "euroc":
        root = os.path.join(folder, "mav0") if os.path.isdir(os.path.join(folder, "mav0")) else folder
        cam = os.path.join(root, "cam0")
        frames = []
        for line in list_lines(os.path.join(cam, "data.csv")):
            stamp, name = line.split(",")[:2]
            frames.append((int(stamp), os.path.join(cam, "data", name.strip()), None))
        sensor = os.path.join(cam, "sensor.yaml")
        if os.path.exists(sensor):
            with open(sensor) as f:
                info = yaml.safe_load(f)
            camera = list(info["intrinsics"]) + list(info.get("distortion_coefficients", []))
        return frames, camera
    # kitti
    frames = []
    for k, t in enumerate(list_lines(os.path.join(folder, "times.txt"))):
        frames.append((seconds_to_ns(t), os.path.join(folder, "image_0", f"{k:06d}.png"), None))
    calib = os.path.join(folder, "calib.txt")
    if os.path.exists(calib):
        for line in list_lines(calib):
            if line.startswith("P0:"):
                p = [float(v) for v in line.split()[1:]]
                camera = [p[0], p[5], p[2], p[6]]
    return frames, camera


class Writer:
    """Collects the manifest's topics and messages, and writes the payload files."""

    def __init__(self, out):
        self.out = out
        self.topics = {}
        self.messages = []
        if os.path.isdir(os.path.join(out, "payload")):
            shutil.rmtree(os.path.join(out, "payload"))
        os.makedirs(os.path.join(out, "payload"))

    def add(self, topic, type_name, stamp_ns, fields, data):
        """One message; `data` is the bytes of its uint8[] data field (None: no such field)."""
        self.topics.setdefault(topic, type_name)
        name = None
        if data is not None:
            name = f"payload/{len(self.messages):06d}.bin"
            with open(os.path.join(self.out, name), "wb") as f:
                f.write(data)
        self.messages.append({"topic": topic, "log_time": str(stamp_ns), "message": fields,
                              "data": name})

    def save(self, source, layout):
        manifest = {"source": os.path.abspath(source), "layout": layout,
                    "topics": [{"name": n, "type": t} for n, t in self.topics.items()],
                    "messages": self.messages}
        with open(os.path.join(self.out, "manifest.json"), "w") as f:
            json.dump(manifest, f, indent=1)


def header(stamp_ns, frame_id):
    return {"stamp": {"sec": stamp_ns // 1_000_000_000, "nanosec": stamp_ns % 1_000_000_000},
            "frame_id": frame_id}


def raw_image(pixels, encoding, stamp_ns, frame_id):
    pixels = numpy.ascontiguousarray(pixels)
    fields = {"header": header(stamp_ns, frame_id), "height": pixels.shape[0],
              "width": pixels.shape[1], "encoding": encoding, "is_bigendian": 0,
              "step": pixels.strides[0]}
    return fields, pixels.tobytes()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder")
    parser.add_argument("out")
    parser.add_argument("--layout", default="auto",
                        choices=["auto", "folder", "visp", "tum", "euroc", "kitti"])
    parser.add_argument("--start", default="1000", help="first invented stamp, seconds")
    parser.add_argument("--period", default="0.1", help="invented stamps' period, seconds")
    parser.add_argument("--frames", type=int, default=0, help="only the first N frames (0: all)")
    parser.add_argument("--image-format", default="raw", choices=["raw", "compressed", "both"])
    parser.add_argument("--colour-encoding", default="rgb8", choices=["rgb8", "bgr8"])
    parser.add_argument("--grey", action="store_true", help="mono8 even for colour images")
    parser.add_argument("--depth-format", default="both",
                        choices=["raw", "compressedDepth", "both", "none"])
    parser.add_argument("--camera", default="", help="fx,fy,cx,cy[,k1,k2,p1,p2,k3]")
    parser.add_argument("--no-camera-info", action="store_true")
    parser.add_argument("--frame-id", default="camera")
    parser.add_argument("--topic", default="/camera/image_raw")
    parser.add_argument("--camera-info-topic", default="/camera/camera_info")
    parser.add_argument("--depth-topic", default="/camera/depth/image_raw")
    args = parser.parse_args()

    layout = detect_layout(args.folder) if args.layout == "auto" else args.layout
    frames, camera = frames_of(args.folder, layout, args)
    if args.frames > 0:
        frames = frames[:args.frames]
    if args.camera:
        camera = [float(v) for v in args.camera.split(",")]
    start_ns, period_ns = seconds_to_ns(args.start), seconds_to_ns(args.period)
    os.makedirs(args.out, exist_ok=True)
    out = Writer(args.out)
    for k, (stamp, image_path, depth_path) in enumerate(frames):
        stamp = start_ns + k * period_ns if stamp is None else stamp
        pixels = cv2.imread(image_path, cv2.IMREAD_GRAYSCALE if args.grey else cv2.IMREAD_UNCHANGED)
        if pixels is None:
            fail(f"cannot read '{image_path}'")
        if pixels.dtype != numpy.uint8:
            fail(f"'{image_path}' is not 8-bit")
        if pixels.ndim == 3 and pixels.shape[2] == 4:
            pixels = cv2.cvtColor(pixels, cv2.COLOR_BGRA2BGR)
        grey = pixels.ndim == 2
        encoding = "mono8" if grey else args.colour_encoding
        if args.image_format in ("raw", "both"):
            shown = pixels if grey or encoding == "bgr8" else cv2.cvtColor(pixels, cv2.COLOR_BGR2RGB)
            out.add(args.topic, "sensor_msgs/msg/Image", stamp,
                    *raw_image(shown, encoding, stamp, args.frame_id))
        if args.image_format in ("compressed", "both"):
            extension = os.path.splitext(image_path)[1].lower()
            kind = "jpeg" if extension in (".jpg", ".jpeg") else "png"
            if extension in (".jpg", ".jpeg", ".png") and not args.grey:
                with open(image_path, "rb") as f:
                    data = f.read()
            else:
                ok, encoded = cv2.imencode("." + ("jpg" if kind == "jpeg" else "png"), pixels)
                assert ok, image_path
                data = encoded.tobytes()
            compressed_as = "mono8" if grey else "bgr8"
            out.add(args.topic + "/compressed", "sensor_msgs/msg/CompressedImage", stamp,
                    {"header": header(stamp, args.frame_id),
                     "format": f"{compressed_as}; {kind} compressed {compressed_as}"}, data)
        if camera and not args.no_camera_info:
            fx, fy, cx, cy = camera[:4]
            out.add(args.camera_info_topic, "sensor_msgs/msg/CameraInfo", stamp, {
                "header": header(stamp, args.frame_id),
                "height": pixels.shape[0], "width": pixels.shape[1],
                "distortion_model": "plumb_bob", "d": (camera[4:] + [0.0] * 5)[:5],
                "k": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
                "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                "p": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
                "binning_x": 0, "binning_y": 0,
                "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0,
                        "do_rectify": False}}, None)
        if depth_path and args.depth_format != "none":
            depth = cv2.imread(depth_path, cv2.IMREAD_UNCHANGED)
            if depth is None or depth.dtype != numpy.uint16 or depth.ndim != 2:
                fail(f"'{depth_path}' is not a 16-bit one-channel image")
            if args.depth_format in ("raw", "both"):
                out.add(args.depth_topic, "sensor_msgs/msg/Image", stamp,
                        *raw_image(depth, "16UC1", stamp, args.frame_id))
            if args.depth_format in ("compressedDepth", "both"):
                if depth_path.lower().endswith(".png"):
                    with open(depth_path, "rb") as f:
                        png = f.read()
                else:
                    ok, encoded = cv2.imencode(".png", depth)
                    assert ok, depth_path
                    png = encoded.tobytes()
                out.add(args.depth_topic + "/compressedDepth", "sensor_msgs/msg/CompressedImage",
                        stamp, {"header": header(stamp, args.frame_id),
                                "format": "16UC1; compressedDepth png"},
                        struct.pack("<iff", 0, 0.0, 0.0) + png)
    out.save(args.folder, layout)
    print(f"make_manifest.py: {len(frames)} frames ({layout}), {len(out.messages)} messages "
          f"on {len(out.topics)} topics -> {args.out}")


if __name__ == "__main__":
    main()

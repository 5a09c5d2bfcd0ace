#!/usr/bin/python3
"""Checks a rosbag2 sqlite3 bag of write_rosbag2_sqlite.py against its manifest (make_manifest.py).

Independently of the Node libraries: reads the .db3 with Python's sqlite3, parses metadata.yaml,
and decodes every message's CDR with a small decoder of its own (encapsulation header, alignment
from the end of the header, little or big endian) for sensor_msgs/msg/Image, CompressedImage and
CameraInfo, comparing every field and every data byte with the manifest. It also checks the
images against one another: per frame, the compressed image decodes (OpenCV) to the raw image's
pixels when it is a PNG, and the compressedDepth PNG (after its 12-byte header) to the 16UC1
depth.

Usage: verify_rosbag2_sqlite.py BAG_DIR MANIFEST_DIR
"""

import glob
import json
import os
import sqlite3
import struct
import sys

import cv2
import numpy
import yaml


def fail(message):
    sys.exit(f"verify_rosbag2_sqlite.py: {message}")


class Cdr:
    """A reader of one CDR message (XCDR1 plain, as ROS 2 sends it)."""

    def __init__(self, data):
        if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
            fail(f"bad CDR encapsulation header {data[:4].hex()}")
        self.data, self.pos = data, 4
        self.order = "<" if data[1] == 1 else ">"

    def _get(self, code, size):
        self.pos += (-(self.pos - 4)) % size  # align relative to the end of the header
        (value,) = struct.unpack_from(self.order + code, self.data, self.pos)
        self.pos += size
        return value

    def u8(self): return self._get("B", 1)
    def i32(self): return self._get("i", 4)
    def u32(self): return self._get("I", 4)
    def f64(self): return self._get("d", 8)

    def string(self):
        n = self.u32()
        text = self.data[self.pos:self.pos + n]
        if n == 0 or text[-1] != 0:
            fail("a CDR string without its NUL")
        self.pos += n
        return text[:-1].decode()

    def bytes(self):
        n = self.u32()
        self.pos += n
        return self.data[self.pos - n:self.pos]

    def header(self):
        return {"stamp": {"sec": self.i32(), "nanosec": self.u32()}, "frame_id": self.string()}

    def end(self):
        if self.pos != len(self.data):
            fail(f"{len(self.data) - self.pos} bytes after the message")


def decode(type_name, data):
    c = Cdr(data)
    m = {"header": c.header()}
    if type_name == "sensor_msgs/msg/Image":
        m.update(height=c.u32(), width=c.u32(), encoding=c.string(), is_bigendian=c.u8(),
                 step=c.u32(), data=c.bytes())
    elif type_name == "sensor_msgs/msg/CompressedImage":
        m.update(format=c.string(), data=c.bytes())
    elif type_name == "sensor_msgs/msg/CameraInfo":
        m.update(height=c.u32(), width=c.u32(), distortion_model=c.string())
        m["d"] = [c.f64() for _ in range(c.u32())]
        for key, n in (("k", 9), ("r", 9), ("p", 12)):
            m[key] = [c.f64() for _ in range(n)]
        m.update(binning_x=c.u32(), binning_y=c.u32())
        m["roi"] = {"x_offset": c.u32(), "y_offset": c.u32(), "height": c.u32(),
                    "width": c.u32(), "do_rectify": bool(c.u8())}
    else:
        fail(f"no decoder for {type_name}")
    c.end()
    return m


def main():
    if len(sys.argv) != 3:
        fail("usage: verify_rosbag2_sqlite.py BAG_DIR MANIFEST_DIR")
    bag, manifest_dir = sys.argv[1:]
    with open(os.path.join(manifest_dir, "manifest.json")) as f:
        manifest = json.load(f)
    with open(os.path.join(bag, "metadata.yaml")) as f:
        info = yaml.safe_load(f)["rosbag2_bagfile_information"]
    files = glob.glob(os.path.join(bag, "*.db3"))
    if info["storage_identifier"] != "sqlite3" or info["relative_file_paths"] != \
            [os.path.basename(p) for p in files]:
        fail("metadata.yaml does not name the bag's .db3")
    if info["message_count"] != len(manifest["messages"]):
        fail(f"metadata.yaml: {info['message_count']} messages")
    db = sqlite3.connect(files[0])
    topics = {row[0]: row[1:] for row in db.execute(
        "SELECT id, name, type, serialization_format FROM topics")}
    if {(n, t) for n, t, _ in topics.values()} != \
            {(t["name"], t["type"]) for t in manifest["topics"]}:
        fail("topics differ from the manifest's")
    if any(fmt != "cdr" for _, _, fmt in topics.values()):
        fail("a topic not in cdr")
    definitions = {row[0] for row in db.execute(
        "SELECT topic_type FROM message_definitions WHERE encoding = 'ros2msg'")}
    if definitions != {t["type"] for t in manifest["topics"]}:
        fail("message_definitions differ from the topics' types")
    rows = list(db.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY id"))
    if len(rows) != len(manifest["messages"]):
        fail(f"{len(rows)} messages, the manifest has {len(manifest['messages'])}")

    frames = {}  # log time -> {topic: decoded}
    for (topic_id, timestamp, data), entry in zip(rows, manifest["messages"]):
        name, type_name, _ = topics[topic_id]
        where = f"{entry['topic']}@{entry['log_time']}"
        if name != entry["topic"] or str(timestamp) != entry["log_time"]:
            fail(f"message {where} is {name}@{timestamp}")
        decoded = decode(type_name, data)
        expected = dict(entry["message"])
        if entry["data"] is not None:
            with open(os.path.join(manifest_dir, entry["data"]), "rb") as f:
                expected["data"] = f.read()
        if decoded != expected:
            diff = [k for k in expected if decoded.get(k) != expected[k]]
            fail(f"{where}: fields {diff} differ")
        frames.setdefault(timestamp, {})[name] = decoded

    checked = 0
    for messages in frames.values():
        raw, depth = messages.get("/camera/image_raw"), messages.get("/camera/depth/image_raw")
        compressed = messages.get("/camera/image_raw/compressed")
        packed = messages.get("/camera/depth/image_raw/compressedDepth")
        if raw and compressed:
            # The same decoder gives the same pixels: a PNG must match its raw image, and so
            # must a JPEG unless it was encoded anew (--grey of a colour file).
            image = cv2.imdecode(numpy.frombuffer(compressed["data"], numpy.uint8),
                                 cv2.IMREAD_GRAYSCALE if raw["encoding"] == "mono8"
                                 else cv2.IMREAD_COLOR)
            if raw["encoding"] == "rgb8":
                image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
            if image.tobytes() == raw["data"]:
                checked += 1
            elif " png " in compressed["format"]:
                fail("a compressed PNG image differs from its raw image")
        if depth and packed:
            if packed["data"][:12] != struct.pack("<iff", 0, 0.0, 0.0):
                fail("compressedDepth header is not int32 0, float 0, float 0")
            image = cv2.imdecode(numpy.frombuffer(packed["data"][12:], numpy.uint8),
                                 cv2.IMREAD_UNCHANGED)
            if image.dtype != numpy.uint16 or image.tobytes() != depth["data"]:
                fail("a compressedDepth PNG differs from its 16UC1 depth")
            checked += 1
    print(f"verify_rosbag2_sqlite.py: {bag}: OK, {len(rows)} messages decoded and compared, "
          f"{checked} compressed/raw pairs agree")


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""Packs the CDR messages dumped by write_mcap.mjs (--cdr-dump DIR) into a rosbag2 sqlite3 bag.

The bag is a folder OUT/ with OUT/NAME_0.db3 and OUT/metadata.yaml, laid out as rosbag2's sqlite3
storage plugin writes them in ROS 2 Jazzy (database schema version 4, bag metadata version 8):
  schema(schema_version, ros_distro)                       one row: 4, --ros-distro
  metadata(id, metadata_version, metadata)                  one row: 8, the bag metadata as YAML
  topics(id, name, type, serialization_format,              one row per topic, "cdr", rosbag2's
         offered_qos_profiles, type_description_hash)       default QoS, hash "" (not computed)
  message_definitions(id, topic_type, encoding,             one row per type: "ros2msg" and the
         encoded_message_definition, type_description_hash) full concatenated definition
  messages(id, topic_id, timestamp, data)                   one row per message: the log time in
                                                            ns and the CDR bytes, as dumped
and the index timestamp_idx on messages(timestamp). The bytes are the very ones write_mcap.mjs put
in the MCAP bag written with the same dump, so both storages hold the same messages.

Usage: write_rosbag2_sqlite.py CDR_DUMP_DIR OUT_BAG_DIR [--name NAME] [--ros-distro jazzy]
"""

import argparse
import json
import os
import shutil
import sqlite3
import sys

import yaml

SCHEMA_VERSION = 4
METADATA_VERSION = 8

CREATE = [
    "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL)",
    "CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,"
    "metadata TEXT NOT NULL)",
    "CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,"
    "serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL,"
    "type_description_hash TEXT NOT NULL)",
    "CREATE TABLE message_definitions(id INTEGER PRIMARY KEY,topic_type TEXT NOT NULL,"
    "encoding TEXT NOT NULL,encoded_message_definition TEXT NOT NULL,"
    "type_description_hash TEXT NOT NULL)",
    "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,"
    "timestamp INTEGER NOT NULL, data BLOB NOT NULL)",
    "CREATE INDEX timestamp_idx ON messages (timestamp ASC)",
]


def quoted(text):
    """A YAML double-quoted scalar (JSON's escaping is valid YAML), as rosbag2 writes QoS."""
    return json.dumps(text)


def metadata_yaml(topics, counts, start, duration, count, files, distro, indent):
    """rosbag2's BagMetadata (version 8) in its own key order; `indent` spaces before each key."""
    p = " " * indent
    lines = [f"version: {METADATA_VERSION}", "storage_identifier: sqlite3",
             "duration:", f"  nanoseconds: {duration}",
             "starting_time:", f"  nanoseconds_since_epoch: {start}",
             f"message_count: {count}", "topics_with_message_count:"]
    for topic in topics:
        lines += ["  - topic_metadata:",
                  f"      name: {topic['name']}",
                  f"      type: {topic['type']}",
                  "      serialization_format: cdr",
                  f"      offered_qos_profiles: {quoted(topic['offered_qos_profiles'])}",
                  '      type_description_hash: ""',
                  f"    message_count: {counts[topic['name']]}"]
    lines += ['compression_format: ""', 'compression_mode: ""', "relative_file_paths:"]
    lines += [f"  - {name}" for name in files]
    lines += ["files:"]
    for name in files:
        lines += [f"  - path: {name}",
                  "    starting_time:", f"      nanoseconds_since_epoch: {start}",
                  "    duration:", f"      nanoseconds: {duration}",
                  f"    message_count: {count}"]
    lines += ["custom_data: ~", f"ros_distro: {distro}"]
    return "".join(p + line + "\n" for line in lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dump")
    parser.add_argument("out")
    parser.add_argument("--name", default="", help="database name stem (default: the folder's)")
    parser.add_argument("--ros-distro", default="jazzy")
    args = parser.parse_args()

    with open(os.path.join(args.dump, "index.json")) as f:
        index = json.load(f)
    if index.get("big_endian"):
        sys.exit("write_rosbag2_sqlite.py: big-endian CDR is for MCAP fixtures only")
    with open(os.path.join(args.dump, "messages.bin"), "rb") as f:
        blob = f.read()

    if os.path.isdir(args.out):
        shutil.rmtree(args.out)
    os.makedirs(args.out)
    name = (args.name or os.path.basename(os.path.normpath(args.out))) + "_0.db3"
    db = sqlite3.connect(os.path.join(args.out, name))
    for statement in CREATE:
        db.execute(statement)
    db.execute("INSERT INTO schema VALUES (?, ?)", (SCHEMA_VERSION, args.ros_distro))
    topic_ids, defined = {}, set()
    for topic in index["topics"]:
        topic_ids[topic["name"]] = len(topic_ids) + 1
        db.execute("INSERT INTO topics VALUES (?, ?, ?, 'cdr', ?, '')",
                   (topic_ids[topic["name"]], topic["name"], topic["type"],
                    topic["offered_qos_profiles"]))
        if topic["type"] not in defined:
            defined.add(topic["type"])
            db.execute("INSERT INTO message_definitions VALUES (?, ?, 'ros2msg', ?, '')",
                       (len(defined), topic["type"], topic["definition"]))
    counts = {topic["name"]: 0 for topic in index["topics"]}
    for k, message in enumerate(index["messages"]):
        data = blob[message["offset"]:message["offset"] + message["length"]]
        db.execute("INSERT INTO messages VALUES (?, ?, ?, ?)",
                   (k + 1, topic_ids[message["topic"]], int(message["timestamp"]), data))
        counts[message["topic"]] += 1

    times = [int(m["timestamp"]) for m in index["messages"]]
    start, duration = (min(times), max(times) - min(times)) if times else (0, 0)
    text = metadata_yaml(index["topics"], counts, start, duration, len(times), [name],
                         args.ros_distro, 0)
    db.execute("INSERT INTO metadata VALUES (1, ?, ?)", (METADATA_VERSION, text))
    db.commit()
    db.close()
    with open(os.path.join(args.out, "metadata.yaml"), "w") as f:
        f.write("rosbag2_bagfile_information:\n" + metadata_yaml(
            index["topics"], counts, start, duration, len(times), [name], args.ros_distro, 2))
    with open(os.path.join(args.out, "metadata.yaml")) as f:  # it must be valid YAML
        assert yaml.safe_load(f)["rosbag2_bagfile_information"]["message_count"] == len(times)
    print(f"write_rosbag2_sqlite.py: {len(times)} messages -> {args.out}/{name} "
          f"({os.path.getsize(os.path.join(args.out, name))} bytes) + metadata.yaml")


if __name__ == "__main__":
    main()

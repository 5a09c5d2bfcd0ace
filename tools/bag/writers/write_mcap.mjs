#!/usr/bin/env node
// Writes a ROS 2 MCAP bag from a manifest of make_manifest.py, with the real MCAP writer
// (@mcap/core's McapWriter) and the real ROS 2 CDR serializer (@foxglove/rosmsg2-serialization),
// laid out as rosbag2's MCAP storage lays it: profile "ros2", one schema per type in "ros2msg"
// encoding (the full concatenated definition), channels in "cdr" message encoding with
// offered_qos_profiles in their metadata.
//
// Usage: node write_mcap.mjs MANIFEST_DIR OUT.mcap [options]
//   --chunk-compression zstd|lz4|none   chunks' compression (default zstd); lz4 is the LZ4 frame
//                                       format (lz4js), zstd is libzstd (@foxglove/wasm-zstd)
//   --chunk-size BYTES                  target uncompressed chunk size (default 1 MiB)
//   --no-chunks                         messages straight in the data section (no chunks)
//   --no-index                          no summary at all: no message or chunk indexes, no
//                                       statistics, no repeated schemas/channels, no summary
//                                       offsets (what a recorder killed mid-way could leave,
//                                       minus the footer: the footer is there, with zeros)
//   --cdr-dump DIR                      also write DIR/messages.bin + DIR/index.json: every
//                                       message's CDR bytes, for write_rosbag2_sqlite.py
//   --big-endian                        serialize CDR big endian (see cdr_big_endian.mjs) instead
//                                       of MessageWriter's little endian

import fs from "node:fs";
import path from "node:path";
import { McapWriter } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageWriter } from "@foxglove/rosmsg2-serialization";
import * as zstd from "@foxglove/wasm-zstd";
import lz4 from "lz4js";
import { fullDefinition } from "./msg_definitions.mjs";
import { writeBigEndian } from "./cdr_big_endian.mjs";
import { readManifest } from "./manifest.mjs";

// rosbag2's default recording QoS (reliable, volatile, keep last), as it stores it per topic.
export const QOS_PROFILES = `- history: 3
  depth: 0
  reliability: 1
  durability: 2
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: 1
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false`;

function parseArgs(argv) {
  const args = { compression: "zstd", chunkSize: 1024 * 1024, chunks: true, index: true };
  const positional = [];
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    if (a === "--chunk-compression") args.compression = argv[++i];
    else if (a === "--chunk-size") args.chunkSize = Number(argv[++i]);
    else if (a === "--no-chunks") args.chunks = false;
    else if (a === "--no-index") args.index = false;
    else if (a === "--cdr-dump") args.cdrDump = argv[++i];
    else if (a === "--big-endian") args.bigEndian = true;
    else if (a.startsWith("--")) throw new Error(`unknown option ${a}`);
    else positional.push(a);
  }
  if (positional.length !== 2) throw new Error("usage: write_mcap.mjs MANIFEST_DIR OUT.mcap [options]");
  if (!["zstd", "lz4", "none"].includes(args.compression)) {
    throw new Error(`--chunk-compression: zstd, lz4 or none, not ${args.compression}`);
  }
  [args.manifestDir, args.out] = positional;
  return args;
}

// An IWritable over a file: McapWriter only needs write() and position().
class FileWritable {
  #fd;
  #position = 0n;
  constructor(file) {
    this.#fd = fs.openSync(file, "w");
  }
  async write(buffer) {
    fs.writeSync(this.#fd, buffer);
    this.#position += BigInt(buffer.byteLength);
  }
  position() {
    return this.#position;
  }
  close() {
    fs.closeSync(this.#fd);
  }
}

// The compressChunk function of McapWriter for --chunk-compression.
function chunkCompressor(compression) {
  if (compression === "zstd") {
    return (data) => ({ compression: "zstd", compressedData: zstd.compress(data, 3) });
  }
  if (compression === "lz4") {
    // lz4js sizes its output by a bound that omits the frame's block headers: give it room.
    return (data) => {
      const room = lz4.compressBound(data.length) + 64 + 4 * Math.ceil(data.length / (4 << 20));
      return { compression: "lz4", compressedData: lz4.compress(data, room) };
    };
  }
  return undefined; // chunks stored as they are (compression "")
}

async function main() {
  const args = parseArgs(process.argv.slice(2));
  await zstd.isLoaded;
  const manifest = readManifest(args.manifestDir);

  const writable = new FileWritable(args.out);
  const writer = new McapWriter({
    writable,
    useChunks: args.chunks,
    chunkSize: args.chunkSize,
    compressChunk: args.chunks ? chunkCompressor(args.compression) : undefined,
    useMessageIndex: args.index,
    useChunkIndex: args.index,
    useStatistics: args.index,
    useSummaryOffsets: args.index,
    repeatSchemas: args.index,
    repeatChannels: args.index,
    useAttachmentIndex: args.index,
    useMetadataIndex: args.index,
  });
  await writer.start({ profile: "ros2", library: "recog tools/bag/writers (@mcap/core 2.2.2)" });

  // One schema per type, one channel per topic, in the manifest's order.
  const types = new Map(); // type name -> { schemaId, definition, serializer }
  const channels = new Map(); // topic -> { channelId, type }
  for (const { name, type } of manifest.topics) {
    if (!types.has(type)) {
      const definition = fullDefinition(type);
      const schemaId = await writer.registerSchema({
        name: type,
        encoding: "ros2msg",
        data: new TextEncoder().encode(definition),
      });
      const parsed = parse(definition, { ros2: true });
      const serialize = args.bigEndian
        ? (message) => writeBigEndian(parsed, message)
        : ((w) => (message) => w.writeMessage(message))(new MessageWriter(parsed));
      types.set(type, { schemaId, definition, serialize });
    }
    const channelId = await writer.registerChannel({
      topic: name,
      schemaId: types.get(type).schemaId,
      messageEncoding: "cdr",
      metadata: new Map([["offered_qos_profiles", QOS_PROFILES]]),
    });
    channels.set(name, { channelId, type });
  }
  // rosbag2 keeps a metadata record "rosbag2" with the ROS distribution; readers must skip it.
  await writer.addMetadata({ name: "rosbag2", metadata: new Map([["ROS_DISTRO", "jazzy"]]) });

  // The CDR dump for the sqlite3 writer: the bytes back to back, and where each message is.
  let dump;
  if (args.cdrDump) {
    fs.mkdirSync(args.cdrDump, { recursive: true });
    dump = { fd: fs.openSync(path.join(args.cdrDump, "messages.bin"), "w"), offset: 0, index: [] };
  }

  const sequence = new Map();
  for (const entry of manifest.messages) {
    const { channelId, type } = channels.get(entry.topic);
    const data = types.get(type).serialize(entry.message);
    const logTime = BigInt(entry.log_time);
    const seq = sequence.get(channelId) ?? 0;
    sequence.set(channelId, seq + 1);
    await writer.addMessage({ channelId, sequence: seq, logTime, publishTime: logTime, data });
    if (dump) {
      fs.writeSync(dump.fd, data);
      dump.index.push({ topic: entry.topic, timestamp: entry.log_time, offset: dump.offset, length: data.length });
      dump.offset += data.length;
    }
  }
  await writer.end();
  writable.close();

  if (dump) {
    fs.closeSync(dump.fd);
    const topics = manifest.topics.map(({ name, type }) => ({
      name,
      type,
      definition: types.get(type).definition,
      offered_qos_profiles: QOS_PROFILES,
    }));
    const index = { big_endian: !!args.bigEndian, topics, messages: dump.index };
    fs.writeFileSync(path.join(args.cdrDump, "index.json"), JSON.stringify(index, null, 1));
  }
  const size = fs.statSync(args.out).size;
  console.log(`write_mcap.mjs: ${manifest.messages.length} messages -> ${args.out} (${size} bytes)`);
}

main().catch((error) => {
  console.error(`write_mcap.mjs: ${error.message}`);
  process.exit(1);
});

#!/usr/bin/env node
// Checks an MCAP bag of write_mcap.mjs against the manifest it was written from: reads it back
// with @mcap/core's McapStreamReader (always) and McapIndexedReader (when it has a summary),
// decompressing chunks with decoders other than the writers' own (lz4: liblz4 in
// @foxglove/wasm-lz4, not lz4js; zstd: libzstd), checking CRCs, and deserializes every message
// with @foxglove/rosmsg2-serialization's MessageReader from the schema stored in the file, to
// compare each field and every data byte with the manifest's.
//
// Usage: node verify_mcap.mjs MANIFEST_DIR FILE.mcap [--compression zstd|lz4|none]
//                             [--chunks yes|no] [--index yes|no]
// Exits 1 with the first difference; prints a summary line when all is the same.

import fs from "node:fs";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import * as zstd from "@foxglove/wasm-zstd";
import lz4Decompress from "@foxglove/wasm-lz4";
import { readManifest } from "./manifest.mjs";

const decompressHandlers = {
  zstd: (buffer, size) => zstd.decompress(buffer, Number(size)),
  lz4: (buffer, size) => lz4Decompress(buffer, Number(size)),
};

function check(condition, message) {
  if (!condition) throw new Error(message);
}

// Deep comparison of a decoded value with the manifest's: typed arrays and arrays alike,
// booleans against 0/1 never. Returns the path of the first difference, or undefined.
function difference(decoded, expected, where = "") {
  const isList = (v) => Array.isArray(v) || ArrayBuffer.isView(v);
  if (isList(expected)) {
    if (!isList(decoded)) return `${where}: not an array`;
    if (decoded.length !== expected.length) {
      return `${where}: length ${decoded.length} != ${expected.length}`;
    }
    for (let i = 0; i < expected.length; i++) {
      if (decoded[i] !== expected[i]) return `${where}[${i}]: ${decoded[i]} != ${expected[i]}`;
    }
    return undefined;
  }
  if (expected !== null && typeof expected === "object") {
    for (const key of Object.keys(expected)) {
      const d = difference(decoded?.[key], expected[key], `${where}.${key}`);
      if (d) return d;
    }
    return undefined;
  }
  return decoded === expected ? undefined : `${where}: ${decoded} != ${expected}`;
}

function parseArgs(argv) {
  const args = { positional: [] };
  for (let i = 0; i < argv.length; i++) {
    if (argv[i] === "--compression") args.compression = argv[++i];
    else if (argv[i] === "--chunks") args.chunks = argv[++i] === "yes";
    else if (argv[i] === "--index") args.index = argv[++i] === "yes";
    else args.positional.push(argv[i]);
  }
  check(args.positional.length === 2, "usage: verify_mcap.mjs MANIFEST_DIR FILE.mcap [options]");
  return args;
}

// Checks the messages read (in any order) against the manifest's, using the file's schemas.
function compareMessages(label, manifest, schemas, channels, messages) {
  check(messages.length === manifest.messages.length,
    `${label}: ${messages.length} messages, the manifest has ${manifest.messages.length}`);
  const readers = new Map();
  const byKey = new Map(messages.map((m) => [`${channels.get(m.channelId).topic}@${m.logTime}`, m]));
  check(byKey.size === messages.length, `${label}: two messages of one topic share a log time`);
  for (const entry of manifest.messages) {
    const key = `${entry.topic}@${entry.log_time}`;
    const record = byKey.get(key);
    check(record, `${label}: no message ${key}`);
    check(record.publishTime === record.logTime, `${label}: ${key}: publish time != log time`);
    const channel = channels.get(record.channelId);
    if (!readers.has(channel.schemaId)) {
      const schema = schemas.get(channel.schemaId);
      readers.set(channel.schemaId, new MessageReader(parse(new TextDecoder().decode(schema.data), { ros2: true })));
    }
    const reader = readers.get(channel.schemaId);
    const decoded = reader.readMessage(record.data);
    check(!reader.lastReadHadTrailingBytes(), `${label}: ${key}: trailing bytes after the message`);
    const d = difference(decoded, entry.message);
    check(!d, `${label}: ${key}: ${d}`);
  }
}

// Schema, channel and header checks shared by both readings.
function checkTopics(label, manifest, schemas, channels) {
  const topics = new Map([...channels.values()].map((c) => [c.topic, c]));
  check(topics.size === manifest.topics.length, `${label}: ${topics.size} channels`);
  for (const { name, type } of manifest.topics) {
    const channel = topics.get(name);
    check(channel, `${label}: no channel ${name}`);
    check(channel.messageEncoding === "cdr", `${label}: ${name}: encoding ${channel.messageEncoding}`);
    check(channel.metadata.get("offered_qos_profiles"), `${label}: ${name}: no offered_qos_profiles`);
    const schema = schemas.get(channel.schemaId);
    check(schema?.name === type && schema.encoding === "ros2msg", `${label}: ${name}: schema ${schema?.name}`);
  }
}

async function main() {
  const args = parseArgs(process.argv.slice(2));
  await zstd.isLoaded;
  await lz4Decompress.isLoaded;
  const [manifestDir, file] = args.positional;
  const manifest = readManifest(manifestDir);
  const bytes = new Uint8Array(fs.readFileSync(file));

  // 1. Streamed, record by record, chunks opened (CRCs of chunks and data section checked).
  const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true, includeChunks: true });
  stream.append(bytes);
  const schemas = new Map(), channels = new Map(), messages = [], compressions = new Set();
  let header, footer, chunks = 0, summaryRecords = 0, metadata = 0, dataEnd = false;
  for (let record; (record = stream.nextRecord()); ) {
    switch (record.type) {
      case "Header": header = record; break;
      case "Schema": schemas.set(record.id, record); break;
      case "Channel": channels.set(record.id, record); break;
      case "Message": if (!dataEnd) messages.push(record); break;
      case "Chunk": chunks++; compressions.add(record.compression); break;
      case "Metadata": metadata++; break;
      case "DataEnd": dataEnd = true; break;
      case "Footer": footer = record; break;
      case "ChunkIndex": case "Statistics": case "SummaryOffset": case "MessageIndex":
        if (record.type !== "MessageIndex") summaryRecords++;
        break;
    }
  }
  check(stream.done(), "stream: bytes left after the footer");
  check(header?.profile === "ros2", `stream: profile '${header?.profile}'`);
  check(metadata === 1, "stream: expected one metadata record (rosbag2)");
  checkTopics("stream", manifest, schemas, channels);
  compareMessages("stream", manifest, schemas, channels, messages);
  if (args.chunks !== undefined) check((chunks > 0) === args.chunks, `${chunks} chunks`);
  if (args.compression !== undefined && chunks > 0) {
    const want = args.compression === "none" ? "" : args.compression;
    check(compressions.size === 1 && compressions.has(want), `chunk compression ${[...compressions]}`);
  }
  const indexed = footer.summaryStart !== 0n;
  if (args.index !== undefined) check(indexed === args.index, `summary start ${footer.summaryStart}`);

  // 2. Indexed, through the summary (chunk indexes and message indexes), when there is one.
  if (indexed) {
    const readable = {
      size: async () => BigInt(bytes.length),
      read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
    };
    const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
    check(reader.statistics?.messageCount === BigInt(manifest.messages.length), "indexed: statistics");
    check(chunks === 0 || reader.chunkIndexes.length === chunks, "indexed: chunk index count");
    checkTopics("indexed", manifest, reader.schemasById, reader.channelsById);
    // McapIndexedReader finds messages through chunk indexes only: none in an unchunked file.
    if (chunks > 0) {
      const read = [];
      for await (const m of reader.readMessages()) read.push(m);
      compareMessages("indexed", manifest, reader.schemasById, reader.channelsById, read);
    }
  }
  const kind = chunks ? `${chunks} chunks (${[...compressions].map((c) => c || "none")})` : "no chunks";
  console.log(`verify_mcap.mjs: ${file}: OK, ${messages.length} messages, ${kind}, ` +
    (indexed ? (chunks ? "indexed (stream and indexed readings agree)" : "summary checked (no chunk indexes)")
      : "no summary (stream reading)"));
}

main().catch((error) => {
  console.error(`verify_mcap.mjs: ${error.message}`);
  process.exit(1);
});

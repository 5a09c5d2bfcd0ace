// Reads a manifest written by make_manifest.py: topics, and per message its topic, log time (ns,
// a decimal string) and fields. An entry's `message` is its full message object, the `data` field
// (when the type has one) read from its payload file each time it is asked for.

import fs from "node:fs";
import path from "node:path";

export function readManifest(dir) {
  const manifest = JSON.parse(fs.readFileSync(path.join(dir, "manifest.json"), "utf8"));
  for (const entry of manifest.messages) {
    const fields = entry.message;
    const payload = entry.data == undefined ? undefined : path.join(dir, entry.data);
    entry.fields = fields;
    Object.defineProperty(entry, "message", {
      get: () => (payload ? { ...fields, data: new Uint8Array(fs.readFileSync(payload)) } : fields),
    });
  }
  return manifest;
}

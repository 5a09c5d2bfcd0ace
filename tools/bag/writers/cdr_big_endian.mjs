// ROS 2 CDR, big endian (encapsulation kind CDR_BE, header 00 00 00 00), with @foxglove/cdr's
// CdrWriter. @foxglove/rosmsg2-serialization's MessageWriter only writes little endian, so this
// walks the parsed message definitions itself (same rules: fields in order, dynamic arrays and
// strings with a uint32 length, primitives aligned to their size, time as int32 + uint32).
// Big endian CDR is what a big-endian host's DDS would send; readers must honour the header.

import { CdrWriter, EncapsulationKind } from "@foxglove/cdr";

const PRIMITIVES = {
  bool: (w, v) => w.uint8(v ? 1 : 0),
  int8: (w, v) => w.int8(v),
  uint8: (w, v) => w.uint8(v),
  byte: (w, v) => w.uint8(v),
  char: (w, v) => w.uint8(v),
  int16: (w, v) => w.int16(v),
  uint16: (w, v) => w.uint16(v),
  int32: (w, v) => w.int32(v),
  uint32: (w, v) => w.uint32(v),
  int64: (w, v) => w.int64(BigInt(v)),
  uint64: (w, v) => w.uint64(BigInt(v)),
  float32: (w, v) => w.float32(v),
  float64: (w, v) => w.float64(v),
  string: (w, v) => w.string(v ?? ""),
  time: (w, v) => w.int32(v?.sec ?? 0).uint32(v?.nanosec ?? v?.nsec ?? 0),
};
PRIMITIVES.duration = PRIMITIVES.time;

// `definitions`: @foxglove/rosmsg parse() output, the first one the root type.
export function writeBigEndian(definitions, message) {
  const byName = new Map(definitions.map((d) => [d.name, d]));
  const writer = new CdrWriter({ kind: EncapsulationKind.CDR_BE });
  const writeValue = (type, isComplex, value) => {
    if (isComplex) writeStruct(byName.get(type).definitions, value ?? {});
    else PRIMITIVES[type](writer, value ?? (type === "string" ? "" : 0));
  };
  const writeStruct = (fields, value) => {
    for (const field of fields) {
      if (field.isConstant) continue;
      const v = value[field.name];
      if (!field.isArray) {
        writeValue(field.type, field.isComplex, v);
        continue;
      }
      const items = v ?? [];
      const length = field.arrayLength ?? items.length;
      if (field.arrayLength == undefined) writer.sequenceLength(length);
      for (let i = 0; i < length; i++) writeValue(field.type, field.isComplex, items[i]);
    }
  };
  writeStruct(definitions[0].definitions, message);
  return writer.data;
}

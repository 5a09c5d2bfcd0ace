// The object model file (.robj): one self-contained, versioned, checksummed file per model.
//
//   offset  size  field
//   0       8     magic "RECOGOBJ"
//   8       4     format version (1)
//   12      4     number of sections
//   16      8     body size in bytes
//   24      8     XXH3-64 of the body
//   32      8     XXH3-64 of bytes 0..31
//   40      ...   body: the sections, each = tag u32 | size u64 | bytes
//
// Sections (little-endian; strings are u32 length + bytes):
//   'META' metadata: name, class, type u8, dimensions 3 x f64, units, source, version u32
//   'DESC' descriptor format (type u8, size_bytes u32), features n u32, n x size_bytes bytes,
//          n x point index u32
//   'PNTS' points m u32, m x (x, y, z f32)
//   'FACE' faces f u32, f x (width, height f64, R 9 x f64, t 3 x f64), then m x face index u32
//          (no count of its own: m is the PNTS count for planar models and 0 for 3D models)
//   'VIEW' views v u32, v x (name, fx fy cx cy f64, distortion count u32 + f64s, R 9 x f64,
//          t 3 x f64, image bytes u32 + PNG bytes)
// A tag's four bytes spell its name ("META" in a hex dump); R is stored row-major. META, DESC and
// PNTS are required, FACE and VIEW optional (absent = empty); each known section may appear once,
// in any order. Unknown sections are skipped (a later minor addition stays readable). The header
// checksum is checked before the version, so a damaged version field is DATA_LOSS while an intact
// header with a higher version is FAILED_PRECONDITION. Every length is checked against what is
// left before anything is read or allocated; any mismatch is DATA_LOSS naming the file; a missing
// file is NOT_FOUND. The decoded model is Validate()d before it is returned.
#pragma once

#include <string>

#include "core/common/status.h"
#include "core/object/model/object_model.h"

namespace recog {

// Serialises a model (Validate()d first) to bytes / parses bytes ("where" names the source in
// errors).
StatusOr<std::string> EncodeObjectModel(const ObjectModel& model);
StatusOr<ObjectModel> DecodeObjectModel(std::string_view bytes, const std::string& where);

// Writes atomically (temporary file renamed into place) / reads a model file.
Status SaveObjectModel(const ObjectModel& model, const std::string& path);
StatusOr<ObjectModel> LoadObjectModel(const std::string& path);

}  // namespace recog

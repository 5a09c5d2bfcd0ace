// Decompression of a bag's data (MCAP chunks, rosbag2's zstd files and messages) with Debian's
// libzstd and liblz4, bounded before anything is allocated: a chunk that says it holds N bytes
// gets a buffer of N bytes and is refused when it decompresses to more or to less, and nothing
// decompresses to more than a cap, so that a small "bomb" cannot take the machine's memory.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"

namespace recog::bag {

// The largest buffer one chunk or message may decompress to: 1 GiB (an MCAP chunk is a few MiB;
// the largest ROS image message, 4K RGB at 16 bits, is 50 MiB).
inline constexpr uint64_t kMaxDecompressedBytes = uint64_t(1) << 30;

// `input` compressed with `compression` ("zstd", "lz4" — an LZ4 frame, as MCAP writes it — or ""
// for none) into exactly `declared_size` bytes, in *output (resized; its capacity reused).
// INVALID_ARGUMENT for an unknown compression name or a declared size above `max_size`;
// DATA_LOSS when the data is damaged or decompresses to another size than declared. `where`
// names the file and record in the errors ("file 'a.mcap', chunk at byte 1234").
Status DecompressExactly(std::string_view compression, std::span<const uint8_t> input,
                         uint64_t declared_size, std::vector<uint8_t>* output,
                         std::string_view where, uint64_t max_size = kMaxDecompressedBytes);

// `input`, zstd frames whose decompressed size may be unknown (rosbag2's per-message mode), into
// *output; DATA_LOSS when damaged, RESOURCE_EXHAUSTED beyond `max_size` (found while
// decompressing, before more is allocated).
Status DecompressZstd(std::span<const uint8_t> input, std::vector<uint8_t>* output,
                      std::string_view where, uint64_t max_size = kMaxDecompressedBytes);

// The zstd file `input_path` decompressed to `output_path` in a streamed pass (rosbag2's
// per-file mode, a .db3.zstd); RESOURCE_EXHAUSTED when it grows beyond `max_size` bytes (the
// partial output is removed), DATA_LOSS when damaged or cut short.
Status DecompressZstdFile(const std::string& input_path, const std::string& output_path,
                          uint64_t max_size);

}  // namespace recog::bag

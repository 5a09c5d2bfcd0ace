#include "tools/bag/decompress.h"

#include <lz4frame.h>
#include <zstd.h>
#include <zstd_errors.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "core/common/file_io.h"

namespace recog::bag {
namespace {

// The most output one byte of compressed input can give, which bounds what a declared size may
// be before a buffer is allocated for it. zstd: a run-length block is 4 bytes for up to 128 KiB.
// LZ4: a match length grows by 255 per extra byte.
constexpr uint64_t kZstdMaxExpansion = 32768;
constexpr uint64_t kLz4MaxExpansion = 256;

// The first output buffer of a decompression whose size is unknown; it doubles as it fills.
constexpr size_t kInitialUnknownSizeOutput = 64 * 1024;

struct ZstdContextDeleter {
  void operator()(ZSTD_DCtx* context) const { ZSTD_freeDCtx(context); }
};
using ZstdContext = std::unique_ptr<ZSTD_DCtx, ZstdContextDeleter>;

struct Lz4ContextDeleter {
  void operator()(LZ4F_dctx* context) const { LZ4F_freeDecompressionContext(context); }
};
using Lz4Context = std::unique_ptr<LZ4F_dctx, Lz4ContextDeleter>;

Status CheckDeclaredSize(std::string_view compression, uint64_t input_size, uint64_t declared_size,
                         uint64_t max_expansion, std::string_view where) {
  if ((declared_size + max_expansion - 1) / max_expansion > input_size) {
    return Status::DataLoss(std::string(where) + ": " + std::to_string(input_size) + " bytes of " +
                            std::string(compression) + " data cannot hold the " +
                            std::to_string(declared_size) + " bytes it declares");
  }
  return Status::Ok();
}

Status DecompressZstdExactly(std::span<const uint8_t> input, uint64_t declared_size,
                             std::vector<uint8_t>* output, std::string_view where) {
  RECOG_RETURN_IF_ERROR(
      CheckDeclaredSize("zstd", input.size(), declared_size, kZstdMaxExpansion, where));
  const unsigned long long frame_size = ZSTD_getFrameContentSize(input.data(), input.size());
  if (frame_size == ZSTD_CONTENTSIZE_ERROR) {
    return Status::DataLoss(std::string(where) + ": not a zstd frame");
  }
  if (frame_size != ZSTD_CONTENTSIZE_UNKNOWN && frame_size > declared_size) {
    return Status::DataLoss(std::string(where) + ": its zstd frame holds " +
                            std::to_string(frame_size) + " bytes, more than the " +
                            std::to_string(declared_size) + " declared");
  }
  output->resize(size_t(declared_size));
  const ZstdContext context(ZSTD_createDCtx());
  if (context == nullptr) return Status::ResourceExhausted(std::string(where) + ": out of memory");
  const size_t result = ZSTD_decompressDCtx(context.get(), output->data(), output->size(),
                                            input.data(), input.size());
  if (ZSTD_isError(result)) {
    if (ZSTD_getErrorCode(result) == ZSTD_error_dstSize_tooSmall) {
      return Status::DataLoss(std::string(where) + ": decompresses to more than the " +
                              std::to_string(declared_size) + " bytes declared");
    }
    return Status::DataLoss(std::string(where) + ": damaged zstd data (" +
                            ZSTD_getErrorName(result) + ")");
  }
  if (result != declared_size) {
    return Status::DataLoss(std::string(where) + ": decompresses to " + std::to_string(result) +
                            " bytes, not the " + std::to_string(declared_size) + " declared");
  }
  return Status::Ok();
}

Status DecompressLz4Exactly(std::span<const uint8_t> input, uint64_t declared_size,
                            std::vector<uint8_t>* output, std::string_view where) {
  RECOG_RETURN_IF_ERROR(
      CheckDeclaredSize("lz4", input.size(), declared_size, kLz4MaxExpansion, where));
  LZ4F_dctx* raw_context = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&raw_context, LZ4F_VERSION))) {
    return Status::ResourceExhausted(std::string(where) + ": out of memory");
  }
  const Lz4Context context(raw_context);
  output->resize(size_t(declared_size));
  size_t consumed = 0;
  size_t produced = 0;
  size_t hint = 1;  // what LZ4F_decompress asks for next; 0 at the end of a frame
  // Where output goes once the declared size is reached: any byte written there is one too many.
  uint8_t overflow[64];
  while (consumed < input.size()) {
    const bool full = produced == output->size();
    uint8_t* destination = full ? overflow : output->data() + produced;
    size_t destination_size = full ? sizeof(overflow) : output->size() - produced;
    size_t source_size = input.size() - consumed;
    hint = LZ4F_decompress(context.get(), destination, &destination_size, input.data() + consumed,
                           &source_size, nullptr);
    if (LZ4F_isError(hint)) {
      return Status::DataLoss(std::string(where) + ": damaged lz4 data (" +
                              LZ4F_getErrorName(hint) + ")");
    }
    if (full && destination_size > 0) {
      return Status::DataLoss(std::string(where) + ": decompresses to more than the " +
                              std::to_string(declared_size) + " bytes declared");
    }
    if (source_size == 0 && destination_size == 0) {
      return Status::DataLoss(std::string(where) + ": lz4 data makes no progress");
    }
    consumed += source_size;
    produced += destination_size;
  }
  if (hint != 0) return Status::DataLoss(std::string(where) + ": lz4 frame cut short");
  if (produced != declared_size) {
    return Status::DataLoss(std::string(where) + ": decompresses to " + std::to_string(produced) +
                            " bytes, not the " + std::to_string(declared_size) + " declared");
  }
  return Status::Ok();
}

}  // namespace

Status DecompressExactly(std::string_view compression, std::span<const uint8_t> input,
                         uint64_t declared_size, std::vector<uint8_t>* output,
                         std::string_view where, uint64_t max_size) {
  if (compression != "" && compression != "zstd" && compression != "lz4") {
    return Status::InvalidArgument(std::string(where) + ": unknown compression '" +
                                   std::string(compression) + "'");
  }
  if (declared_size > max_size) {
    return Status::InvalidArgument(
        std::string(where) + ": declares " + std::to_string(declared_size) +
        " decompressed bytes, more than the limit of " + std::to_string(max_size));
  }
  if (compression == "zstd") return DecompressZstdExactly(input, declared_size, output, where);
  if (compression == "lz4") return DecompressLz4Exactly(input, declared_size, output, where);
  if (input.size() != declared_size) {
    return Status::DataLoss(std::string(where) + ": holds " + std::to_string(input.size()) +
                            " uncompressed bytes, not the " + std::to_string(declared_size) +
                            " declared");
  }
  output->assign(input.begin(), input.end());
  return Status::Ok();
}

Status DecompressZstd(std::span<const uint8_t> input, std::vector<uint8_t>* output,
                      std::string_view where, uint64_t max_size) {
  if (input.empty()) return Status::DataLoss(std::string(where) + ": no zstd frame");
  const unsigned long long frame_size = ZSTD_getFrameContentSize(input.data(), input.size());
  if (frame_size == ZSTD_CONTENTSIZE_ERROR) {
    return Status::DataLoss(std::string(where) + ": not a zstd frame");
  }
  if (frame_size != ZSTD_CONTENTSIZE_UNKNOWN && frame_size > max_size) {
    return Status::ResourceExhausted(std::string(where) + ": its zstd frame holds " +
                                     std::to_string(frame_size) +
                                     " bytes, more than the limit of " + std::to_string(max_size));
  }
  const ZstdContext context(ZSTD_createDCtx());
  if (context == nullptr) return Status::ResourceExhausted(std::string(where) + ": out of memory");
  output->resize(size_t(std::min<uint64_t>(max_size, kInitialUnknownSizeOutput)));
  ZSTD_inBuffer source{input.data(), input.size(), 0};
  size_t produced = 0;
  size_t remaining_in_frame = 0;  // ZSTD_decompressStream's result: 0 at the end of a frame
  for (;;) {
    if (produced == output->size() && produced < max_size) {
      output->resize(size_t(std::min<uint64_t>(max_size, uint64_t(produced) * 2)));
    }
    // Full at the limit: the output goes to a one-byte scratch buffer, where any byte is too many.
    const bool at_limit = produced == output->size();
    uint8_t scratch[1];
    ZSTD_outBuffer destination = at_limit
                                     ? ZSTD_outBuffer{scratch, sizeof(scratch), 0}
                                     : ZSTD_outBuffer{output->data(), output->size(), produced};
    const size_t consumed_before = source.pos;
    const size_t produced_before = destination.pos;
    const size_t result = ZSTD_decompressStream(context.get(), &destination, &source);
    if (ZSTD_isError(result)) {
      return Status::DataLoss(std::string(where) + ": damaged zstd data (" +
                              ZSTD_getErrorName(result) + ")");
    }
    if (at_limit && destination.pos > 0) {
      return Status::ResourceExhausted(std::string(where) +
                                       ": decompresses to more than the limit of " +
                                       std::to_string(max_size) + " bytes");
    }
    // No progress: the decoder wants input that is not there.
    if (source.pos == consumed_before && destination.pos == produced_before) break;
    remaining_in_frame = result;
    if (!at_limit) produced = destination.pos;
    if (source.pos == source.size && remaining_in_frame == 0) break;
  }
  if (remaining_in_frame != 0) {
    return Status::DataLoss(std::string(where) + ": zstd data cut short");
  }
  output->resize(produced);
  return Status::Ok();
}

Status DecompressZstdFile(const std::string& input_path, const std::string& output_path,
                          uint64_t max_size) {
  const std::string where = "zstd file '" + input_path + "'";
  const File input(std::fopen(input_path.c_str(), "rb"));
  if (input == nullptr) return Status::NotFound(where + " cannot be opened");
  File output(std::fopen(output_path.c_str(), "wb"));
  if (output == nullptr) {
    return Status::NotFound("file '" + output_path + "' cannot be created");
  }
  const auto fail = [&](Status status) {
    output.reset();
    std::error_code ignored;
    std::filesystem::remove(output_path, ignored);
    return status;
  };
  const ZstdContext context(ZSTD_createDCtx());
  if (context == nullptr) return fail(Status::ResourceExhausted(where + ": out of memory"));
  std::vector<uint8_t> in_buffer(ZSTD_DStreamInSize());
  std::vector<uint8_t> out_buffer(ZSTD_DStreamOutSize());
  uint64_t written = 0;
  size_t remaining_in_frame = 0;
  bool any_input = false;
  for (;;) {
    const size_t read = std::fread(in_buffer.data(), 1, in_buffer.size(), input.get());
    if (read == 0) {
      if (std::ferror(input.get())) return fail(Status::DataLoss(where + " cannot be read"));
      break;
    }
    any_input = true;
    ZSTD_inBuffer source{in_buffer.data(), read, 0};
    // Drain the decoder: it may still hold output when the input has been consumed.
    bool output_full = true;
    while (source.pos < source.size || output_full) {
      ZSTD_outBuffer destination{out_buffer.data(), out_buffer.size(), 0};
      const size_t consumed_before = source.pos;
      const size_t result = ZSTD_decompressStream(context.get(), &destination, &source);
      if (ZSTD_isError(result)) {
        return fail(
            Status::DataLoss(where + ": damaged zstd data (" + ZSTD_getErrorName(result) + ")"));
      }
      // A call that does nothing after the end of a frame asks for the next one's header.
      if (destination.pos > 0 || source.pos > consumed_before) remaining_in_frame = result;
      if (destination.pos > max_size - written) {
        return fail(Status::ResourceExhausted(where + ": decompresses to more than the limit of " +
                                              std::to_string(max_size) + " bytes"));
      }
      if (std::fwrite(out_buffer.data(), 1, destination.pos, output.get()) != destination.pos) {
        return fail(
            Status::ResourceExhausted("file '" + output_path + "' cannot be written (disk full?)"));
      }
      written += destination.pos;
      output_full = destination.pos == destination.size;
    }
  }
  if (!any_input) return fail(Status::DataLoss(where + ": empty, no zstd frame"));
  if (remaining_in_frame != 0) return fail(Status::DataLoss(where + ": cut short"));
  if (std::fclose(output.release()) != 0) {
    return fail(
        Status::ResourceExhausted("file '" + output_path + "' cannot be written (disk full?)"));
  }
  return Status::Ok();
}

}  // namespace recog::bag

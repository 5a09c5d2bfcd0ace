// What an image costs the server before it is decoded or refused (server/api: ReadImageHeader,
// PixelBudget, DecodeFrame). A decompression bomb is a small file declaring a huge image: here a
// real 20000 x 20000 grey PNG of zeros (about 390 KB, generated at start with zlib) and a JPEG
// whose frame header declares 20000 x 20000. Each is refused from its header; the reference is a
// real 640 x 480 JPEG decoded in full, and, last (it raises the process's peak memory), OpenCV's
// decoder given the PNG bomb as the server used to do before reading headers.
//
// Counters: peak_rss_growth_MB, how much the process's peak resident memory rose during the
// benchmark (0 when the bytes decoded fit in memory already touched).
//
// Run: build/bin/bench_decode
#include <sys/resource.h>
#include <zlib.h>

#include <benchmark/benchmark.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "server/api/frame_decoding.h"
#include "tests/testing/data_paths.h"

namespace recog::server {
namespace {

constexpr uint32_t kBombSide = 20000;

void AppendBigEndian(std::string* out, uint32_t value) {
  for (int shift = 24; shift >= 0; shift -= 8) out->push_back(char((value >> shift) & 0xFF));
}

void AppendChunk(std::string* png, const char* type, const std::string& data) {
  AppendBigEndian(png, uint32_t(data.size()));
  const std::string typed = std::string(type, 4) + data;
  *png += typed;
  AppendBigEndian(
      png, uint32_t(crc32(0, reinterpret_cast<const Bytef*>(typed.data()), uInt(typed.size()))));
}

// A valid 8-bit grey PNG of kBombSide x kBombSide zeros, compressed row by row.
const std::string& PngBomb() {
  static const std::string png = [] {
    std::string header;
    AppendBigEndian(&header, kBombSide);
    AppendBigEndian(&header, kBombSide);
    header += std::string("\x08\x00\x00\x00\x00", 5);
    z_stream stream{};
    deflateInit(&stream, 9);
    const std::vector<unsigned char> row(kBombSide + 1, 0);  // filter byte, then the pixels
    std::string compressed;
    std::vector<unsigned char> out(1 << 16);
    for (uint32_t y = 0; y < kBombSide; ++y) {
      stream.next_in = const_cast<Bytef*>(row.data());
      stream.avail_in = uInt(row.size());
      const int flush = y + 1 == kBombSide ? Z_FINISH : Z_NO_FLUSH;
      do {
        stream.next_out = out.data();
        stream.avail_out = uInt(out.size());
        deflate(&stream, flush);
        compressed.append(reinterpret_cast<char*>(out.data()), out.size() - stream.avail_out);
      } while (stream.avail_out == 0);
    }
    deflateEnd(&stream);
    std::string bytes("\x89PNG\r\n\x1a\n", 8);
    AppendChunk(&bytes, "IHDR", header);
    AppendChunk(&bytes, "IDAT", compressed);
    AppendChunk(&bytes, "IEND", "");
    return bytes;
  }();
  return png;
}

// A JPEG's start and a baseline frame header declaring kBombSide x kBombSide.
std::string JpegBomb() {
  std::string bytes("\xFF\xD8\xFF\xC0\x00\x0B\x08", 7);
  for (int i = 0; i < 2; ++i) bytes += {char(kBombSide >> 8), char(kBombSide & 0xFF)};
  return bytes + std::string("\x01\x01\x11\x00\xFF\xD9", 6);
}

double PeakRssMb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return double(usage.ru_maxrss) / 1024.0;
}

void RunDecode(benchmark::State& state, const std::string& bytes, bool expect_ok) {
  pb::Frame frame;
  frame.set_encoded_image(bytes);
  const double rss_before = PeakRssMb();
  for (auto _ : state) {
    PixelBudget budget;
    const StatusOr<DecodedFrame> decoded = DecodeFrame(frame, DescriptorFormat::Orb(), budget);
    if (decoded.ok() != expect_ok) {
      state.SkipWithError(decoded.ok() ? "decoded" : decoded.status().ToString().c_str());
      break;
    }
    benchmark::DoNotOptimize(decoded);
  }
  state.counters["file_KB"] = double(bytes.size()) / 1024.0;
  state.counters["peak_rss_growth_MB"] = PeakRssMb() - rss_before;
}

void BM_RefusePngBomb(benchmark::State& state) { RunDecode(state, PngBomb(), false); }
BENCHMARK(BM_RefusePngBomb)->Unit(benchmark::kMicrosecond);

void BM_RefuseJpegBomb(benchmark::State& state) { RunDecode(state, JpegBomb(), false); }
BENCHMARK(BM_RefuseJpegBomb)->Unit(benchmark::kMicrosecond);

void BM_DecodeJpeg640x480(benchmark::State& state) {
  cv::Mat image =
      cv::imread(recog::testing::ProjectTestData("corridor/1.jpg"), cv::IMREAD_GRAYSCALE);
  cv::resize(image, image, cv::Size(640, 480));
  std::vector<uchar> jpeg;
  cv::imencode(".jpg", image, jpeg);
  RunDecode(state, std::string(jpeg.begin(), jpeg.end()), true);
}
BENCHMARK(BM_DecodeJpeg640x480)->Unit(benchmark::kMicrosecond);

// What the server did before it read headers: OpenCV decodes the whole bomb (and then the size
// check refused it). Last, since it leaves the process's peak memory high.
void BM_OpenCvDecodesPngBomb(benchmark::State& state) {
  const std::string& bytes = PngBomb();
  const cv::Mat buffer(1, int(bytes.size()), CV_8UC1, const_cast<char*>(bytes.data()));
  const double rss_before = PeakRssMb();
  for (auto _ : state) {
    const cv::Mat image = cv::imdecode(buffer, cv::IMREAD_GRAYSCALE);
    benchmark::DoNotOptimize(image.data);
  }
  state.counters["file_KB"] = double(bytes.size()) / 1024.0;
  state.counters["peak_rss_growth_MB"] = PeakRssMb() - rss_before;
}
BENCHMARK(BM_OpenCvDecodesPngBomb)->Unit(benchmark::kMillisecond)->Iterations(2);

}  // namespace
}  // namespace recog::server

BENCHMARK_MAIN();

// recogd's gRPC port fuzzed below gRPC's client: a seeded generator makes up calls and sends them
// with a raw HTTP/2 client (tests/testing/raw_http2_client.h) to a recogd in this process (CI runs
// it in the AddressSanitizer + UndefinedBehaviorSanitizer build too), with tokens off and on.
//
// A call is a stream: its HEADERS (method paths real, mutated or made up; pseudo-headers missing,
// repeated or out of order; content-type, te, grpc-timeout, grpc-encoding, x-request-id and
// authorization right or wrong; random keys and values of every byte 0-255, empty or several KB
// long, up to hundreds of them; HPACK literals of every kind, CONTINUATION fragments, blocks cut
// short) and its DATA (requests of the method's type filled at random, some mutated; the
// compressed flag set or not, with gzip or deflate bytes or without; length prefixes that lie,
// longer, shorter or huge; messages cut mid-frame). It ends with END_STREAM (or client trailers),
// a RST_STREAM at a random point, nothing (abandoned), a GOAWAY, or the connection cut mid-frame.
// Between frames go PING, PRIORITY, SETTINGS, WINDOW_UPDATE and unknown frames, rarely ones that
// break the connection. Each connection makes from one to hundreds of calls, several at a time.
//
// Nothing is asserted of the answers, only that there is one: every call that ended with
// END_STREAM gets an answer (a grpc-status, a RST_STREAM, a GOAWAY or the connection closed)
// within kAnswerTimeout, the process does not die, and every kCheckEvery calls and at the end the
// server answers real calls through the generated stubs: ListMaps, the health check and, at the
// end, AddFrame and QueryPlace of corridor frames. A one-line summary gives the calls by outcome
// and the calls per second.
//
// Environment:
//   RECOG_GRPC_FUZZ_CALLS       calls per test case (default 6000: 20-30 s for the two cases in
//                               the ASan + UBSan build; CI runs the default in both passes)
//   RECOG_GRPC_FUZZ_SEED        the seed (default 1); connection c of a run draws from (seed, c)
//   RECOG_GRPC_FUZZ_CONNECTION  make only the calls of that connection (to replay a failure;
//                               with --gtest_filter naming the failed case)
//   RECOG_GRPC_FUZZ_TRACE       a file that gets every call's frames (hex) before they are sent:
//                               after a crash, its last line is the call that caused it
// The campaign, 100,000 calls per case (200,000 in all; 7 to 13 minutes on 2 busy cores), from
// the project's root in CI's sanitizer build, with .ci/run's sanitizer options:
//   export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:intercept_tls_get_addr=0
//   export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
//   export LSAN_OPTIONS=suppressions=$PWD/.ci/lsan.supp
//   RECOG_GRPC_FUZZ_CALLS=100000 build-asan/tests/server_grpc_fuzz_test
#include <zlib.h>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>

#include "grpc/health/v1/health.grpc.pb.h"
#include "tests/server/server_fixture.h"
#include "tests/testing/raw_http2_client.h"

namespace recog::server::testing {
namespace {

namespace http2 = recog::testing::http2;
namespace protobuf = google::protobuf;
using recog::testing::RawHttp2Client;

constexpr char kAdmin[] = "admin-token-0123456789", kReader[] = "reader-token-0123456789";
// How long a batch of calls waits for the answers of those that ended with END_STREAM (generous:
// a batch may queue a dozen frames for the workers, and under the sanitizers).
constexpr auto kAnswerTimeout = std::chrono::seconds(30);
constexpr size_t kCheckEvery = 2000;
// The DATA of one call stays within the server's initial stream window (65,535 bytes).
constexpr size_t kMaxBody = 60000;

size_t EnvNumber(const char* name, size_t fallback) {
  const char* value = std::getenv(name);
  return value != nullptr && *value != '\0' ? size_t(std::strtoull(value, nullptr, 10)) : fallback;
}

// A method the generator calls: its path and request type (null when the descriptor pool does not
// have it).
struct Method {
  std::string path;
  const protobuf::Descriptor* request = nullptr;
  bool watch = false;  // a server stream that does not end when the client half-closes
};

// Every method of recogd's services, of the health service and of server reflection.
std::vector<Method> Methods() {
  std::vector<Method> methods;
  for (const char* name : {"recognition.v1.PlaceRecognition", "recognition.v1.ObjectRecognition",
                           "recognition.v1.ObjectRepository", "recognition.v1.Admin",
                           "grpc.health.v1.Health", "grpc.reflection.v1alpha.ServerReflection"}) {
    const protobuf::ServiceDescriptor* service =
        protobuf::DescriptorPool::generated_pool()->FindServiceByName(name);
    for (int i = 0; service != nullptr && i < service->method_count(); ++i) {
      const protobuf::MethodDescriptor* method = service->method(i);
      methods.push_back({"/" + service->full_name() + "/" + method->name(), method->input_type(),
                         method->name().starts_with("Watch")});
    }
  }
  // Reflection's path even when its descriptors are not in this binary's pool.
  const std::string reflection = "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo";
  if (std::none_of(methods.begin(), methods.end(),
                   [&](const Method& m) { return m.path == reflection; })) {
    methods.push_back({reflection, nullptr, false});
  }
  return methods;
}

// `bytes` compressed as gRPC's "gzip" (`gzip`) or "deflate" (zlib) encoding does.
std::string Compress(const std::string& bytes, bool gzip) {
  z_stream stream{};
  deflateInit2(&stream, Z_DEFAULT_COMPRESSION, Z_DEFLATED, gzip ? 31 : 15, 8, Z_DEFAULT_STRATEGY);
  std::string out(deflateBound(&stream, uLong(bytes.size())), '\0');
  stream.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
  stream.avail_in = uInt(bytes.size());
  stream.next_out = reinterpret_cast<Bytef*>(out.data());
  stream.avail_out = uInt(out.size());
  deflate(&stream, Z_FINISH);
  out.resize(stream.total_out);
  deflateEnd(&stream);
  return out;
}

// One call as made up: its stream, its frames in order, and how it ends.
struct CallPlan {
  enum class End {
    kHalfClose,  // END_STREAM (on DATA, HEADERS or client trailers): the server must answer
    kReset,      // a RST_STREAM at a random point
    kAbandon,    // no END_STREAM: left open until the connection closes
    kCut,        // the connection is closed in the middle of the last frame
    kGoaway,     // a GOAWAY after the call; the connection is closed once the batch is answered
  };
  uint32_t stream = 0;
  std::string path;
  std::vector<std::string> frames;  // whole frames
  End end = End::kHalfClose;
  bool watch = false;        // an endless server stream: its answer is not awaited
  bool valid_stream = true;  // false: a stream id that is a protocol error (see StreamId())
  size_t cut_bytes = 0;      // kCut: the bytes of the last frame sent
  bool abortive = false;     // kCut: close with a TCP reset rather than a FIN
  bool AwaitsAnswer() const { return end == End::kHalfClose && !watch; }
};

const char* EndName(CallPlan::End end) {
  switch (end) {
    case CallPlan::End::kHalfClose:
      return "half-close";
    case CallPlan::End::kReset:
      return "reset";
    case CallPlan::End::kAbandon:
      return "abandon";
    case CallPlan::End::kCut:
      return "cut";
    case CallPlan::End::kGoaway:
      return "goaway";
  }
  return "?";
}

// Makes up calls. Reseed() starts a connection: what it makes depends on the seed and the
// connection's number only, not on the server's answers.
class CallMaker {
 public:
  CallMaker(std::string authority, std::vector<std::string> tokens, std::string jpeg)
      : methods_(Methods()),
        authority_(std::move(authority)),
        tokens_(std::move(tokens)),
        jpeg_(std::move(jpeg)) {}

  size_t methods_known() const {
    return size_t(std::count_if(methods_.begin(), methods_.end(),
                                [](const Method& m) { return m.request != nullptr; }));
  }

  void Reseed(uint64_t seed, uint64_t connection) {
    std::seed_seq sequence{uint32_t(seed), uint32_t(seed >> 32), uint32_t(connection),
                           uint32_t(connection >> 32)};
    random_.seed(sequence);
    next_stream_ = 1;
  }

  size_t CallsOnConnection() {
    const double p = Uniform();
    return 1 + Index(p < 0.2 ? 5 : p < 0.7 ? 100 : 500);
  }
  size_t BatchSize() { return Chance(0.5) ? 1 : 1 + Index(16); }

  CallPlan Next() {
    CallPlan plan;
    plan.stream = StreamId(&plan.valid_stream);
    const Method* method = nullptr;
    plan.path = Path(&method);
    plan.watch = method != nullptr && method->watch;
    const double p = Uniform();
    plan.end = p < 0.855   ? CallPlan::End::kHalfClose
               : p < 0.935 ? CallPlan::End::kReset
               : p < 0.985 ? CallPlan::End::kAbandon
               : p < 0.995 ? CallPlan::End::kCut
                           : CallPlan::End::kGoaway;
    // gRPC closes the connection of a call whose grpc-encoding, te, content-type or grpc-timeout
    // it cannot parse (as it does when a pseudo-header is missing): such values are rare.
    const std::string encoding =
        Chance(0.25) ? Chance(0.97) ? Choose({"gzip", "deflate", "identity"})
                                    : Choose({"snappy", "gzip, deflate", "", "GZIP", Value()})
                     : "";
    const std::string body = Body(method == nullptr ? nullptr : method->request, encoding);
    const bool half_close = plan.end != CallPlan::End::kAbandon;
    const bool end_on_headers = half_close && body.empty() && Chance(0.7);
    const bool client_trailers = half_close && !end_on_headers && Chance(0.03);

    // HEADERS (and CONTINUATIONs).
    std::vector<http2::Header> headers = Headers(plan.path, encoding, plan.watch);
    const size_t fragment = Chance(0.85) ? http2::kDefaultMaxFrameSize : 1 + Index(64);
    AppendFrames(&plan.frames,
                 http2::HeaderFrames(plan.stream, Block(headers), end_on_headers, fragment));
    const size_t header_frames = plan.frames.size();
    // DATA.
    if (!end_on_headers) {
      size_t at = 0;
      do {
        const size_t piece = std::min(body.size() - at,
                                      Chance(0.85) ? http2::kDefaultMaxFrameSize : 1 + Index(2000));
        const bool last = at + piece >= body.size();
        const uint8_t flags = last && half_close && !client_trailers ? http2::kEndStream : 0;
        // Padded DATA is rare: gRPC closes the connection on it.
        if (Chance(0.002) && piece < http2::kDefaultMaxFrameSize - 256) {
          const std::string padding(Index(256), '\0');
          plan.frames.push_back(
              http2::Frame(http2::kData, uint8_t(flags | http2::kPadded), plan.stream,
                           char(padding.size()) + body.substr(at, piece) + padding));
        } else {
          plan.frames.push_back(
              http2::Frame(http2::kData, flags, plan.stream, body.substr(at, piece)));
        }
        at += piece;
      } while (at < body.size());
      if (client_trailers) {
        std::vector<http2::Header> trailers;
        for (size_t n = Index(3); n > 0; --n) trailers.push_back(Field());
        AppendFrames(&plan.frames, http2::HeaderFrames(plan.stream, Block(trailers), true));
      }
    }
    // Frames about the connection, between the call's; rarely inside its header block (where
    // nothing but CONTINUATION may come: a protocol error).
    if (Chance(0.04)) {
      for (size_t n = 1 + Index(2); n > 0; --n) {
        const size_t first = Chance(0.05) ? 0 : header_frames;
        plan.frames.insert(
            plan.frames.begin() + long(first + Index(plan.frames.size() - first + 1)),
            Noise(plan.stream));
      }
    }
    switch (plan.end) {
      case CallPlan::End::kReset: {
        // Mostly after the header block (inside it, the reset is a protocol error).
        const size_t first = Chance(0.05) ? 1 : header_frames;
        const size_t at = first + Index(plan.frames.size() - first + 1);
        // Mostly nothing more of the stream after its reset; sometimes the rest anyway.
        if (Chance(0.9)) plan.frames.resize(at);
        plan.frames.insert(
            plan.frames.begin() + long(at),
            http2::RstStream(plan.stream, Chance(0.8)
                                              ? http2::kCancel
                                              : uint32_t(Index(16)) ^ (Chance(0.1) ? 0xff00 : 0)));
        break;
      }
      case CallPlan::End::kCut:
        plan.frames.resize(1 + Index(plan.frames.size()));
        plan.cut_bytes = Index(plan.frames.back().size());
        plan.abortive = Chance(0.5);
        break;
      case CallPlan::End::kGoaway:
        plan.frames.push_back(http2::Goaway(Chance(0.8) ? plan.stream : uint32_t(Index(1u << 31)),
                                            Chance(0.7) ? http2::kNoError : uint32_t(Index(14)),
                                            Chance(0.2) ? Value() : ""));
        break;
      case CallPlan::End::kHalfClose:
      case CallPlan::End::kAbandon:
        break;
    }
    return plan;
  }

 private:
  double Uniform() { return std::uniform_real_distribution<double>(0, 1)(random_); }
  bool Chance(double p) { return Uniform() < p; }
  size_t Index(size_t n) { return std::uniform_int_distribution<size_t>(0, n - 1)(random_); }
  uint8_t Byte() { return uint8_t(Index(256)); }
  std::string Choose(std::initializer_list<std::string> values) {
    return *(values.begin() + long(Index(values.size())));
  }

  static void AppendFrames(std::vector<std::string>* frames, const std::string& bytes) {
    for (size_t at = 0; at < bytes.size();) {
      const size_t length = 9 + http2::ReadBigEndian(std::string_view(bytes).substr(at, 3));
      frames->push_back(bytes.substr(at, length));
      at += length;
    }
  }

  // Mostly the next odd id; rarely one that skips ahead (allowed), an even one, an old one, 0 or
  // the reserved bit: protocol errors (*valid is false) that gRPC may ignore, or answer by
  // dropping earlier streams without a word, so their connection is not used after that call.
  uint32_t StreamId(bool* valid) {
    uint32_t id = next_stream_;
    *valid = true;
    if (Chance(0.005)) {
      const double p = Uniform();
      *valid = p < 0.4;
      id = p < 0.4   ? next_stream_ + 2 * uint32_t(Index(1000))
           : p < 0.6 ? next_stream_ + 1
           : p < 0.8 ? (next_stream_ > 2 ? next_stream_ - 2 : 1)
           : p < 0.9 ? 0
                     : (next_stream_ | 0x80000000u);
    }
    const uint32_t masked = id & http2::kStreamIdMask;  // the server ignores the reserved bit
    if (masked % 2 == 1 && masked >= next_stream_ && masked < 0x7ffffff0u) {
      next_stream_ = masked + 2;
    }
    return id;
  }

  // A length: mostly short, some at the edges of size classes, some of several KB.
  size_t Length() {
    static constexpr size_t kEdges[] = {0, 1, 63, 64, 65, 127, 128, 255, 256, 1024};
    const double p = Uniform();
    if (p < 0.7) return Index(40);
    if (p < 0.9) return kEdges[Index(std::size(kEdges))];
    return 1000 + Index(7000);
  }

  std::string Printable(size_t n) {
    std::string s(n, ' ');
    for (char& c : s) c = char(0x20 + Index(0x5f));
    return s;
  }

  std::string AnyBytes(size_t n) {
    std::string s(n, '\0');
    for (char& c : s) c = char(Byte());
    return s;
  }

  // A metadata value: printable, printable but for one control or non-ASCII byte, any bytes,
  // bytes 0x80-0xff only, spaces around, or empty.
  std::string Value() {
    const size_t n = Length();
    switch (Index(8)) {
      case 0:
      case 1:
      case 2:
        return Printable(n);
      case 3: {
        std::string s = Printable(n);
        const uint8_t bad = Chance(0.5)   ? uint8_t(Index(0x20))
                            : Chance(0.1) ? 0x7f
                                          : uint8_t(0x80 + Index(0x80));
        s.insert(s.begin() + long(Index(s.size() + 1)), char(bad));
        return s;
      }
      case 4:
        return AnyBytes(n);
      case 5: {
        std::string s(n, '\0');
        for (char& c : s) c = char(0x80 + Index(0x80));
        return s;
      }
      case 6:
        return " " + Printable(n) + "\t";
      default:
        return "";
    }
  }

  // A value for a `-bin` key: base64 of any bytes, padded or not; rarely Value() (gRPC closes the
  // whole connection on a value that does not decode).
  std::string BinValue() {
    if (Chance(0.02)) return Value();
    static constexpr char kBase64[] =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const std::string bytes = AnyBytes(Length());
    std::string text;
    for (size_t i = 0; i < bytes.size(); i += 3) {
      uint32_t group = uint32_t(uint8_t(bytes[i])) << 16;
      if (i + 1 < bytes.size()) group |= uint32_t(uint8_t(bytes[i + 1])) << 8;
      if (i + 2 < bytes.size()) group |= uint8_t(bytes[i + 2]);
      const size_t chars = std::min<size_t>(4, bytes.size() - i + 1);
      for (size_t c = 0; c < chars; ++c) text += kBase64[(group >> (18 - 6 * c)) & 63];
    }
    if (Chance(0.5)) text.append((4 - text.size() % 4) % 4, '=');
    return text;
  }

  // A metadata key: mostly legal (lowercase), sometimes upper case, any bytes, empty, `-bin`,
  // or long.
  std::string Key() {
    static constexpr char kLegal[] = "abcdefghijklmnopqrstuvwxyz0123456789-_.";
    auto legal = [&](size_t n) {
      std::string s(n, 'a');
      for (char& c : s) c = kLegal[Index(sizeof(kLegal) - 1)];
      return s;
    };
    switch (Index(10)) {
      case 5:
        return "X-Fuzz-" + legal(1 + Index(10));
      case 6:
        return AnyBytes(1 + Index(20));
      case 7:
        return "";
      case 8:
        return "x-" + legal(Index(10)) + "-bin";
      case 9:
        return legal(100 + Index(2000));
      default:
        return "x-" + legal(1 + Index(20));
    }
  }

  // A metadata field of Key() with a value for it.
  http2::Header Field() {
    std::string key = Key();
    std::string value = key.ends_with("-bin") ? BinValue() : Value();
    return {std::move(key), std::move(value)};
  }

  // Half the time "Bearer <one of the tokens>", else one malformed or made up.
  std::string Authorization() {
    const std::string token = tokens_.empty() ? "nothing" : tokens_[Index(tokens_.size())];
    if (Chance(0.5)) return "Bearer " + token;
    switch (Index(5)) {
      case 0:
        return "bearer\t " + token + " ";
      case 1:
        return "Bearer " + token + " extra";
      case 2:
        return "Bearer ";
      case 3:
        return "Basic " + Printable(Length());
      default:
        return Value();
    }
  }

  // A path: mostly a real method's (sometimes mutated), else one made up.
  std::string Path(const Method** method) {
    if (Chance(0.88)) {
      *method = &methods_[Index(methods_.size())];
      std::string path = (*method)->path;
      if (Chance(0.05)) {
        switch (Index(5)) {
          case 0:
            path[Index(path.size())] = char(Byte());
            break;
          case 1:
            path.insert(Index(path.size() + 1), AnyBytes(1 + Index(4)));
            break;
          case 2:
            path.resize(Index(path.size()));
            break;
          case 3:
            std::transform(path.begin(), path.end(), path.begin(),
                           [](unsigned char c) { return char(std::toupper(c)); });
            break;
          default:
            path += Choose({"/", "?x=1", "/..", "%00", "#"});
            break;
        }
      }
      return path;
    }
    switch (Index(10)) {
      case 0:
      case 1:
      case 2:
        return Choose({"", "/", "*", "//", "/recognition.v1.PlaceRecognition/",
                       "/recognition.v1.PlaceRecognition/Nope", "/grpc.health.v1.Health",
                       "/nope.Service/Method", "http://127.0.0.1/grpc.health.v1.Health/Check"});
      case 3:
        return "/" + std::string(1000 + Index(5000), 'a');
      case 4:
        return AnyBytes(Length());  // mostly not a valid :path: the connection is closed
      default:
        return "/" + Printable(Length()) + "/" + Printable(Length());
    }
  }

  std::vector<http2::Header> Headers(const std::string& path, const std::string& encoding,
                                     bool watch) {
    std::vector<http2::Header> headers;
    auto add = [&](double p, std::string name, std::string value) {
      if (Chance(p)) headers.emplace_back(std::move(name), std::move(value));
    };
    // Pseudo-headers missing or not valid (the connection is closed) are rare.
    add(0.998, ":method", Chance(0.995) ? "POST" : Choose({"GET", "PUT", "post", "", "CONNECT"}));
    add(0.998, ":scheme", Chance(0.995) ? "http" : Choose({"https", "ftp", "", "HTTP"}));
    add(0.998, ":path", path);
    add(0.995, ":authority", Chance(0.99) ? authority_ : Value());
    if (Chance(0.005)) {
      headers.emplace_back(Choose({":status", ":protocol", ":fuzz", ":"}), Value());
    }
    add(0.995, "content-type",
        Chance(0.9) ? "application/grpc"
        : Chance(0.8)
            ? Choose({"application/grpc+proto", "application/grpc+json",
                      "application/grpc; charset=utf-8", "application/grpc+fuzz"})
            : Choose({"application/grpcx", "text/plain", "", "application/GRPC", Value()}));
    add(0.995, "te",
        Chance(0.995) ? "trailers" : Choose({"gzip", "", "trailers, deflate", Value()}));
    // Endless streams mostly get a short deadline, so that the server ends them itself.
    if (Chance(watch ? 0.6 : 0.3)) {
      std::string timeout = std::to_string(1 + Index(watch ? 200 : 100000000)) +
                            Choose({"H", "M", "S", "m", "u", "n"});
      if (watch) timeout = std::to_string(1 + Index(200)) + "m";
      if (Chance(0.03)) {
        timeout = Choose({"", "-1S", "1", "S", "99999999999H", "0n", "1.5S", "1s", "0x10S",
                          "123456789S", Value()});
      }
      headers.emplace_back("grpc-timeout", timeout);
    }
    if (!encoding.empty()) headers.emplace_back("grpc-encoding", encoding);
    add(0.2, "grpc-accept-encoding", Choose({"gzip", "identity,deflate,gzip", "", Value()}));
    add(0.3, "user-agent", Chance(0.5) ? "grpc-fuzz/1" : Value());
    add(0.5, "x-request-id", Chance(0.5) ? Printable(1 + Index(70)) : Value());
    add(tokens_.empty() ? 0.3 : 0.95, "authorization", Authorization());
    if (Chance(0.1)) {
      std::string key =
          Choose({"grpc-status", "grpc-message", "grpc-previous-rpc-attempts",
                  "grpc-retry-pushback-ms", "grpc-tags-bin", "grpc-trace-bin",
                  "grpc-internal-encoding-request", "grpc-status-details-bin", "grpc-timeout",
                  "grpc-encoding", "grpc-accept-encoding", "content-type", "x-request-id"});
      headers.emplace_back(key, key.ends_with("-bin") ? BinValue() : Value());
    }
    if (Chance(0.03)) {
      headers.emplace_back(Choose({"connection", "transfer-encoding", "upgrade", "host",
                                   "content-length", "keep-alive", "proxy-connection"}),
                           Value());
    }
    const double p = Uniform();
    const size_t extra = p < 0.7 ? Index(4) : p < 0.97 ? Index(20) : Index(300);
    for (size_t n = 0; n < extra; ++n) headers.push_back(Field());
    // gRPC closes the connection of a call whose header list is over 8 KiB (counting 32 bytes per
    // field): mostly the last fields are dropped to stay below; some calls get a huge one more.
    if (Chance(0.97)) {
      auto size = [&] {
        size_t bytes = 0;
        for (const auto& [name, value] : headers) bytes += name.size() + value.size() + 32;
        return bytes;
      };
      while (size() > 7000 && headers.size() > 4) headers.pop_back();
    } else {
      headers.emplace_back("x-long", Printable(1000 + Index(20000)));
    }
    if (Chance(0.02) && !headers.empty()) headers.push_back(headers[Index(headers.size())]);
    if (Chance(0.02)) std::shuffle(headers.begin(), headers.end(), random_);
    return headers;
  }

  // The header block: literals of every kind (names and values as they are), the static table's
  // entries for some; rarely a table size update, a dynamic index that may not exist, a Huffman
  // string of random bits, bytes added or the block cut short.
  std::string Block(const std::vector<http2::Header>& headers) {
    std::string block;
    if (Chance(0.005)) {
      block += http2::HpackTableSizeUpdate(Chance(0.8) ? Index(4097) : Index(1u << 20));
    }
    for (const auto& [name, value] : headers) {
      const double p = Uniform();
      const size_t name_index = http2::StaticNameIndex(name);
      const auto full = std::find(std::begin(http2::kStaticTable), std::end(http2::kStaticTable),
                                  std::pair<std::string_view, std::string_view>(name, value));
      if (p < 0.8) {
        block += http2::HpackLiteral(name, value);
      } else if (p < 0.88) {
        block += http2::HpackLiteral(name, value, http2::Indexing::kIncremental);
      } else if (p < 0.93) {
        block += http2::HpackLiteral(name, value, http2::Indexing::kNever);
      } else if (full != std::end(http2::kStaticTable)) {
        block += http2::HpackIndexed(size_t(full - std::begin(http2::kStaticTable)) + 1);
      } else if (name_index > 0) {
        block += http2::HpackLiteralIndexedName(name_index, value);
      } else {
        block += http2::HpackLiteral(name, value);
      }
    }
    if (Chance(0.002)) block += http2::HpackIndexed(http2::kStaticTableSize + 1 + Index(100));
    if (Chance(0.002)) {
      const std::string bits = AnyBytes(Length());
      block += '\0';
      http2::AppendHpackInteger(&block, 0x80, 7, bits.size());  // the Huffman bit set
      block += bits;
      http2::AppendHpackString(&block, "x");
    }
    if (Chance(0.002)) block += AnyBytes(1 + Index(8));
    if (Chance(0.002)) block.resize(Index(block.size() + 1));
    return block;
  }

  // Strings of requests: names the server knows or may, and some it should refuse.
  std::string Text() {
    switch (Index(8)) {
      case 0:
        return Choose({"fuzz", "fuzz-2", "crate", "group:fuzz", "*", "", "fuzz*", "..", "a/b"});
      case 1:
        return Printable(Length());
      case 2:
        return "\xC3\xA9t\xC3\xA9";  // UTF-8
      case 3:
        return Printable(1000 + Index(4000));
      case 4:
        return Chance(0.1) ? std::string(64, 'a') : "fuzz";  // a SHA-256 in hex
      default:
        return "fuzz";
    }
  }

  // Fills `message` at random: each field set or not, numbers at their edges, strings from Text()
  // (valid UTF-8: protobuf refuses to serialize other strings), bytes random or a JPEG.
  void Fill(protobuf::Message* message, int depth) {
    const protobuf::Descriptor* type = message->GetDescriptor();
    const protobuf::Reflection* reflection = message->GetReflection();
    for (int i = 0; i < type->field_count(); ++i) {
      const protobuf::FieldDescriptor* field = type->field(i);
      if (Chance(0.4)) continue;
      const size_t count = field->is_repeated() ? Index(4) : 1;
      for (size_t n = 0; n < count; ++n) {
        const bool repeated = field->is_repeated();
        const int64_t number =
            Chance(0.7) ? int64_t(Index(100)) : std::vector<int64_t>{-1,
                                                                     0,
                                                                     1,
                                                                     INT32_MAX,
                                                                     INT32_MIN,
                                                                     int64_t(UINT32_MAX),
                                                                     int64_t(1) << 40,
                                                                     INT64_MAX,
                                                                     INT64_MIN}[Index(9)];
        const double real = Chance(0.7)
                                ? Uniform() * 100
                                : std::vector<double>{-1.0,     0.0,       -0.0, 1e308, -1e308,
                                                      INFINITY, -INFINITY, NAN,  5e-324}[Index(9)];
        switch (field->cpp_type()) {
          case protobuf::FieldDescriptor::CPPTYPE_INT32:
            repeated ? reflection->AddInt32(message, field, int32_t(number))
                     : reflection->SetInt32(message, field, int32_t(number));
            break;
          case protobuf::FieldDescriptor::CPPTYPE_INT64:
            repeated ? reflection->AddInt64(message, field, number)
                     : reflection->SetInt64(message, field, number);
            break;
          case protobuf::FieldDescriptor::CPPTYPE_UINT32:
            repeated ? reflection->AddUInt32(message, field, uint32_t(number))
                     : reflection->SetUInt32(message, field, uint32_t(number));
            break;
          case protobuf::FieldDescriptor::CPPTYPE_UINT64:
            repeated ? reflection->AddUInt64(message, field, uint64_t(number))
                     : reflection->SetUInt64(message, field, uint64_t(number));
            break;
          case protobuf::FieldDescriptor::CPPTYPE_DOUBLE:
            repeated ? reflection->AddDouble(message, field, real)
                     : reflection->SetDouble(message, field, real);
            break;
          case protobuf::FieldDescriptor::CPPTYPE_FLOAT:
            repeated ? reflection->AddFloat(message, field, float(real))
                     : reflection->SetFloat(message, field, float(real));
            break;
          case protobuf::FieldDescriptor::CPPTYPE_BOOL:
            repeated ? reflection->AddBool(message, field, Chance(0.5))
                     : reflection->SetBool(message, field, Chance(0.5));
            break;
          case protobuf::FieldDescriptor::CPPTYPE_ENUM: {
            // Open (proto3) enums: a known value or any number.
            const int value =
                Chance(0.8) ? field->enum_type()
                                  ->value(int(Index(size_t(field->enum_type()->value_count()))))
                                  ->number()
                            : int(number);
            repeated ? reflection->AddEnumValue(message, field, value)
                     : reflection->SetEnumValue(message, field, value);
            break;
          }
          case protobuf::FieldDescriptor::CPPTYPE_STRING: {
            const bool bytes = field->type() == protobuf::FieldDescriptor::TYPE_BYTES;
            const std::string value = !bytes         ? Text()
                                      : Chance(0.03) ? jpeg_
                                      : Chance(0.05) ? jpeg_.substr(0, Index(jpeg_.size()))
                                                     : AnyBytes(Length());
            repeated ? reflection->AddString(message, field, value)
                     : reflection->SetString(message, field, value);
            break;
          }
          case protobuf::FieldDescriptor::CPPTYPE_MESSAGE:
            if (depth < 4) {
              Fill(repeated ? reflection->AddMessage(message, field)
                            : reflection->MutableMessage(message, field),
                   depth + 1);
            }
            break;
        }
      }
    }
  }

  // A request of type `type` (random bytes when unknown), sometimes with bytes changed.
  std::string Payload(const protobuf::Descriptor* type) {
    if (type == nullptr || Chance(0.1)) return AnyBytes(Length());
    std::unique_ptr<protobuf::Message> message(
        protobuf::MessageFactory::generated_factory()->GetPrototype(type)->New());
    Fill(message.get(), 0);
    std::string bytes = message->SerializeAsString();
    if (Chance(0.1) && !bytes.empty()) {
      switch (Index(3)) {
        case 0:
          for (size_t n = 1 + Index(4); n > 0; --n) bytes[Index(bytes.size())] = char(Byte());
          break;
        case 1:
          bytes.resize(Index(bytes.size()));
          break;
        default:
          bytes.insert(Index(bytes.size() + 1), AnyBytes(1 + Index(8)));
          break;
      }
    }
    return bytes;
  }

  // The DATA of a call: zero to three length-prefixed messages; compressed (as `encoding` says,
  // or not though flagged so), prefixes that lie, a message cut short.
  std::string Body(const protobuf::Descriptor* type, const std::string& encoding) {
    const double p = Uniform();
    const size_t messages = p < 0.1 ? 0 : p < 0.92 ? 1 : 2 + Index(2);
    std::string body;
    for (size_t i = 0; i < messages; ++i) {
      std::string payload = Payload(type);
      uint8_t flag = 0;
      if ((encoding == "gzip" || encoding == "deflate") && Chance(0.7)) {
        payload = Compress(payload, encoding == "gzip");
        flag = 1;
      } else if (Chance(0.05)) {
        flag = 1;
      } else if (Chance(0.01)) {
        flag = uint8_t(2 + Index(254));
      }
      std::optional<uint32_t> length;
      if (Chance(0.1)) {
        const uint32_t size = uint32_t(payload.size());
        length = std::vector<uint32_t>{size - std::min<uint32_t>(size, 1 + uint32_t(Index(16))),
                                       size + 1 + uint32_t(Index(100)),
                                       0,
                                       0xffffffffu,
                                       0x7fffffffu,
                                       (32u << 20) + 1,
                                       1u << 24}[Index(7)];
      }
      std::string message = http2::GrpcMessage(payload, flag, length);
      if (Chance(0.02)) message.resize(Index(message.size()));
      body += message;
    }
    if (body.size() > kMaxBody) body.resize(kMaxBody);
    return body;
  }

  // A frame about the connection: mostly allowed ones (PRIORITY, SETTINGS, WINDOW_UPDATE, unknown
  // types, a PING now and then); rarely one that is a connection error.
  std::string Noise(uint32_t stream) {
    if (Chance(0.9)) {
      switch (Index(10)) {
        case 0:
          return http2::Ping(random_());
        case 1:
        case 2:
          return http2::Frame(http2::kPriority, 0, stream,
                              http2::BigEndian(Index(stream + 1), 4) + char(Byte()));
        case 3:
        case 4:
          return http2::Settings({{http2::kMaxHeaderListSize, uint32_t(Index(1u << 20))},
                                  {http2::kMaxConcurrentStreams, uint32_t(Index(200))},
                                  {http2::kEnablePush, 0},
                                  {uint16_t(7 + Index(100)), uint32_t(random_())}});
        case 5:
        case 6:
          return http2::WindowUpdate(Chance(0.5) ? 0 : stream, 1 + uint32_t(Index(65535)));
        default:
          return http2::Frame(uint8_t(0x0a + Index(0xf6)), Byte(), uint32_t(Index(stream + 2)),
                              AnyBytes(Index(64)));
      }
    }
    switch (Index(11)) {
      case 0:
        return http2::Settings({{http2::kEnablePush, 2}});
      case 1:
        return http2::Settings({{http2::kInitialWindowSize, 0x80000000u}});
      case 2:
        return http2::Settings({{http2::kMaxFrameSize, Chance(0.5) ? 100 : 1u << 24}});
      case 3:
        return http2::Frame(http2::kSettings, 0, Chance(0.5) ? 0 : stream, AnyBytes(1 + Index(11)));
      case 4:
        return http2::WindowUpdate(Chance(0.5) ? 0 : stream, Chance(0.5) ? 0 : http2::kMaxWindow);
      case 5:
        return http2::Frame(http2::kData, 0, 0, AnyBytes(Index(10)));
      case 6:
        return http2::Frame(http2::kContinuation, http2::kEndHeaders, stream, AnyBytes(Index(10)));
      case 7:
        return http2::Frame(http2::kPushPromise, http2::kEndHeaders, stream,
                            http2::BigEndian(stream + 1, 4));
      case 8:
        return http2::Frame(http2::kPing, 0, Chance(0.5) ? 0 : stream, AnyBytes(Index(16)));
      case 9:
        return http2::Frame(uint8_t(0x0a + Index(0xf6)), 0, 0,
                            std::string(http2::kDefaultMaxFrameSize + 1 + Index(1000), 'x'));
      default:
        return http2::Frame(http2::kRstStream, 0, 0, AnyBytes(Index(8)));
    }
  }

  std::vector<Method> methods_;
  std::string authority_;
  std::vector<std::string> tokens_;
  std::string jpeg_;
  std::mt19937_64 random_;
  uint32_t next_stream_ = 1;
};

class GrpcFuzzTest : public ServerFixture {
 protected:
  // `calls` made-up calls, checking that the server serves every kCheckEvery calls and at the end.
  void Fuzz(const std::vector<std::string>& tokens, const std::string& token) {
    const size_t calls = EnvNumber("RECOG_GRPC_FUZZ_CALLS", 6000);
    const uint64_t seed = EnvNumber("RECOG_GRPC_FUZZ_SEED", 1);
    const char* only = std::getenv("RECOG_GRPC_FUZZ_CONNECTION");
    const char* trace_path = std::getenv("RECOG_GRPC_FUZZ_TRACE");
    std::unique_ptr<FILE, int (*)(FILE*)> trace(
        trace_path != nullptr ? std::fopen(trace_path, "w") : nullptr, &std::fclose);
    ASSERT_TRUE(CreateMap("fuzz", token).ok());
    const int port = server_->port();
    CallMaker maker("127.0.0.1:" + std::to_string(port), tokens, CorridorJpeg(1));
    ASSERT_GE(maker.methods_known(), 20u);

    std::map<std::string, size_t> outcomes, connection_ends;
    size_t made = 0, connections = 0, next_check = kCheckEvery;
    std::vector<std::string> unanswered;  // the first calls that got no answer
    const auto start = std::chrono::steady_clock::now();
    for (uint64_t connection = 0; made < calls; ++connection) {
      if (only != nullptr && connection != std::strtoull(only, nullptr, 10)) {
        if (connection > std::strtoull(only, nullptr, 10)) break;
        continue;
      }
      maker.Reseed(seed, connection);
      ++connections;
      RawHttp2Client client(port);
      ASSERT_TRUE(client.open()) << "cannot connect after " << made << " calls";
      const size_t planned = std::min(calls - made, maker.CallsOnConnection());
      // `ours`: the fuzzer cut the connection, or broke its streams with a stream id that is a
      // protocol error (gRPC may then drop earlier streams silently): the batch's answers are not
      // awaited, and the connection is not used any more.
      bool usable = true, ours = false;
      for (size_t call = 0; call < planned && usable;) {
        // A batch: its calls sent one after the other, then their answers read.
        std::vector<CallPlan> batch;
        for (size_t n = maker.BatchSize(); n > 0 && call < planned && usable; --n, ++call) {
          batch.push_back(maker.Next());
          const CallPlan& plan = batch.back();
          ++made;
          if (trace != nullptr) Trace(trace.get(), connection, call, plan);
          usable = Send(&client, plan) && plan.valid_stream;
          ours = ours || plan.end == CallPlan::End::kCut || !plan.valid_stream;
        }
        if (!ours) Await(&client, batch);
        for (const CallPlan& plan : batch) {
          const std::string outcome = Outcome(&client, plan, ours);
          ++outcomes[outcome];
          if (outcome == "no answer" && unanswered.size() < 10) {
            unanswered.push_back("seed " + std::to_string(seed) + " connection " +
                                 std::to_string(connection) + " stream " +
                                 std::to_string(plan.stream) + " " + plan.path);
          }
          // The server keeps no stream open for the fuzzer (abandoned ones last until the close).
          if (client.open() && !client.stream(plan.stream).ended &&
              plan.end != CallPlan::End::kAbandon) {
            client.Send(http2::RstStream(plan.stream, http2::kCancel));
          }
          client.Forget(plan.stream);
        }
        usable = usable && client.open() && !client.goaway_error().has_value();
      }
      ASSERT_FALSE(client.decode_failed()) << "connection " << connection << " (seed " << seed
                                           << "): a header block of the server was not understood";
      ++connection_ends[client.goaway_error().has_value()
                            ? "server GOAWAY " + std::to_string(*client.goaway_error())
                        : ours            ? "broken by the fuzzer"
                        : client.closed() ? "closed by the server"
                                          : "closed by the fuzzer"];
      client.Close(/*abortive=*/connection % 2 == 1);
      if (made >= next_check) {
        ASSERT_NO_FATAL_FAILURE(ExpectServing(token, "after " + std::to_string(made) + " calls"));
        next_check += kCheckEvery;
      }
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::string summary;
    for (const auto& [outcome, count] : outcomes) {
      summary += "; " + outcome + ": " + std::to_string(count);
    }
    std::string ends;
    for (const auto& [end, count] : connection_ends) {
      ends += "; " + end + ": " + std::to_string(count);
    }
    std::printf(
        "grpc fuzz (seed %llu): %zu calls on %zu connections in %.1f s, %.0f calls/s%s "
        "| connections%s\n",
        static_cast<unsigned long long>(seed), made, connections, seconds, double(made) / seconds,
        summary.c_str(), ends.c_str());
    std::fflush(stdout);

    for (const std::string& call : unanswered) ADD_FAILURE() << "no answer: " << call;
    if (only == nullptr) {
      // The calls reached the services: some succeeded, some were refused by their checks.
      EXPECT_GT(outcomes["grpc-status 0"], made / 50);
      EXPECT_GT(outcomes["grpc-status 3"], made / 100);
    }
    ASSERT_NO_FATAL_FAILURE(ExpectServing(token, "at the end"));
    // Real frames of the corridor: added to a map of its own (the fuzzer may delete "fuzz") and
    // found again.
    ASSERT_TRUE(CreateMap("after-fuzz", token).ok());
    for (int n : {1, 20, 41, 60}) {
      pb::AddFrameRequest add;
      add.set_map("after-fuzz");
      *add.mutable_frame() = JpegFrame(CorridorJpeg(n));
      pb::AddFrameResponse added;
      const grpc::Status status = places_->AddFrame(Context(token).get(), add, &added);
      ASSERT_TRUE(status.ok()) << status.error_message();
    }
    const grpc::Status queried = QueryCorridorFrame("after-fuzz", 20, token);
    EXPECT_TRUE(queried.ok()) << queried.error_message();
  }

  grpc::Status CreateMap(const std::string& name, const std::string& token) {
    pb::CreateMapRequest request;
    request.set_name(name);
    pb::CreateMapResponse response;
    return places_->CreateMap(Context(token).get(), request, &response);
  }

  // The server answers ListMaps and the health check through the generated stubs.
  void ExpectServing(const std::string& token, const std::string& when) {
    pb::ListMapsResponse maps;
    const grpc::Status listed = places_->ListMaps(Context(token).get(), {}, &maps);
    ASSERT_TRUE(listed.ok()) << when << ": " << listed.error_message();
    auto health = ::grpc::health::v1::Health::NewStub(channel_);
    ::grpc::health::v1::HealthCheckResponse serving;
    const grpc::Status checked = health->Check(Context().get(), {}, &serving);
    ASSERT_TRUE(checked.ok()) << when << ": " << checked.error_message();
    ASSERT_EQ(serving.status(), ::grpc::health::v1::HealthCheckResponse::SERVING) << when;
  }

  // Sends the frames of `plan`; false when the connection is no longer to be used.
  static bool Send(RawHttp2Client* client, const CallPlan& plan) {
    for (size_t i = 0; i < plan.frames.size(); ++i) {
      if (plan.end == CallPlan::End::kCut && i + 1 == plan.frames.size()) {
        client->Send(std::string_view(plan.frames[i]).substr(0, plan.cut_bytes));
        client->Close(plan.abortive);
        return false;
      }
      if (!client->SendFrame(plan.frames[i])) return false;
    }
    return plan.end != CallPlan::End::kGoaway;
  }

  // Reads answers until every call of `batch` that awaits one has it, the connection is gone, or
  // kAnswerTimeout passed.
  static void Await(RawHttp2Client* client, const std::vector<CallPlan>& batch) {
    const auto until = std::chrono::steady_clock::now() + kAnswerTimeout;
    auto waiting = [&] {
      return std::any_of(batch.begin(), batch.end(), [&](const CallPlan& plan) {
        return plan.AwaitsAnswer() && !client->stream(plan.stream).ended;
      });
    };
    while (client->open() && waiting() && std::chrono::steady_clock::now() < until) {
      client->Poll(std::chrono::milliseconds(50));
    }
  }

  // What became of a call: the server's grpc-status, its RST_STREAM, its HTTP status without
  // grpc-status, the connection's GOAWAY or close; else it was the fuzzer that ended it (the call,
  // or the connection: `ours`), or it got no answer.
  static std::string Outcome(RawHttp2Client* client, const CallPlan& plan, bool ours) {
    const RawHttp2Client::StreamEnd& end = client->stream(plan.stream);
    if (end.grpc_status.has_value()) return "grpc-status " + std::to_string(*end.grpc_status);
    if (end.reset.has_value()) return "RST_STREAM";
    if (end.ended) return "HTTP " + end.http_status;
    if (!plan.AwaitsAnswer() || ours) return "ended by the fuzzer";
    if (client->goaway_error().has_value()) return "GOAWAY";
    if (client->closed()) return "connection closed";
    return "no answer";
  }

  // One line per call: where it was made, how it ends, its frames in hex (of the last frame of a
  // cut call, only the first cut_bytes are sent).
  static void Trace(FILE* trace, uint64_t connection, size_t call, const CallPlan& plan) {
    std::fprintf(trace, "connection %llu call %zu stream %u %s",
                 static_cast<unsigned long long>(connection), call, plan.stream, EndName(plan.end));
    if (plan.end == CallPlan::End::kCut) std::fprintf(trace, " after %zu bytes", plan.cut_bytes);
    std::fputc(':', trace);
    for (const std::string& frame : plan.frames) {
      std::fputc(' ', trace);
      for (unsigned char c : frame) std::fprintf(trace, "%02x", c);
    }
    std::fputc('\n', trace);
    std::fflush(trace);
  }
};

TEST_F(GrpcFuzzTest, RandomCallsWithoutTokensLeaveTheServerServing) { Fuzz({}, ""); }

TEST_F(GrpcFuzzTest, RandomCallsWithTokensLeaveTheServerServing) {
  const std::string tokens = data_dir_.Sub("tokens.yaml");
  std::ofstream(tokens) << "tokens:\n"
                        << "  - name: admin\n    token: " << kAdmin << "\n    rights: [write]\n"
                        << "  - name: reader\n    token: " << kReader << "\n    rights: [read]\n";
  StopServer();
  config().token_file = tokens;
  StartServer();
  Fuzz({kAdmin, kReader, "not-a-token-0123456789"}, kAdmin);
}

}  // namespace
}  // namespace recog::server::testing

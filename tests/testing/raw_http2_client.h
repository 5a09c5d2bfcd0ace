// RawHttp2Client: a small HTTP/2 client on plain TCP (no TLS), for tests that must send what
// gRPC's own client refuses to: metadata bytes that are not legal, message prefixes that lie,
// frames cut short, resets and GOAWAYs at any point (tests/server/grpc_fuzz_test.cc).
//
// Sending. The functions of namespace http2 build frames (RFC 9113, section 6) and HPACK header
// blocks (RFC 7541) from bytes taken as they are: literal fields are never Huffman-coded, so a name
// or value may hold any byte 0-255. The client sends whatever it is given: SendFrame() for whole
// frames (a DATA frame waits for the server's connection window first), Send() for any bytes.
//
// Receiving. Poll() reads what the server sent and keeps, per stream, how it ended: the `:status`
// and `grpc-status` of its header blocks (a trailers-only answer is one HEADERS with END_STREAM),
// or the server's RST_STREAM; for the connection, a GOAWAY and whether it was closed. The client
// acknowledges the server's SETTINGS and PINGs. Flow control: at the start the client grants the
// server 2^31-1 bytes on the connection and on every stream, so it never sends a WINDOW_UPDATE
// while reading; of the server's windows it tracks only the connection's (RFC 9113, section 6.9),
// which test payloads stay within per stream. The server's header blocks are decoded with HPACK's
// static and dynamic tables; Huffman-coded strings are not decoded (gRPC Huffman-codes only the
// values of `-bin` keys, which these tests never need): a block with one marks the connection as
// not understood (decode_failed()), and the client stops reading it.
#pragma once

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <deque>
#include <iterator>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace recog::testing {
namespace http2 {

constexpr std::string_view kPreface = "PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n";

// Frame types.
constexpr uint8_t kData = 0x0, kHeaders = 0x1, kPriority = 0x2, kRstStream = 0x3, kSettings = 0x4,
                  kPushPromise = 0x5, kPing = 0x6, kGoaway = 0x7, kWindowUpdate = 0x8,
                  kContinuation = 0x9;
// Flags (END_STREAM and ACK share a bit).
constexpr uint8_t kEndStream = 0x1, kAck = 0x1, kEndHeaders = 0x4, kPadded = 0x8,
                  kPriorityFlag = 0x20;
// Settings.
constexpr uint16_t kEnablePush = 0x2, kMaxConcurrentStreams = 0x3, kInitialWindowSize = 0x4,
                   kMaxFrameSize = 0x5, kMaxHeaderListSize = 0x6;
// Error codes (RST_STREAM, GOAWAY).
constexpr uint32_t kNoError = 0x0, kCancel = 0x8;

constexpr uint32_t kDefaultMaxFrameSize = 16384;  // until the peer's SETTINGS say otherwise
constexpr uint32_t kDefaultWindow = 65535;
constexpr uint32_t kMaxWindow = 0x7fffffff;
constexpr uint32_t kStreamIdMask = 0x7fffffff;  // a stream id without the reserved bit

// `value`'s low `bytes` bytes, most significant first.
inline std::string BigEndian(uint64_t value, int bytes) {
  std::string out(size_t(bytes), '\0');
  for (int i = bytes - 1; i >= 0; --i, value >>= 8) out[size_t(i)] = char(value & 0xff);
  return out;
}

inline uint32_t ReadBigEndian(std::string_view bytes) {
  uint32_t value = 0;
  for (unsigned char c : bytes) value = value << 8 | c;
  return value;
}

// A frame: 24-bit length, type, flags, 31-bit stream id (the reserved bit as given), payload
// (shorter than 2^24 bytes).
inline std::string Frame(uint8_t type, uint8_t flags, uint32_t stream, std::string_view payload) {
  std::string frame = BigEndian(payload.size(), 3);
  frame += char(type);
  frame += char(flags);
  frame += BigEndian(stream, 4);
  frame += payload;
  return frame;
}

inline std::string Settings(const std::vector<std::pair<uint16_t, uint32_t>>& settings) {
  std::string payload;
  for (const auto& [id, value] : settings) payload += BigEndian(id, 2) + BigEndian(value, 4);
  return Frame(kSettings, 0, 0, payload);
}

inline std::string RstStream(uint32_t stream, uint32_t error) {
  return Frame(kRstStream, 0, stream, BigEndian(error, 4));
}

inline std::string Goaway(uint32_t last_stream, uint32_t error, std::string_view debug = {}) {
  return Frame(kGoaway, 0, 0, BigEndian(last_stream, 4) + BigEndian(error, 4) + std::string(debug));
}

inline std::string Ping(uint64_t opaque, bool ack = false) {
  return Frame(kPing, ack ? kAck : 0, 0, BigEndian(opaque, 8));
}

inline std::string WindowUpdate(uint32_t stream, uint32_t increment) {
  return Frame(kWindowUpdate, 0, stream, BigEndian(increment, 4));
}

// A gRPC length-prefixed message: the compressed flag, the length (big-endian; `payload`'s own
// unless `declared_length` lies), the payload.
inline std::string GrpcMessage(std::string_view payload, uint8_t compressed_flag = 0,
                               std::optional<uint32_t> declared_length = std::nullopt) {
  return char(compressed_flag) + BigEndian(declared_length.value_or(uint32_t(payload.size())), 4) +
         std::string(payload);
}

// HPACK (RFC 7541). An integer with an N-bit prefix (section 5.1); `first` holds the bits above it.
inline void AppendHpackInteger(std::string* out, uint8_t first, int prefix_bits, uint64_t value) {
  const uint64_t max = (uint64_t(1) << prefix_bits) - 1;
  if (value < max) {
    *out += char(first | value);
    return;
  }
  *out += char(first | max);
  for (value -= max; value >= 128; value >>= 7) *out += char(0x80 | (value & 0x7f));
  *out += char(value);
}

// A string literal, not Huffman-coded: its bytes as they are.
inline void AppendHpackString(std::string* out, std::string_view bytes) {
  AppendHpackInteger(out, 0x00, 7, bytes.size());
  *out += bytes;
}

// How a literal field is to be indexed by the decoder (section 6.2): the representation's bits.
enum class Indexing : uint8_t { kWithout = 0x00, kNever = 0x10, kIncremental = 0x40 };

// A literal field with a new name.
inline std::string HpackLiteral(std::string_view name, std::string_view value,
                                Indexing indexing = Indexing::kWithout) {
  std::string out(1, char(indexing));
  AppendHpackString(&out, name);
  AppendHpackString(&out, value);
  return out;
}

// A literal field whose name is entry `name_index` of the tables.
inline std::string HpackLiteralIndexedName(uint64_t name_index, std::string_view value,
                                           Indexing indexing = Indexing::kWithout) {
  std::string out;
  AppendHpackInteger(&out, uint8_t(indexing), indexing == Indexing::kIncremental ? 6 : 4,
                     name_index);
  AppendHpackString(&out, value);
  return out;
}

// A field that is entry `index` of the tables (section 6.1).
inline std::string HpackIndexed(uint64_t index) {
  std::string out;
  AppendHpackInteger(&out, 0x80, 7, index);
  return out;
}

// A dynamic table size update (section 6.3).
inline std::string HpackTableSizeUpdate(uint64_t size) {
  std::string out;
  AppendHpackInteger(&out, 0x20, 5, size);
  return out;
}

// HPACK's static table (RFC 7541, appendix A); entry i is kStaticTable[i - 1].
inline constexpr std::pair<std::string_view, std::string_view> kStaticTable[] = {
    {":authority", ""},
    {":method", "GET"},
    {":method", "POST"},
    {":path", "/"},
    {":path", "/index.html"},
    {":scheme", "http"},
    {":scheme", "https"},
    {":status", "200"},
    {":status", "204"},
    {":status", "206"},
    {":status", "304"},
    {":status", "400"},
    {":status", "404"},
    {":status", "500"},
    {"accept-charset", ""},
    {"accept-encoding", "gzip, deflate"},
    {"accept-language", ""},
    {"accept-ranges", ""},
    {"accept", ""},
    {"access-control-allow-origin", ""},
    {"age", ""},
    {"allow", ""},
    {"authorization", ""},
    {"cache-control", ""},
    {"content-disposition", ""},
    {"content-encoding", ""},
    {"content-language", ""},
    {"content-length", ""},
    {"content-location", ""},
    {"content-range", ""},
    {"content-type", ""},
    {"cookie", ""},
    {"date", ""},
    {"etag", ""},
    {"expect", ""},
    {"expires", ""},
    {"from", ""},
    {"host", ""},
    {"if-match", ""},
    {"if-modified-since", ""},
    {"if-none-match", ""},
    {"if-range", ""},
    {"if-unmodified-since", ""},
    {"last-modified", ""},
    {"link", ""},
    {"location", ""},
    {"max-forwards", ""},
    {"proxy-authenticate", ""},
    {"proxy-authorization", ""},
    {"range", ""},
    {"referer", ""},
    {"refresh", ""},
    {"retry-after", ""},
    {"server", ""},
    {"set-cookie", ""},
    {"strict-transport-security", ""},
    {"transfer-encoding", ""},
    {"user-agent", ""},
    {"vary", ""},
    {"via", ""},
    {"www-authenticate", ""},
};
constexpr size_t kStaticTableSize = std::size(kStaticTable);

// The index of `name` in the static table (its first entry), 0 when it has none.
inline size_t StaticNameIndex(std::string_view name) {
  for (size_t i = 0; i < kStaticTableSize; ++i) {
    if (kStaticTable[i].first == name) return i + 1;
  }
  return 0;
}

// A header block as HEADERS and, when longer than `fragment` bytes, CONTINUATION frames.
inline std::string HeaderFrames(uint32_t stream, std::string_view block, bool end_stream,
                                size_t fragment = kDefaultMaxFrameSize) {
  std::string frames;
  size_t at = 0;
  do {
    const std::string_view piece = block.substr(at, fragment);
    at += piece.size();
    const uint8_t flags = uint8_t((at >= block.size() ? kEndHeaders : 0) |
                                  (frames.empty() && end_stream ? kEndStream : 0));
    frames += Frame(frames.empty() ? kHeaders : kContinuation, flags, stream, piece);
  } while (at < block.size());
  return frames;
}

using Header = std::pair<std::string, std::string>;

// Decodes the header blocks of one connection's direction (its dynamic table lives across blocks).
class HpackDecoder {
 public:
  // Appends the fields of `block` to `headers`; false when the block is malformed or holds a
  // Huffman-coded string.
  bool Decode(std::string_view block, std::vector<Header>* headers) {
    while (!block.empty()) {
      const uint8_t first = uint8_t(block[0]);
      uint64_t index = 0;
      if (first & 0x80) {  // indexed field
        Header header;
        if (!ReadInteger(&block, 7, &index) || !Lookup(index, &header)) return false;
        headers->push_back(std::move(header));
        continue;
      }
      if ((first & 0xe0) == 0x20) {  // dynamic table size update
        if (!ReadInteger(&block, 5, &index) || index > kMaxTableSize) return false;
        max_size_ = size_t(index);
        Evict();
        continue;
      }
      const bool incremental = first & 0x40;
      Header header;
      if (!ReadInteger(&block, incremental ? 6 : 4, &index)) return false;
      if (index == 0 ? !ReadString(&block, &header.first) : !Lookup(index, &header)) return false;
      if (!ReadString(&block, &header.second)) return false;
      if (incremental) Insert(header);
      headers->push_back(std::move(header));
    }
    return true;
  }

 private:
  static constexpr size_t kMaxTableSize = 4096;  // SETTINGS_HEADER_TABLE_SIZE, never changed
  static constexpr size_t kEntryOverhead = 32;

  static bool ReadInteger(std::string_view* in, int prefix_bits, uint64_t* value) {
    if (in->empty()) return false;
    const uint64_t max = (uint64_t(1) << prefix_bits) - 1;
    *value = uint8_t((*in)[0]) & max;
    in->remove_prefix(1);
    if (*value < max) return true;
    for (int shift = 0; shift < 56; shift += 7) {
      if (in->empty()) return false;
      const uint8_t byte = uint8_t((*in)[0]);
      in->remove_prefix(1);
      *value += uint64_t(byte & 0x7f) << shift;
      if ((byte & 0x80) == 0) return true;
    }
    return false;
  }

  static bool ReadString(std::string_view* in, std::string* out) {
    if (in->empty() || (uint8_t((*in)[0]) & 0x80) != 0) return false;  // empty, or Huffman
    uint64_t length = 0;
    if (!ReadInteger(in, 7, &length) || length > in->size()) return false;
    out->assign(in->substr(0, size_t(length)));
    in->remove_prefix(size_t(length));
    return true;
  }

  bool Lookup(uint64_t index, Header* header) const {
    if (index == 0) return false;
    if (index <= kStaticTableSize) {
      *header = Header(kStaticTable[index - 1].first, kStaticTable[index - 1].second);
      return true;
    }
    if (index - kStaticTableSize > table_.size()) return false;
    *header = table_[size_t(index - kStaticTableSize - 1)];
    return true;
  }

  // Section 4.4: an entry larger than the table empties it.
  void Insert(const Header& header) {
    table_.push_front(header);
    size_ += header.first.size() + header.second.size() + kEntryOverhead;
    Evict();
  }

  void Evict() {
    while (size_ > max_size_) {
      size_ -= table_.back().first.size() + table_.back().second.size() + kEntryOverhead;
      table_.pop_back();
    }
  }

  std::deque<Header> table_;  // the newest entry first (index kStaticTableSize + 1)
  size_t size_ = 0, max_size_ = kMaxTableSize;
};

}  // namespace http2

class RawHttp2Client {
 public:
  // What the server said of a stream.
  struct StreamEnd {
    bool ended = false;              // END_STREAM or RST_STREAM received
    std::string http_status;         // ":status" of its first header block
    std::optional<int> grpc_status;  // "grpc-status" of any of its header blocks
    std::optional<uint32_t> reset;   // the error code of the server's RST_STREAM
  };

  // Connects to 127.0.0.1:`port` and sends the preface, SETTINGS (no push; 2^31-1 bytes of window
  // per stream) and a WINDOW_UPDATE opening the connection's window as wide.
  explicit RawHttp2Client(int port) {
    fd_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(uint16_t(port));
    inet_pton(AF_INET, "127.0.0.1", &address.sin_addr);
    if (fd_ < 0 || connect(fd_, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0) {
      closed_ = true;
      return;
    }
    const int one = 1;
    setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
    fcntl(fd_, F_SETFL, fcntl(fd_, F_GETFL) | O_NONBLOCK);
    Send(
        std::string(http2::kPreface) +
        http2::Settings({{http2::kEnablePush, 0}, {http2::kInitialWindowSize, http2::kMaxWindow}}) +
        http2::WindowUpdate(0, http2::kMaxWindow - http2::kDefaultWindow));
  }
  ~RawHttp2Client() { Close(/*abortive=*/false); }
  RawHttp2Client(const RawHttp2Client&) = delete;
  RawHttp2Client& operator=(const RawHttp2Client&) = delete;

  // Whether bytes can still be sent and answers read.
  bool open() const { return !closed_ && !decode_failed_; }
  // The server closed the connection (or it broke).
  bool closed() const { return closed_; }
  // A header block of the server that this client could not decode (see the header comment).
  bool decode_failed() const { return decode_failed_; }
  // The error code of the server's GOAWAY, if it sent one.
  const std::optional<uint32_t>& goaway_error() const { return goaway_error_; }

  // Stream `id` as the server reads it (without the reserved bit).
  const StreamEnd& stream(uint32_t id) { return streams_[id & http2::kStreamIdMask]; }
  // Drops what is kept of stream `id` (its answer was read).
  void Forget(uint32_t id) { streams_.erase(id & http2::kStreamIdMask); }

  // Sends `bytes` as they are, reading what arrives meanwhile; false when the connection is gone
  // or the server took nothing for `timeout`.
  bool Send(std::string_view bytes,
            std::chrono::milliseconds timeout = std::chrono::milliseconds(5000)) {
    out_ += bytes;
    return Flush(timeout);
  }

  // Sends a whole frame; a DATA frame first waits (up to `timeout`) for the server's connection
  // window to take its payload.
  bool SendFrame(std::string_view frame,
                 std::chrono::milliseconds timeout = std::chrono::milliseconds(5000)) {
    if (frame.size() >= 9 && uint8_t(frame[3]) == http2::kData) {
      const int64_t length = int64_t(frame.size() - 9);
      const auto until = std::chrono::steady_clock::now() + timeout;
      while (open() && send_window_ < length && std::chrono::steady_clock::now() < until) {
        Poll(std::chrono::milliseconds(10));
      }
      send_window_ -= length;
    }
    return Send(frame, timeout);
  }

  // Waits up to `timeout` for bytes from the server and takes in all that arrived.
  void Poll(std::chrono::milliseconds timeout) {
    if (!open()) return;
    pollfd entry{fd_, short(POLLIN | (out_.empty() ? 0 : POLLOUT)), 0};
    if (poll(&entry, 1, int(timeout.count())) <= 0) return;
    if (entry.revents & (POLLIN | POLLHUP | POLLERR)) Read();
    if (!out_.empty()) Flush(std::chrono::milliseconds(0));
  }

  // Closes the connection: with a TCP reset when `abortive`, else with a FIN.
  void Close(bool abortive) {
    if (fd_ < 0) return;
    if (abortive) {
      const linger reset{1, 0};
      setsockopt(fd_, SOL_SOCKET, SO_LINGER, &reset, sizeof(reset));
    }
    close(fd_);
    fd_ = -1;
    closed_ = true;
  }

 private:
  bool Flush(std::chrono::milliseconds timeout) {
    const auto until = std::chrono::steady_clock::now() + timeout;
    while (!out_.empty() && !closed_) {
      const ssize_t sent = send(fd_, out_.data(), out_.size(), MSG_NOSIGNAL);
      if (sent > 0) {
        out_.erase(0, size_t(sent));
        continue;
      }
      if (sent < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
        closed_ = true;
        break;
      }
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          until - std::chrono::steady_clock::now());
      if (left.count() <= 0) return false;
      // While the server does not take bytes, read what it sends (it may wait for that).
      pollfd entry{fd_, POLLIN | POLLOUT, 0};
      if (poll(&entry, 1, int(left.count())) > 0 &&
          (entry.revents & (POLLIN | POLLHUP | POLLERR))) {
        Read();
      }
    }
    return !closed_;
  }

  void Read() {
    char buffer[16384];
    for (;;) {
      const ssize_t n = recv(fd_, buffer, sizeof(buffer), 0);
      if (n > 0) {
        in_.append(buffer, size_t(n));
        continue;
      }
      if (n == 0 || (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) closed_ = true;
      break;
    }
    size_t at = 0;
    while (!decode_failed_ && in_.size() - at >= 9) {
      const size_t length = http2::ReadBigEndian(std::string_view(in_).substr(at, 3));
      if (in_.size() - at - 9 < length) break;
      const std::string_view header = std::string_view(in_).substr(at, 9);
      Handle(uint8_t(header[3]), uint8_t(header[4]),
             http2::ReadBigEndian(header.substr(5)) & http2::kStreamIdMask,
             std::string_view(in_).substr(at + 9, length));
      at += 9 + length;
    }
    in_.erase(0, at);
  }

  void Handle(uint8_t type, uint8_t flags, uint32_t stream, std::string_view payload) {
    switch (type) {
      case http2::kSettings:
        if ((flags & http2::kAck) == 0) out_ += http2::Frame(http2::kSettings, http2::kAck, 0, {});
        break;
      case http2::kPing:
        if ((flags & http2::kAck) == 0 && payload.size() == 8) {
          out_ += http2::Frame(http2::kPing, http2::kAck, 0, payload);
        }
        break;
      case http2::kWindowUpdate:
        if (stream == 0 && payload.size() == 4) send_window_ += http2::ReadBigEndian(payload);
        break;
      case http2::kHeaders: {
        size_t skip = 0, padding = 0;
        if ((flags & http2::kPadded) && !payload.empty()) {
          padding = uint8_t(payload[0]);
          skip = 1;
        }
        if (flags & http2::kPriorityFlag) skip += 5;
        if (skip + padding > payload.size()) {
          decode_failed_ = true;
          break;
        }
        block_.assign(payload.substr(skip, payload.size() - skip - padding));
        block_end_stream_ = flags & http2::kEndStream;
        if (flags & http2::kEndHeaders) EndBlock(stream);
        break;
      }
      case http2::kContinuation:
        block_ += payload;
        if (flags & http2::kEndHeaders) EndBlock(stream);
        break;
      case http2::kData:
        if (flags & http2::kEndStream) streams_[stream].ended = true;
        break;
      case http2::kRstStream:
        if (payload.size() == 4) {
          StreamEnd& end = streams_[stream];
          if (!end.ended) end.reset = http2::ReadBigEndian(payload);
          end.ended = true;
        }
        break;
      case http2::kGoaway:
        if (payload.size() >= 8) goaway_error_ = http2::ReadBigEndian(payload.substr(4, 4));
        break;
      default:  // PRIORITY, unknown types: nothing to keep
        break;
    }
  }

  void EndBlock(uint32_t stream) {
    std::vector<http2::Header> headers;
    if (!decoder_.Decode(block_, &headers)) {
      decode_failed_ = true;
      return;
    }
    StreamEnd& end = streams_[stream];
    for (const auto& [name, value] : headers) {
      if (name == ":status" && end.http_status.empty()) end.http_status = value;
      if (name == "grpc-status") end.grpc_status = std::atoi(value.c_str());
    }
    if (block_end_stream_) end.ended = true;
  }

  int fd_ = -1;
  bool closed_ = false, decode_failed_ = false;
  std::string in_, out_;                         // bytes read and not yet handled; bytes to send
  int64_t send_window_ = http2::kDefaultWindow;  // the server's connection-level window
  http2::HpackDecoder decoder_;
  std::string block_;  // the header block being received (HEADERS, then CONTINUATIONs)
  bool block_end_stream_ = false;
  std::map<uint32_t, StreamEnd> streams_;
  std::optional<uint32_t> goaway_error_;
};

}  // namespace recog::testing

// Text that comes from outside (clients, uploaded files, HTTP requests) on its way to places that
// need it well formed: protobuf string fields and JSON, which must be UTF-8, and log lines, which
// must stay one line each whatever a client put into a name.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace recog {

// True when `text` is well-formed UTF-8 (no overlong forms, surrogates or code points beyond
// U+10FFFF).
bool IsValidUtf8(std::string_view text);

// True when every byte of `text` is printable ASCII (0x20 space to 0x7E '~'): what may go into
// an HTTP header or gRPC metadata as it is.
bool IsPrintableAscii(std::string_view text);

// `text` with each byte that does not start or continue a well-formed UTF-8 sequence replaced by
// U+FFFD; unchanged when it is valid.
std::string ToValidUtf8(std::string_view text);

// `text` for one log line: printable ASCII is kept, a backslash is doubled and every other byte
// (newline, escape, a byte of a UTF-8 sequence) is written as \xNN, so that what a client sent can
// neither start a forged line nor garble the terminal; cut to its first `max_bytes` bytes with
// "..." after it.
std::string EscapeForLog(std::string_view text, size_t max_bytes = 256);

}  // namespace recog

// HostAllowList: which Host headers one of recogd's HTTP ports (the console, the metrics) answers
// to, parsed strictly. A browser page can reach a port on this machine through a name it makes
// resolve here (DNS rebinding) and then reads the answers as its own; it cannot do so through an
// IP address, nor through a name the operator did not list. So a port answers a request only
// when its Host is an IP literal ("127.0.0.1", "[::1]"), "localhost" or one of the configured
// names, each with an optional ":port". The header is parsed as RFC 3986's host[:port] and
// nothing more: userinfo ("127.0.0.1:1@evil.example"), a path, a percent sign, a space or an
// empty or over-long port make it malformed, hence refused. Thread-safe (const).
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace recog::server {

// The host part of a Host header value ("name", "name:port", "1.2.3.4:80", "[v6]:port"), lower
// case and with the IPv6 brackets kept; nullopt when the value is not exactly host[:port] (the
// port 1 to 5 digits, at most 65535; the host a name of letters, digits, '-', '.' and '_', an
// IPv4 address or a bracketed IPv6 address).
std::optional<std::string> HostOfHeader(std::string_view value);

// Whether `host` (as HostOfHeader returns it) is an IPv4 or bracketed IPv6 literal.
bool IsIpLiteral(const std::string& host);

class HostAllowList {
 public:
  // `names`: the host names accepted besides IP literals and "localhost" (any case).
  explicit HostAllowList(const std::vector<std::string>& names);

  // Whether a request whose Host header is `value` may be answered.
  bool AcceptsHeader(std::string_view value) const;
  // Whether `host` (as HostOfHeader returns it) may be answered.
  bool AcceptsHost(const std::string& host) const;

 private:
  std::vector<std::string> names_;  // lower case
};

}  // namespace recog::server

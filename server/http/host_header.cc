#include "server/http/host_header.h"

#include <arpa/inet.h>

#include <algorithm>
#include <cctype>

namespace recog::server {
namespace {

std::string Lower(std::string_view text) {
  std::string lower(text);
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return lower;
}

bool IsNameCharacter(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '.' || c == '_';
}

// ":1" to ":65535" (or nothing); false for anything else.
bool IsPortSuffix(std::string_view rest) {
  if (rest.empty()) return true;
  if (rest.front() != ':' || rest.size() < 2 || rest.size() > 6) return false;
  unsigned port = 0;
  for (const char c : rest.substr(1)) {
    if (c < '0' || c > '9') return false;
    port = port * 10 + unsigned(c - '0');
  }
  return port <= 65535;
}

}  // namespace

std::optional<std::string> HostOfHeader(std::string_view value) {
  std::string_view host;
  std::string_view rest;
  if (value.starts_with('[')) {
    const size_t close = value.find(']');
    if (close == std::string_view::npos) return std::nullopt;
    host = value.substr(0, close + 1);
    rest = value.substr(close + 1);
    if (!IsIpLiteral(std::string(host))) return std::nullopt;
  } else {
    const size_t colon = value.find(':');
    host = value.substr(0, colon);
    rest = colon == std::string_view::npos ? std::string_view() : value.substr(colon);
    if (host.empty() || host.size() > 253 ||
        !std::all_of(host.begin(), host.end(), IsNameCharacter)) {
      return std::nullopt;
    }
  }
  if (!IsPortSuffix(rest)) return std::nullopt;
  return Lower(host);
}

bool IsIpLiteral(const std::string& host) {
  unsigned char address[16];
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') {
    return inet_pton(AF_INET6, host.substr(1, host.size() - 2).c_str(), address) == 1;
  }
  return inet_pton(AF_INET, host.c_str(), address) == 1;
}

HostAllowList::HostAllowList(const std::vector<std::string>& names) {
  for (const std::string& name : names) names_.push_back(Lower(name));
}

bool HostAllowList::AcceptsHeader(std::string_view value) const {
  const std::optional<std::string> host = HostOfHeader(value);
  return host.has_value() && AcceptsHost(*host);
}

bool HostAllowList::AcceptsHost(const std::string& host) const {
  // A rebinding page reaches the port through a name of its own; an address cannot be rebound.
  return IsIpLiteral(host) || host == "localhost" ||
         std::find(names_.begin(), names_.end(), host) != names_.end();
}

}  // namespace recog::server

#include "client/cpp/request_id.h"

#include <cstdint>
#include <cstdio>
#include <random>

namespace recog::client::internal {

std::string NewRequestId() {
  thread_local std::mt19937_64 generator{[] {
    std::random_device device;
    std::seed_seq seed{device(), device(), device(), device()};
    return std::mt19937_64(seed);
  }()};
  uint64_t high = generator(), low = generator();
  high = (high & ~uint64_t{0xf000}) | 0x4000;                  // version 4
  low = (low & ~(uint64_t{0xc} << 60)) | (uint64_t{8} << 60);  // variant 10xx
  char text[37];
  std::snprintf(text, sizeof(text), "%08llx-%04llx-%04llx-%04llx-%012llx",
                static_cast<unsigned long long>(high >> 32),
                static_cast<unsigned long long>((high >> 16) & 0xffff),
                static_cast<unsigned long long>(high & 0xffff),
                static_cast<unsigned long long>(low >> 48),
                static_cast<unsigned long long>(low & 0xffffffffffffULL));
  return text;
}

std::string RequestIdOr(const std::string& given) { return given.empty() ? NewRequestId() : given; }

}  // namespace recog::client::internal

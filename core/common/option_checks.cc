#include "core/common/option_checks.h"

#include <charconv>
#include <cmath>

namespace recog {

bool RealRange::Contains(double value) const {
  if (!std::isfinite(value)) return false;
  const bool above_min = min_included ? value >= min : value > min;
  const bool below_max = max_included ? value <= max : value < max;
  return above_min && below_max;
}

std::string RealRange::Describe() const {
  if (std::isinf(max)) {
    return std::string("finite and ") + (min_included ? ">= " : "> ") + RealText(min);
  }
  return std::string("in ") + (min_included ? "[" : "(") + RealText(min) + ", " + RealText(max) +
         (max_included ? "]" : ")");
}

std::string RealText(double value) {
  char text[32];
  const std::to_chars_result written = std::to_chars(text, text + sizeof(text), value);
  return std::string(text, written.ptr);
}

void OptionChecks::InRange(std::string_view field, double value, const RealRange& range) {
  if (!range.Contains(value)) Fail(field, RealText(value), range.Describe());
}

std::string OptionChecks::Path(std::string_view field) const {
  std::string path = owner_;
  path += '.';
  path += field;
  return path;
}

void OptionChecks::Fail(std::string_view field, std::string_view value, std::string_view rule) {
  if (!status_.ok()) return;
  std::string message = Path(field);
  message += " = ";
  message += value;
  message += ": must be ";
  message += rule;
  status_ = Status::InvalidArgument(std::move(message));
}

}  // namespace recog

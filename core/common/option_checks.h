// OptionChecks: what the Validate() of core's options structs is written with, in the manner of
// COLMAP's option checks. A Validate states the range of each field in turn; the first field out
// of its range gives an INVALID_ARGUMENT that names the struct, the field, the value and the
// range, e.g.
//   "RecognitionOptions.match.ratio = nan: must be in (0, 1]"
// and the checks after it are skipped. A struct held by another is named by its path in the
// outer one (its Validate takes that name), so the outer struct validates its members with
// messages that say where the value sits. A real number must be finite in every range: NaN and
// infinity are refused even where the range has no upper end.
#pragma once

#include <concepts>
#include <limits>
#include <string>
#include <string_view>
#include <type_traits>

#include "core/common/status.h"

namespace recog {

// A range of finite real numbers, each end included or not; `max` infinite: no upper end.
struct RealRange {
  double min = 0;
  double max = std::numeric_limits<double>::infinity();
  bool min_included = true;
  bool max_included = true;

  static RealRange Closed(double min, double max) { return {min, max, true, true}; }
  static RealRange OpenClosed(double min, double max) { return {min, max, false, true}; }
  static RealRange Open(double min, double max) { return {min, max, false, false}; }
  static RealRange AtLeast(double min) {
    return {min, std::numeric_limits<double>::infinity(), true, false};
  }
  static RealRange Above(double min) {
    return {min, std::numeric_limits<double>::infinity(), false, false};
  }

  bool Contains(double value) const;  // false for NaN and infinity
  // What a value must be: "in (0, 1]", or "finite and >= 0" without an upper end.
  std::string Describe() const;
};

// A real number as the messages show it: the shortest text that reads back to it ("0.3", "nan",
// "inf").
std::string RealText(double value);

class OptionChecks {
 public:
  // `owner` names the struct in the messages: its type ("RoiOptions") or its path in the struct
  // that holds it ("RecognitionOptions.roi").
  explicit OptionChecks(std::string_view owner) : owner_(owner) {}

  void InRange(std::string_view field, double value, const RealRange& range);
  template <std::integral T>
  void InRange(std::string_view field, T value, std::type_identity_t<T> min,
               std::type_identity_t<T> max) {
    if (value < min || value > max) {
      Fail(field, std::to_string(value),
           "in [" + std::to_string(min) + ", " + std::to_string(max) + "]");
    }
  }
  template <std::integral T>
  void AtLeast(std::string_view field, T value, std::type_identity_t<T> min) {
    if (value < min) Fail(field, std::to_string(value), ">= " + std::to_string(min));
  }
  // A rule that a range cannot say, often one between two fields: `field` breaks it unless
  // `holds`; `rule` completes "must be", e.g. "<= temporal_matches (3)".
  template <std::integral T>
  void Require(bool holds, std::string_view field, T value, std::string_view rule) {
    if (!holds) Fail(field, std::to_string(value), rule);
  }
  // A member struct, by its own Validate under its path in this one.
  template <typename Options>
  void Member(std::string_view field, const Options& member) {
    if (status_.ok()) status_ = member.Validate(Path(field));
  }

  // OK, or the first check that failed.
  const Status& status() const { return status_; }

 private:
  std::string Path(std::string_view field) const;  // "<owner>.<field>"
  // Records "<owner>.<field> = <value>: must be <rule>", unless a check failed before.
  void Fail(std::string_view field, std::string_view value, std::string_view rule);

  std::string owner_;
  Status status_;
};

}  // namespace recog

// Tests of an options struct's Validate(), one bad field at a time: each BadOption breaks one field
// of default options, and Validate() must refuse the result with INVALID_ARGUMENT and a message
// that names the field. ExpectEachRefused checks the usual message of the option checks,
// "<owner>.<field> = <value>: must be ...", up to the rule; ExpectEachRefusedStartingWith checks
// any other start the case gives in full.
#pragma once

#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/status.h"

namespace recog::testing {

template <typename Options>
struct BadOption {
  std::string expected;  // how the refusal's message starts (see the functions below)
  std::function<void(Options&)> break_it;
};

// `expected` is the message's whole start.
template <typename Options>
void ExpectEachRefusedStartingWith(const std::vector<BadOption<Options>>& cases) {
  for (const BadOption<Options>& c : cases) {
    Options options;
    c.break_it(options);
    const Status s = options.Validate();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << c.expected;
    EXPECT_EQ(s.message().rfind(c.expected, 0), 0u) << s.message();
  }
}

// `expected` is the message after "<owner>." up to the rule ("alpha = nan"): the message must
// start "<owner>.<expected>: must be ".
template <typename Options>
void ExpectEachRefused(std::string_view owner, std::vector<BadOption<Options>> cases) {
  for (BadOption<Options>& c : cases) {
    c.expected = std::string(owner) + "." + c.expected + ": must be ";
  }
  ExpectEachRefusedStartingWith(cases);
}

}  // namespace recog::testing

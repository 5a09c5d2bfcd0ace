#include "core/common/text.h"

#include <gtest/gtest.h>

namespace recog {
namespace {

TEST(TextTest, WellFormedUtf8IsValid) {
  EXPECT_TRUE(IsValidUtf8(""));
  EXPECT_TRUE(IsValidUtf8("lion"));
  EXPECT_TRUE(IsValidUtf8("caf\xC3\xA9 \xE2\x82\xAC \xF0\x9F\x93\xB7"));  // é € camera
  EXPECT_TRUE(IsValidUtf8(std::string_view("a\0b", 3)));
}

TEST(TextTest, MalformedUtf8IsNot) {
  EXPECT_FALSE(IsValidUtf8("\xFF\xFE"));          // the bytes of the RoboEarth meta.xml finding
  EXPECT_FALSE(IsValidUtf8("\x80"));              // a continuation byte alone
  EXPECT_FALSE(IsValidUtf8("caf\xC3"));           // a sequence cut short
  EXPECT_FALSE(IsValidUtf8("\xC0\xAF"));          // an overlong '/'
  EXPECT_FALSE(IsValidUtf8("\xED\xA0\x80"));      // a surrogate
  EXPECT_FALSE(IsValidUtf8("\xF4\x90\x80\x80"));  // beyond U+10FFFF
}

TEST(TextTest, ToValidUtf8ReplacesEachBadByteAndKeepsTheRest) {
  EXPECT_EQ(ToValidUtf8("caf\xC3\xA9"), "caf\xC3\xA9");
  EXPECT_EQ(ToValidUtf8("a\xFF\xFE"
                        "b"),
            "a\xEF\xBF\xBD\xEF\xBF\xBD"
            "b");
  EXPECT_EQ(ToValidUtf8("\xC3"), "\xEF\xBF\xBD");
  EXPECT_TRUE(IsValidUtf8(ToValidUtf8("\xED\xA0\x80\xF4\x90\x80\x80 ok")));
}

TEST(TextTest, PrintableAsciiHasNoControlOrHighBytes) {
  EXPECT_TRUE(IsPrintableAscii("Bearer abc-123 ~"));
  EXPECT_TRUE(IsPrintableAscii(""));
  EXPECT_FALSE(IsPrintableAscii("Bearer\tabc"));
  EXPECT_FALSE(IsPrintableAscii("Bearer \xC3\xA9"));
  EXPECT_FALSE(IsPrintableAscii("a\x7F"));
}

TEST(TextTest, EscapeForLogKeepsOneLineAndCuts) {
  EXPECT_EQ(EscapeForLog("robot-7"), "robot-7");
  EXPECT_EQ(EscapeForLog("a\nrequest=1 code=OK"), "a\\x0Arequest=1 code=OK");
  EXPECT_EQ(EscapeForLog("back\\slash\x1B[31m"), "back\\\\slash\\x1B[31m");
  EXPECT_EQ(EscapeForLog("\xC3\xA9"), "\\xC3\\xA9");
  EXPECT_EQ(EscapeForLog("abcdef", 3), "abc...");
}

}  // namespace
}  // namespace recog

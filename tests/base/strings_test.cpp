// The bottom layer's helpers: ASCII case folding, trim and split (base/strings.h) exactly as the
// copies they replaced behaved, and the clock's units (base/clock.h) agreeing with one another.
#include "base/strings.h"

#include <gtest/gtest.h>

#include <string>
#include <string_view>
#include <vector>

#include "base/clock.h"

namespace rcan {
namespace {

using Views = std::vector<std::string_view>;

TEST(AsciiCase, FoldsOnlyAsciiLetters) {
  EXPECT_EQ(ascii_lower("Transfer-Encoding: CHUNKED 42"), "transfer-encoding: chunked 42");
  EXPECT_EQ(ascii_upper("rrn-bd-000000000042"), "RRN-BD-000000000042");
  // UTF-8 bytes and the characters around the letters' ranges ('@', '[', '`', '{') are kept.
  EXPECT_EQ(ascii_lower("\xc3\x84@[`{Z"), "\xc3\x84@[`{z");
  EXPECT_EQ(ascii_upper("\xc3\xa4@[`{a"), "\xc3\xa4@[`{A");
  EXPECT_EQ(ascii_lower(""), "");
}

TEST(Trim, DropsTheGivenCharactersAtBothEndsOnly) {
  EXPECT_EQ(trim(" \t\r\n token \n"), "token");
  EXPECT_EQ(trim("  a b  "), "a b");
  EXPECT_EQ(trim(" \t a\t", " "), "\t a\t");
  EXPECT_EQ(trim("   "), "");
  EXPECT_EQ(trim(""), "");
}

TEST(Split, KeepsOrDropsEmptyFields) {
  EXPECT_EQ(split("a/b//c", '/'), (Views{"a", "b", "", "c"}));
  EXPECT_EQ(split("/a/", '/'), (Views{"", "a", ""}));
  EXPECT_EQ(split("", ','), (Views{""}));
  EXPECT_EQ(split("a,,b,", ',', /*keep_empty=*/false), (Views{"a", "b"}));
  EXPECT_EQ(split(",", ',', /*keep_empty=*/false), Views{});
  EXPECT_EQ(split("", ',', /*keep_empty=*/false), Views{});
}

TEST(Clock, UnitsAgree) {
  const int64_t s = unix_seconds(), ms = unix_ms(), us = unix_us();
  EXPECT_LE(s * 1000, ms);
  EXPECT_LE(ms * 1000, us);
  EXPECT_LT(us - ms * 1000, 1'000'000);  // read within a second of one another
  const int64_t a = steady_ms(), b = steady_us() / 1000, c = steady_ns() / 1'000'000;
  EXPECT_LE(a, b);
  EXPECT_LE(b, c);
  EXPECT_GE(Clock::system().wall_ms(), ms);
}

}  // namespace
}  // namespace rcan

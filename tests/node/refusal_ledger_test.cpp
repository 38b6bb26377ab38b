// The refusal ledger: one record per source and kind per window, the rest counted into a
// summary; bounded keys with overflow counting; nothing lost (refusal_ledger.h).
#include "node/vocabulary/refusal_ledger.h"

#include <gtest/gtest.h>

#include <string>

namespace rcan::node {
namespace {

RefusalKey key(const std::string& source, const std::string& code = "AUTH_REQUIRED") {
  return RefusalKey{source, "AUTH_FAILED", code, "/rcan/v1/command"};
}

TEST(RefusalLedger, TheFirstOfAKindIsRecordedTheRestAreSummarisedWhenTheWindowCloses) {
  RefusalLedger l({.window_ms = 1000, .max_keys = 16});
  EXPECT_TRUE(l.admit(key("192.0.2.1"), 0));
  for (int i = 1; i <= 500; ++i) EXPECT_FALSE(l.admit(key("192.0.2.1"), i));
  EXPECT_TRUE(l.admit(key("192.0.2.1", "AUTH_INVALID"), 10));  // another kind
  EXPECT_TRUE(l.admit(key("192.0.2.2"), 10));                  // another source
  EXPECT_TRUE(l.due(999).empty());                             // the window is still open
  auto s = l.due(1000);
  ASSERT_EQ(s.size(), 1u);  // only the key that counted something
  EXPECT_EQ(s[0].key.source, "192.0.2.1");
  EXPECT_EQ(s[0].suppressed, 500u);
  EXPECT_EQ(s[0].first_ms, 1);
  EXPECT_EQ(s[0].last_ms, 500);
  EXPECT_TRUE(l.admit(key("192.0.2.1"), 1001));  // a new window records its first again
  EXPECT_EQ(l.suppressed_total(), 500u);
}

TEST(RefusalLedger, AFullTableCountsUnderOverflowKeysAndLosesNothing) {
  RefusalLedger l({.window_ms = 1000, .max_keys = 4});
  int recorded = 0;
  for (int i = 0; i < 1000; ++i)
    recorded += l.admit(key("198.51.100." + std::to_string(i % 250), std::to_string(i)), i % 900);
  uint64_t summarised = 0;
  for (const auto& s : l.due(0, true)) summarised += s.suppressed;
  EXPECT_EQ(static_cast<uint64_t>(recorded) + summarised, 1000u);
  EXPECT_LE(recorded, 4);
}

TEST(RefusalLedger, SourcesAreAddressesWithoutPorts) {
  EXPECT_EQ(RefusalLedger::source_of("192.0.2.7:4711"), "192.0.2.7");
  EXPECT_EQ(RefusalLedger::source_of("[::1]:80"), "::1");
  EXPECT_EQ(RefusalLedger::source_of("::1"), "::1");
  EXPECT_EQ(RefusalLedger::source_of(""), "");
}

}  // namespace
}  // namespace rcan::node

// The log's in-memory ring (runtime/log.h): the newest lines, bounded, URLs cut to their host,
// whole under concurrent writers.
#include <gtest/gtest.h>

#include <string>
#include <thread>
#include <vector>

#include "rcan/json.h"
#include "runtime/log.h"

namespace rcan {
namespace {

class LogRingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    set_log_sink([](std::string_view) {});  // keep stderr quiet
  }
  void TearDown() override { set_log_sink({}); }
};

TEST(RedactUrls, KeepsSchemeHostAndPortDropsUserPathAndQuery) {
  EXPECT_EQ(redact_urls("mqtt://alice:s3cret@broker.lan:1883"), "mqtt://broker.lan:1883");
  EXPECT_EQ(redact_urls("https://hooks.example/services/T0/B0/XyZsecret?token=abc"),
            "https://hooks.example/\xe2\x80\xa6");
  EXPECT_EQ(redact_urls("http://127.0.0.1:8080"), "http://127.0.0.1:8080");
  EXPECT_EQ(redact_urls("no url here"), "no url here");
  EXPECT_EQ(redact_urls("rcan://local.rcan/acme/rover/0a1b2c3d"),
            "rcan://local.rcan/acme/rover/0a1b2c3d")
      << "a RURI is the robot's public name";
  EXPECT_EQ(redact_urls("://x"), "://x") << "no scheme: left alone";
  EXPECT_EQ(redact_urls("a http://h/p b wss://u@g/q"),
            "a http://h/\xe2\x80\xa6 b wss://g/\xe2\x80\xa6");
  // In JSON text a URL ends at the closing quote or an escape, so the line stays JSON.
  std::string line = json::dump(
      json::Value(json::Object{{"url", "https://u:p@h.example/x\"y?k=1"}, {"next", "ok"}}));
  std::string red = redact_urls(line);
  auto v = json::parse(red);
  ASSERT_TRUE(v.ok()) << red;
  EXPECT_EQ(json::string_field(*v, "next"), "ok");
  EXPECT_EQ(red.find("u:p@"), std::string::npos) << red;
  EXPECT_EQ(red.find("/x"), std::string::npos) << red;
}

TEST_F(LogRingTest, KeepsTheNewestLinesRedacted) {
  const uint64_t before = recent_log_lines(0).written;
  for (int i = 0; i < 250; ++i)
    log(LogLevel::kInfo, "ring.test",
        json::Object{{"i", i}, {"broker", "mqtt://user:pw@b.example:1883/t"}});
  RecentLog all = recent_log_lines(1000);
  EXPECT_EQ(all.lines.size(), kLogRingCapacity);
  EXPECT_EQ(all.written, before + 250);
  auto last = json::parse(all.lines.back());
  ASSERT_TRUE(last.ok()) << all.lines.back();
  EXPECT_EQ(json::string_field(*last, "event"), "ring.test");
  EXPECT_EQ(json::int_field(*last, "i"), 249);
  EXPECT_EQ(json::string_field(*last, "broker"), "mqtt://b.example:1883/\xe2\x80\xa6");
  for (const auto& l : all.lines) EXPECT_EQ(l.find("user:pw"), std::string::npos) << l;
  RecentLog three = recent_log_lines(3);
  ASSERT_EQ(three.lines.size(), 3u);
  EXPECT_EQ(three.lines.back(), all.lines.back());
}

TEST_F(LogRingTest, BelowTheLevelNothingIsKeptAndALongLineIsShortened) {
  const uint64_t before = recent_log_lines(0).written;
  log(LogLevel::kDebug, "ring.debug");
  EXPECT_EQ(recent_log_lines(0).written, before);
  log(LogLevel::kWarn, "ring.long", json::Object{{"text", std::string(10000, 'x')}});
  RecentLog r = recent_log_lines(1);
  ASSERT_EQ(r.lines.size(), 1u);
  auto v = json::parse(r.lines[0]);
  ASSERT_TRUE(v.ok()) << r.lines[0];
  EXPECT_EQ(json::string_field(*v, "event"), "ring.long");
  EXPECT_EQ(json::string_field(*v, "level"), "warn");
  EXPECT_GT(json::int_field(*v, "truncated"), 10000);
  EXPECT_LE(r.lines[0].size(), kLogRingMaxLine);
}

TEST_F(LogRingTest, ConcurrentWritersAndReadersSeeWholeLines) {
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([t] {
      for (int i = 0; i < 300; ++i)
        log(LogLevel::kInfo, "ring.mt", json::Object{{"t", t}, {"i", i}});
    });
  threads.emplace_back([] {
    for (int i = 0; i < 300; ++i)
      for (const auto& l : recent_log_lines(50).lines) ASSERT_TRUE(json::parse(l).ok()) << l;
  });
  for (auto& th : threads) th.join();
  EXPECT_EQ(recent_log_lines(1000).lines.size(), kLogRingCapacity);
}

}  // namespace
}  // namespace rcan

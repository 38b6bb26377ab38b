// The §16.5 thought log on disk: every thought is appended and synced, read back at start (the
// newest `capacity`), compacted when the file holds twice as many lines, a torn line skipped;
// a thought id holding one sender's thought cannot be taken over by another (thoughts.h).
#include "node/ai/thoughts.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>
#include <string>

#include "rcan/base/env.h"
#include "test_support.h"
#include "testing/fault_env.h"

namespace rcan::node {
namespace {

Thought thought(const std::string& id, const std::string& principal, const std::string& why) {
  Thought t;
  t.id = id;
  t.timestamp_ms = 1'700'000'000'000;
  t.provider = "anthropic";
  t.model = "planner-1";
  t.layer = "planner";
  t.instruction = "go to the dock";
  t.reasoning = why;
  t.confidence = 0.8;
  t.action = json::Object{{"type", "move"}, {"linear", 0.1}};
  t.context_snapshot = json::Object{{"battery", 0.4}};
  t.message_id = "msg-" + id;
  t.principal = principal;
  return t;
}

size_t lines_of(const std::string& path) {
  std::string s = test::read_file(path);
  size_t n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

TEST(ThoughtFile, ThoughtsAreReadBackAfterARestartWithTheirReasoning) {
  test::TempDir dir;
  const std::string f = dir.file("thoughts.jsonl");
  {
    ThoughtLog log(10, f);
    ASSERT_TRUE(log.open().ok());
    for (int i = 0; i < 3; ++i)
      ASSERT_TRUE(
          log.put(thought("th_" + std::to_string(i), "iss|alice", "why " + std::to_string(i))));
  }
  struct stat st {};
  ASSERT_EQ(::stat(f.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  ThoughtLog again(10, f);
  auto skipped = again.open();
  ASSERT_TRUE(skipped.ok());
  EXPECT_EQ(*skipped, 0u);
  ASSERT_EQ(again.size(), 3u);
  auto t = again.get("th_1");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->reasoning, "why 1");
  EXPECT_EQ(json::canonical(t->to_json(true)),
            json::canonical(thought("th_1", "iss|alice", "why 1").to_json(true)));
  EXPECT_EQ(t->principal, "iss|alice");
}

TEST(ThoughtFile, TheFileIsBoundedAndKeepsTheNewest) {
  test::TempDir dir;
  const std::string f = dir.file("thoughts.jsonl");
  {
    ThoughtLog log(5, f);
    ASSERT_TRUE(log.open().ok());
    for (int i = 0; i < 40; ++i) ASSERT_TRUE(log.put(thought("th_" + std::to_string(i), "p", "r")));
    EXPECT_LE(lines_of(f), 10u);  // compacted at twice the capacity
  }
  ThoughtLog again(5, f);
  ASSERT_TRUE(again.open().ok());
  EXPECT_EQ(again.size(), 5u);
  EXPECT_TRUE(again.get("th_39"));
  EXPECT_TRUE(again.get("th_35"));
  EXPECT_FALSE(again.get("th_34"));
}

TEST(ThoughtFile, ATornOrForeignLineIsSkippedAndCountedNeverACrash) {
  test::TempDir dir;
  const std::string f = dir.file("thoughts.jsonl");
  {
    ThoughtLog log(10, f);
    ASSERT_TRUE(log.open().ok());
    ASSERT_TRUE(log.put(thought("th_a", "p", "r")));
  }
  {
    std::ofstream out(f, std::ios::app);
    out << "[1,2,3]\n{\"id\":7}\n{\"id\":\"th_b\",\"timestamp_ms\":\"soon\"}\n{\"id\":\"th_c\","
           "\"tim";
  }
  ThoughtLog again(10, f);
  auto skipped = again.open();
  ASSERT_TRUE(skipped.ok());
  EXPECT_EQ(*skipped, 4u);
  EXPECT_EQ(again.size(), 1u);
  EXPECT_EQ(lines_of(f), 1u);  // rewritten to what was kept: no torn tail to append after
  ASSERT_TRUE(again.put(thought("th_d", "p", "r")));
  ThoughtLog third(10, f);
  ASSERT_TRUE(third.open().ok());
  EXPECT_EQ(third.size(), 2u);
}

TEST(ThoughtFile, AnotherSenderCannotOverwriteAThoughtAndClearEmptiesTheFile) {
  test::TempDir dir;
  const std::string f = dir.file("thoughts.jsonl");
  ThoughtLog log(10, f);
  ASSERT_TRUE(log.open().ok());
  ASSERT_TRUE(log.put(thought("th_x", "iss|alice", "the real reasoning")));
  EXPECT_FALSE(log.put(thought("th_x", "iss|mallory", "a forged reasoning")));
  EXPECT_EQ(log.get("th_x")->reasoning, "the real reasoning");
  EXPECT_TRUE(log.put(thought("th_x", "iss|alice", "revised by its sender")));
  {
    ThoughtLog reread(10, f);
    ASSERT_TRUE(reread.open().ok());
    EXPECT_EQ(reread.get("th_x")->reasoning, "revised by its sender");
  }
  log.clear();  // ownership transfer
  ThoughtLog after(10, f);
  ASSERT_TRUE(after.open().ok());
  EXPECT_EQ(after.size(), 0u);
}

TEST(ThoughtFile, AThoughtTheFileCannotTakeIsKeptInMemoryAndCounted) {
  test::TempDir dir;
  base::FaultInjectionEnv env(base::Env::posix());
  ThoughtLog log(10, dir.file("thoughts.jsonl"), &env);
  ASSERT_TRUE(log.open().ok());
  env.fail_after(1);
  EXPECT_TRUE(log.put(thought("th_1", "p", "r")));
  EXPECT_TRUE(log.get("th_1"));
  EXPECT_EQ(log.unpersisted(), 1u);
}

}  // namespace
}  // namespace rcan::node

// LatchFile: the ESTOP latch's file read and written through base::Env — its round trip, the
// in-place latch over a cleared file, a torn or missing file, and faults injected into the
// Env: a failed read or write is the latch's error (INTERNAL, latch_unreadable /
// latch_unwritable), not the audit log's; SafetyCore::open reads the latch through the Env, so
// an unreadable file brings the node up latched.
#include "node/safety/latch_file.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "base/clock.h"
#include "node/safety/safety.h"
#include "node/safety/sim_robot.h"
#include "rcan/base/env.h"
#include "test_support.h"
#include "testing/fault_env.h"

namespace rcan::node {
namespace {

using base::FaultInjectionEnv;
using test::TempDir;

LatchState latched_by(const std::string& source, int by_level) {
  return LatchState{true, source, "pressed", 1'700'000'000'000, by_level};
}

TEST(LatchFile, WritesAndReadsBackTheLatchInItsFixedForm) {
  TempDir dir;
  LatchFile file(dir.path(), nullptr);
  ASSERT_TRUE(file.write(latched_by("http", 3), 42).ok());
  EXPECT_EQ(test::read_file(file.path()).size(), LatchFile::kBytes);

  LatchFile again(dir.path(), nullptr);
  auto r = again.read();
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_FALSE(r->missing);
  EXPECT_FALSE(r->corrupt) << r->why;
  EXPECT_TRUE(r->state.active);
  EXPECT_EQ(r->state.source, "http");
  EXPECT_EQ(r->state.reason, "pressed");
  EXPECT_EQ(r->state.since_wall_ms, 1'700'000'000'000);
  EXPECT_EQ(r->state.by_level, 3);
  EXPECT_TRUE(again.fixed());
}

TEST(LatchFile, AMissingFileIsMissingAndATornOneFailsItsCheck) {
  TempDir dir;
  LatchFile file(dir.path(), nullptr);
  auto none = file.read();
  ASSERT_TRUE(none.ok()) << none.error().message;
  EXPECT_TRUE(none->missing);

  ASSERT_TRUE(file.write(latched_by("http", 3), 42).ok());
  std::string text = test::read_file(file.path());
  text.replace(text.find("pressed"), 7, "PRESSED");  // as a torn rewrite would leave it
  std::ofstream(file.path(), std::ios::binary | std::ios::trunc) << text;
  auto torn = LatchFile(dir.path(), nullptr).read();
  ASSERT_TRUE(torn.ok()) << torn.error().message;
  EXPECT_TRUE(torn->corrupt);
  EXPECT_EQ(torn->why, "state file fails its check (a write torn by a crash?)");
}

// Cleared → latched rewrites the file where it is: one write and one sync (two mutations), not
// a temporary file, a rename and a directory sync (three).
TEST(LatchFile, ALatchOverAClearedFileIsWrittenInPlace) {
  TempDir dir;
  FaultInjectionEnv env(base::Env::posix());
  LatchFile file(dir.path(), &env);
  ASSERT_TRUE(file.write(LatchState{}, 1).ok());
  const uint64_t before = env.mutations();
  ASSERT_TRUE(file.write(latched_by("mqtt", 0), 2).ok());
  EXPECT_EQ(env.mutations() - before, 2u);
  auto r = LatchFile(dir.path(), nullptr).read();
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r->state.active);
  EXPECT_EQ(r->state.source, "mqtt");
}

TEST(LatchFile, AnInjectedWriteFailureIsTheLatchsError) {
  TempDir dir;
  FaultInjectionEnv env(base::Env::posix());
  LatchFile file(dir.path(), &env);
  env.fail_after(1);
  Status s = file.write(latched_by("http", 3), 42);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::kInternal);
  EXPECT_NE(s.error().code, ErrorCode::kAuditUnavailable);
  EXPECT_EQ(s.error().reason, LatchFile::kUnwritable);
  EXPECT_NE(s.error().message.find("injected fault"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find(file.path()), std::string::npos) << s.error().message;
  EXPECT_FALSE(file.fixed());  // unknown after a failure: the next write is whole
}

TEST(LatchFile, AnInjectedReadFailureIsTheLatchsError) {
  TempDir dir;
  FaultInjectionEnv env(base::Env::posix());
  LatchFile file(dir.path(), &env);
  ASSERT_TRUE(file.write(latched_by("http", 3), 42).ok());
  env.fail_reads(true);
  auto r = file.read();
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kInternal);
  EXPECT_NE(r.error().code, ErrorCode::kAuditUnavailable);
  EXPECT_EQ(r.error().reason, LatchFile::kUnreadable);
  EXPECT_NE(r.error().message.find("injected fault"), std::string::npos) << r.error().message;
}

// SafetyCore::open reads the latch through its Env: a file it cannot read is taken as corrupt,
// the node comes up latched (fail safe) and the file is kept as *.corrupt.
TEST(LatchFile, SafetyCoreComesUpLatchedWhenTheLatchCannotBeRead) {
  TempDir dir;
  ManualClock clock;
  ASSERT_TRUE(LatchFile(dir.path(), nullptr).write(LatchState{}, 1).ok());
  FaultInjectionEnv env(base::Env::posix());
  env.fail_reads(true);
  SafetyCore core(std::make_unique<SimRobot>(), SafetyConfig{}, clock);
  ASSERT_TRUE(core.open(dir.path(), &env).ok());
  EXPECT_TRUE(core.estop_active());
  const SafetyStatus st = core.status();
  EXPECT_EQ(st.estop_source, "startup");
  EXPECT_EQ(st.startup_note, "state file unreadable; came up latched (fail safe)");
  EXPECT_TRUE(std::filesystem::exists(dir.file("safety_state.json.corrupt")));
}

}  // namespace
}  // namespace rcan::node

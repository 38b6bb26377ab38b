// FleetEstopLedger (src/node/fleet/estop_ledger.h): a fleet ESTOP the fleet has resumed since
// never latches the robot again, a standing one must be newer than the last RESUME, and both
// survive a restart; a new ESTOP always latches.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>

#include "node/fleet/estop_ledger.h"
#include "runtime/state_file.h"
#include "test_support.h"

namespace rcan::node {
namespace {

using V = FleetEstopLedger::Verdict;
constexpr int64_t kNow = 1'800'000'000;  // unix seconds
constexpr int64_t kMs = kNow * 1000;

TEST(FleetEstopLedger, AResumedEstopNeverLatchesAgainAndANewOneAlwaysDoes) {
  FleetEstopLedger book("", "alpha", "robot-a", kNow);
  EXPECT_EQ(book.judge("e1", kMs, true), V::kObey);  // nothing known: a standing order
  book.honoured("e1", kMs, kNow + 3600, kNow);
  // Not resumed yet: the standing ESTOP still stands (a member resumed over HTTP latches again).
  EXPECT_EQ(book.judge("e1", kMs, true), V::kObey);
  EXPECT_EQ(book.judge("e1", kMs, false), V::kObey);
  book.resumed(kMs + 5000, kNow + 5);
  EXPECT_EQ(book.last_resume_ms(), kMs + 5000);
  // Its replay, live or retained, and a standing ESTOP older than the RESUME: refused.
  EXPECT_EQ(book.judge("e1", kMs, true), V::kSuperseded);
  EXPECT_EQ(book.judge("e1", kMs, false), V::kSuperseded);
  EXPECT_EQ(book.judge("never-seen", kMs + 5000 - FleetEstopLedger::kClockMarginMs, true),
            V::kOlderThanResume);
  // A standing ESTOP of a coordinator whose clock is behind the RESUME's stops the robot.
  EXPECT_EQ(book.judge("behind", kMs + 1000, true), V::kObey);
  // Even when its own stamp is later than the RESUME's (another coordinator's clock ahead).
  book.honoured("e2", kMs + 9000, kNow + 3600, kNow + 6);
  book.resumed(kMs + 8000, kNow + 7);
  EXPECT_EQ(book.judge("e2", kMs + 9000, true), V::kSuperseded);
  EXPECT_EQ(book.last_resume_ms(), kMs + 8000);
  // A new ESTOP: a live one whatever its stamp (freshness judges it), a standing one stamped
  // after the last RESUME.
  EXPECT_EQ(book.judge("e3", kMs + 1000, false), V::kObey);
  EXPECT_EQ(book.judge("e3", kMs + 8001, true), V::kObey);
  EXPECT_EQ(book.judge("e3", kMs + 8000 - FleetEstopLedger::kClockMarginMs + 1, true), V::kObey);
}

TEST(FleetEstopLedger, KeptAcrossARestartIn0600AndForgottenWhenTheTokenExpires) {
  test::TempDir tmp;
  const std::string path = tmp.file("fleet_estops.json");
  {
    FleetEstopLedger book(path, "alpha", "robot-a", kNow);
    book.honoured("e1", kMs, kNow + 3600, kNow);
    book.honoured("short", kMs, kNow + 10, kNow);
    book.resumed(kMs + 5000, kNow + 5);
  }
  struct stat st {};
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  FleetEstopLedger again(path, "alpha", "robot-a", kNow + 6);
  EXPECT_EQ(again.judge("e1", kMs, true), V::kSuperseded);
  EXPECT_EQ(again.judge("other", kMs - 30'000, true), V::kOlderThanResume);
  EXPECT_EQ(again.size(), 2u);
  // Past its token's expiry an entry is dropped (the token no longer verifies either).
  FleetEstopLedger later(path, "alpha", "robot-a", kNow + 11);
  EXPECT_EQ(later.size(), 1u);
  EXPECT_EQ(later.judge("e1", kMs, false), V::kSuperseded);
}

TEST(FleetEstopLedger, AnotherMembersOrATornFileIsNotTaken) {
  test::TempDir tmp;
  const std::string path = tmp.file("fleet_estops.json");
  {
    FleetEstopLedger book(path, "alpha", "robot-b", kNow);
    book.resumed(kMs + 5000, kNow);
  }
  FleetEstopLedger other(path, "alpha", "robot-a", kNow);
  EXPECT_EQ(other.last_resume_ms(), 0);
  EXPECT_EQ(other.judge("e1", kMs, true), V::kObey);
  std::ofstream(path, std::ios::trunc) << "{\"fleet_id\":\"alpha\",";
  FleetEstopLedger torn(path, "alpha", "robot-a", kNow);
  EXPECT_EQ(torn.last_resume_ms(), 0);
  EXPECT_EQ(torn.judge("e1", kMs, true), V::kObey);
}

TEST(FleetEstopLedger, BoundedTheOldestGoFirst) {
  FleetEstopLedger book("", "alpha", "robot-a", kNow);
  for (size_t i = 0; i < FleetEstopLedger::kMaxEntries + 10; ++i)
    book.honoured("e" + std::to_string(i), kMs + static_cast<int64_t>(i), std::nullopt, kNow);
  EXPECT_EQ(book.size(), FleetEstopLedger::kMaxEntries);
  book.resumed(kMs + 100'000, kNow);
  const std::string newest = "e" + std::to_string(FleetEstopLedger::kMaxEntries + 9);
  EXPECT_EQ(book.judge(newest, kMs, false), V::kSuperseded);
  EXPECT_EQ(book.judge("e0", kMs, false), V::kObey);  // crowded out; live, it is judged fresh
  EXPECT_EQ(book.judge("e0", kMs, true), V::kOlderThanResume);  // standing: still refused
}

}  // namespace
}  // namespace rcan::node

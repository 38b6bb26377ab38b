// The replay memory (src/node/admission/replay.h) alone, its clock a parameter: the spec's
// windows, one memory per principal, its bounds, and that no principal's traffic removes,
// ages out or makes stale another principal's ids. The last test runs principals on threads
// (TSan set).
#include "node/admission/replay.h"

#include <gtest/gtest.h>

#include <atomic>
#include <string>
#include <thread>
#include <vector>

#include "rcan/errors.h"

namespace rcan::node {
namespace {

constexpr int64_t kT = 1'750'000'000'000;  // the node's wall clock at the start of each test
const std::string kOwner = "rcand-local\x1fowner";
const std::string kGuest = "rcand-local\x1fguest";

ErrorCode code_of(const Result<ReplayGuard::Verdict>& r) {
  return r.ok() ? ErrorCode::kInternal : r.error().code;
}

TEST(Replay, TheSpecWindowsAreKept) {
  ReplayGuard g;
  // 30 s into the past, 5 s into the future; 10 s into the past for a stop.
  EXPECT_TRUE(g.check(kOwner, "a", kT - 30'000, false, kT).ok());
  EXPECT_EQ(code_of(g.check(kOwner, "b", kT - 30'001, false, kT)), ErrorCode::kMessageStale);
  EXPECT_TRUE(g.check(kOwner, "c", kT + 5'000, false, kT).ok());
  EXPECT_EQ(code_of(g.check(kOwner, "d", kT + 5'001, false, kT)), ErrorCode::kMessageStale);
  EXPECT_TRUE(g.check(kOwner, "e", kT - 10'000, true, kT).ok());
  EXPECT_EQ(code_of(g.check(kOwner, "f", kT - 10'001, true, kT)), ErrorCode::kMessageStale);
  EXPECT_EQ(code_of(g.check(kOwner, "g", kT + 5'001, true, kT)), ErrorCode::kMessageStale);
  // A used id is refused while its timestamp is in the window, and forgotten after.
  EXPECT_EQ(code_of(g.check(kOwner, "c", kT + 5'000, false, kT + 1)), ErrorCode::kReplayDetected);
  EXPECT_EQ(code_of(g.check(kOwner, "c", kT + 5'000, false, kT + 35'000)),
            ErrorCode::kReplayDetected);
  EXPECT_EQ(code_of(g.check(kOwner, "c", kT + 5'000, false, kT + 35'001)),
            ErrorCode::kMessageStale);
  EXPECT_TRUE(g.check(kOwner, "h", kT + 35'001, false, kT + 35'001).ok());
  EXPECT_EQ(g.size(), 1u);  // everything else has left the window
}

TEST(Replay, IdsBelongToTheirPrincipal) {
  ReplayGuard g;
  ASSERT_TRUE(g.check(kOwner, "x", kT, false, kT).ok());
  // Another principal's "x" is another message: not a replay, and it uses up nothing of the
  // owner's.
  ASSERT_TRUE(g.check(kGuest, "x", kT, false, kT).ok());
  EXPECT_EQ(code_of(g.check(kOwner, "x", kT, false, kT + 1)), ErrorCode::kReplayDetected);
  EXPECT_EQ(code_of(g.check(kGuest, "x", kT, false, kT + 1)), ErrorCode::kReplayDetected);
  EXPECT_EQ(g.size(), 2u);
  EXPECT_EQ(g.principals(), 2u);
  EXPECT_EQ(g.size_of(kOwner), 1u);
  // The subject alone is not the principal: the same subject from another issuer is another.
  EXPECT_TRUE(g.check("other-issuer\x1fowner", "x", kT, false, kT + 2).ok());
}

TEST(Replay, PeekRefusesWhatCheckWouldAndRemembersNothing) {
  ReplayGuard g;
  EXPECT_TRUE(g.peek(kOwner, "x", kT, false, kT).ok());
  EXPECT_TRUE(g.peek(kOwner, "x", kT, false, kT).ok());
  EXPECT_EQ(g.size(), 0u);
  EXPECT_EQ(code_of(g.peek(kOwner, "y", kT - 31'000, false, kT)), ErrorCode::kMessageStale);
  EXPECT_EQ(code_of(g.peek(kOwner, "y", kT + 6'000, false, kT)), ErrorCode::kMessageStale);
  ASSERT_TRUE(g.check(kOwner, "x", kT, false, kT).ok());
  EXPECT_EQ(code_of(g.peek(kOwner, "x", kT, false, kT)), ErrorCode::kReplayDetected);
  EXPECT_TRUE(g.peek(kGuest, "x", kT, false, kT).ok());
  // A stop seen before is let through by both, and reported.
  ASSERT_TRUE(g.check(kOwner, "stop", kT, true, kT).ok());
  auto p = g.peek(kOwner, "stop", kT, true, kT);
  ASSERT_TRUE(p.ok());
  EXPECT_TRUE(p->duplicate_safety);
  auto c = g.check(kOwner, "stop", kT, true, kT);
  ASSERT_TRUE(c.ok());
  EXPECT_TRUE(c->duplicate_safety);
  EXPECT_EQ(g.size(), 2u);
}

// The review's reproduction, on the memory alone (10,000 ids, the defaults): a GUEST sends
// 12,000 ids stamped 4.9 s ahead over 2.6 s. It holds at most its share; it never removes one of
// the OWNER's ids, and the OWNER's fresh messages stay fresh throughout and after.
TEST(Replay, AFutureStampedFloodStaysInItsOwnShare) {
  ReplayGuard g;
  ASSERT_EQ(g.share(), 625u);
  ASSERT_TRUE(g.check(kOwner, "owner-0", kT, false, kT).ok());
  for (int i = 0; i < 12'000; ++i) {
    const int64_t now = kT + i * 2600 / 12'000;
    ASSERT_TRUE(g.check(kGuest, "g" + std::to_string(i), now + 4'900, false, now).ok()) << i;
    ASSERT_LE(g.size_of(kGuest), g.share());
    if (i % 1000 == 999) {
      ASSERT_TRUE(g.check(kOwner, "owner-" + std::to_string(i), now, false, now).ok()) << i;
    }
  }
  EXPECT_EQ(g.size_of(kGuest), 625u);
  EXPECT_EQ(g.evictions(), 12'000u - 625u);
  EXPECT_EQ(g.size_of(kOwner), 13u);  // nothing of the OWNER's was removed
  // The guest's forgotten ids stay refused (its own refused range), as do its remembered ones.
  EXPECT_EQ(code_of(g.check(kGuest, "g0", kT + 4'900, false, kT + 2'700)),
            ErrorCode::kMessageStale);
  EXPECT_EQ(code_of(g.check(kGuest, "g11999", kT + 2'599 + 4'900, false, kT + 2'700)),
            ErrorCode::kReplayDetected);
  // Every moment of the next 30 s is fresh for the OWNER.
  for (int64_t at = kT + 2'700; at < kT + 32'700; at += 100)
    ASSERT_TRUE(g.check(kOwner, "late-" + std::to_string(at), at, false, at).ok()) << at - kT;
}

// A principal past its share makes room from its own oldest ids; a forgotten id can never be
// replayed, and only that principal's messages stamped inside its refused range are affected.
TEST(Replay, APrincipalAtItsShareForgetsOnlyItsOwnOldestAndSafely) {
  ReplayOptions o;
  o.capacity = 160;  // a share of 10
  ReplayGuard g(o);
  ASSERT_EQ(g.share(), 10u);
  for (int i = 0; i < 10; ++i)
    ASSERT_TRUE(g.check(kOwner, "o" + std::to_string(i), kT + i, false, kT + 20).ok());
  for (int i = 0; i < 100; ++i)
    ASSERT_TRUE(g.check(kGuest, "g" + std::to_string(i), kT + 100 + i, false, kT + 200).ok());
  EXPECT_EQ(g.size_of(kGuest), 10u);
  EXPECT_EQ(g.size_of(kOwner), 10u);
  EXPECT_EQ(g.evictions(), 90u);
  // Every id the guest used is still refused: forgotten ones as stale, the rest as replays.
  for (int i = 0; i < 100; ++i) {
    auto r = g.check(kGuest, "g" + std::to_string(i), kT + 100 + i, false, kT + 300);
    EXPECT_EQ(code_of(r), i < 90 ? ErrorCode::kMessageStale : ErrorCode::kReplayDetected) << i;
  }
  // The owner's ids and its messages stamped in the guest's refused range are untouched.
  EXPECT_EQ(code_of(g.check(kOwner, "o0", kT, false, kT + 300)), ErrorCode::kReplayDetected);
  EXPECT_TRUE(g.check(kOwner, "o-in-guest-range", kT + 150, false, kT + 300).ok());
  // The guest's own later messages are fresh.
  EXPECT_TRUE(g.check(kGuest, "g-next", kT + 300, false, kT + 300).ok());
}

// The whole memory full: a principal below its share is refused (never made stale, never
// evicting anyone), a stop passes unremembered, a principal at its share goes on, and every
// place comes back once the ids leave the window.
TEST(Replay, AFullMemoryRefusesPrincipalsBelowTheirShareButNeverAStop) {
  ReplayOptions o;
  o.capacity = 32;
  ReplayGuard g(o);
  ASSERT_EQ(g.share(), 2u);
  for (int p = 0; p < 16; ++p)
    for (int i = 0; i < 2; ++i)
      ASSERT_TRUE(g.check("p" + std::to_string(p), std::to_string(i), kT, false, kT).ok());
  ASSERT_EQ(g.size(), 32u);
  auto refused = g.check(kOwner, "x", kT + 10, false, kT + 10);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kRateLimited);
  EXPECT_EQ(refused.error().reason, "replay_memory_full");
  EXPECT_EQ(g.full_refusals(), 1u);
  EXPECT_EQ(g.retry_after_ms(kT + 10), 30'000 - 10 + 1);
  // Refused, not remembered: the same id is fresh once there is room.
  auto stop = g.check(kOwner, "stop", kT + 10, true, kT + 10);
  ASSERT_TRUE(stop.ok());
  EXPECT_TRUE(stop->unremembered);
  EXPECT_EQ(g.size(), 32u);
  EXPECT_TRUE(g.check("p0", "2", kT + 10, false, kT + 10).ok());  // at its share: its own room
  EXPECT_EQ(g.size(), 32u);
  EXPECT_EQ(g.size_of("p1"), 2u);
  EXPECT_TRUE(g.check(kOwner, "x", kT + 10, false, kT + 30'001).ok());
  EXPECT_EQ(g.size(), 2u);  // p0's "2" (stamped kT + 10) and the owner's "x"
  EXPECT_EQ(g.principals(), 2u);
}

TEST(Replay, TheShareIsASixteenthOfTheMemoryUnlessSet) {
  EXPECT_EQ(ReplayGuard().share(), 625u);
  ReplayOptions o;
  o.capacity = 100;
  EXPECT_EQ(ReplayGuard(o).share(), 6u);
  o.capacity = 10;
  EXPECT_EQ(ReplayGuard(o).share(), 1u);
  o.principal_share = 50;
  EXPECT_EQ(ReplayGuard(o).share(), 10u);  // never more than the whole memory
  o.capacity = 1000;
  EXPECT_EQ(ReplayGuard(o).share(), 50u);
}

// Principals on their own threads (as the node's I/O threads are): each sends the same ids;
// each principal accepts every id once and refuses every copy, whatever the others do.
TEST(Replay, PrincipalsOnThreadsNeverShareIds) {
  ReplayOptions o;
  o.capacity = 64 * 1024;
  ReplayGuard g(o);
  constexpr int kThreads = 8, kIds = 2000;
  std::atomic<int> wrong{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      const std::string p = "iss\x1fp" + std::to_string(t);
      for (int i = 0; i < kIds; ++i) {
        const std::string id = "id-" + std::to_string(i);
        if (!g.check(p, id, kT + i, false, kT + i).ok()) ++wrong;
        if (code_of(g.peek(p, id, kT + i, false, kT + i)) != ErrorCode::kReplayDetected) ++wrong;
        if (code_of(g.check(p, id, kT + i, false, kT + i)) != ErrorCode::kReplayDetected) ++wrong;
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(wrong.load(), 0);
  EXPECT_EQ(g.size(), static_cast<size_t>(kThreads * kIds));
  EXPECT_EQ(g.principals(), static_cast<size_t>(kThreads));
  EXPECT_EQ(g.evictions(), 0u);
}

}  // namespace
}  // namespace rcan::node

// Fault injection in the spirit of LevelDB's fault_injection_test.cc: the process "dies"
// at every file-system operation in turn — inside an append, a group commit, a rotation,
// a retention pass, and inside recovery itself — the machine loses whatever was not
// fsync'ed (optionally leaving a torn tail), and the log is reopened. Every acknowledged
// record must be there, the chain must verify, and a recovery record must say so.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <condition_variable>
#include <cstdlib>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

#include "audit_util.h"
#include "rcan/audit/audit_log.h"
#include "rcan/audit/verify.h"
#include "test_support.h"
#include "testing/fault_env.h"

namespace rcan::audit {
namespace {

using namespace testutil;
using base::FaultInjectionEnv;
using rcan::test::TempDir;

// The fault env models the disk (what was synced survives); the real fsyncs underneath
// only cost time, so this suite's temporary directories go to tmpfs when there is one. Set for
// the suite only and restored after it: the folder's other suites share this program.
class AuditFault : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const char* old = std::getenv("TMPDIR");
    saved_tmpdir_ = old != nullptr ? std::optional<std::string>(old) : std::nullopt;
    if (::access("/dev/shm", W_OK) == 0) ::setenv("TMPDIR", "/dev/shm", 1);
  }
  static void TearDownTestSuite() {
    if (saved_tmpdir_) {
      ::setenv("TMPDIR", saved_tmpdir_->c_str(), 1);
    } else {
      ::unsetenv("TMPDIR");
    }
  }

 private:
  static inline std::optional<std::string> saved_tmpdir_;
};

struct Acked {
  uint64_t seq;
  std::string message_id;
};

AuditOptions fault_options(Env* env, bool retention) {
  AuditOptions o = options(1500);  // a rotation every few records
  o.env = env;
  o.background_index = false;  // deterministic operation order
  if (retention) o.retention_max_bytes = 6000;
  return o;
}

// Appends until the injected fault stops the log. Returns whether a fault happened.
bool run_workload(const std::string& dir, FaultInjectionEnv& env, uint64_t fail_at, bool retention,
                  bool grouped, int n, std::vector<Acked>* acked) {
  auto log = AuditLog::open(dir, fault_options(env.audit(), retention));
  if (!log.ok()) return true;  // died during open
  env.fail_after(fail_at);
  int i = 0;
  while (i < n) {
    if (!grouped) {
      AuditEntry e = entry(i);
      auto r = (*log)->append(e);
      if (!r.ok()) {
        EXPECT_EQ(r.error().code, ErrorCode::kAuditUnavailable);
        break;
      }
      acked->push_back({r->seq, e.message_id});
      ++i;
      continue;
    }
    // Several records in flight: they share group commits.
    std::mutex mu;
    std::condition_variable cv;
    int pending = 4;
    bool any_failed = false;
    for (int k = 0; k < 4; ++k, ++i) {
      AuditEntry e = entry(i);
      std::string mid = e.message_id;
      (*log)->append_async(std::move(e), [&, mid](Result<Receipt> r) {
        std::lock_guard<std::mutex> l(mu);
        if (r.ok()) {
          acked->push_back({r->seq, mid});
        } else {
          any_failed = true;
        }
        if (--pending == 0) cv.notify_all();
      });
    }
    std::unique_lock<std::mutex> l(mu);
    cv.wait(l, [&] { return pending == 0; });
    if (any_failed) break;
  }
  bool crashed = env.failed();
  log->reset();  // the "process" ends; with a fault it wrote no CLEAN marker
  return crashed;
}

int g_torn_cuts = 0;  // recoveries that cut a torn tail

void check_recovered(const std::string& dir, const std::vector<Acked>& acked, bool expect_recovery,
                     const std::string& ctx) {
  auto log = AuditLog::open(dir, fault_options(Env::posix(), false));
  ASSERT_TRUE(log.ok()) << ctx << ": " << log.error().message;
  for (const auto& a : acked) {
    auto line = (*log)->get(a.seq);
    if (!line.ok()) {
      // Only retention may have removed it, and then it is older than the first kept seq.
      EXPECT_LT(a.seq, (*log)->stats().first_seq)
          << ctx << ": acknowledged seq " << a.seq << " lost";
      continue;
    }
    EXPECT_EQ(parse(*line).get("message_id")->as_string(), a.message_id) << ctx << " seq " << a.seq;
  }
  auto lines = export_lines(**log);
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_TRUE(rep.ok) << ctx << ": " << rep.why << " at seq " << rep.first_bad_seq;
  if (expect_recovery) {
    bool saw = false;
    for (auto it = lines.rbegin(); it != lines.rend() && it - lines.rbegin() < 3; ++it)
      if (kind_of(*it) == "recovery") {
        saw = true;
        g_torn_cuts += parse(*it).get("detail")->get("bytes_cut")->as_int() > 0;
      }
    EXPECT_TRUE(saw) << ctx << ": no recovery record at the end of the chain";
  }
  log->reset();
  auto dirrep = verify_dir(dir, kSecret);
  EXPECT_TRUE(dirrep.ok) << ctx << ": " << dirrep.why;
}

void crash_everywhere(bool retention, bool grouped, double keep_fraction, bool torn_appends) {
  int runs = 0;
  for (uint64_t k = 1;; ++k) {
    TempDir tmp;
    std::string dir = tmp.path() + "/log";
    FaultInjectionEnv env(base::Env::posix());
    env.set_torn_appends(torn_appends);
    std::vector<Acked> acked;
    bool crashed = run_workload(dir, env, k, retention, grouped, 24, &acked);
    ASSERT_TRUE(env.drop_unsynced(keep_fraction).ok());
    std::string ctx = "crash at op " + std::to_string(k) + (retention ? " +retention" : "") +
                      (grouped ? " grouped" : "") + " keep=" + std::to_string(keep_fraction);
    check_recovered(dir, acked, crashed, ctx);
    if (::testing::Test::HasFailure()) return;
    ++runs;
    if (!crashed) break;  // the workload finished before op k: every point was covered
    ASSERT_LT(k, 5000u) << "workload never finishes";
  }
  EXPECT_GT(runs, 20);
}

// A disk slower than the records coming in: the queue is bounded, the records beyond it are
// refused at once (audit_queue_full), and every record it took is written once the disk moves.
TEST_F(AuditFault, TheWriterQueueIsBoundedAndRefusesWhatItCannotHold) {
  TempDir tmp;
  FaultInjectionEnv env(base::Env::posix());
  AuditOptions o = options();
  o.env = env.audit();
  o.preallocate = false;
  o.max_queued_records = 4;
  auto log = AuditLog::open(tmp.path() + "/log", o);
  ASSERT_TRUE(log.ok()) << log.error().message;
  env.hold(true);  // the disk stops taking writes
  std::mutex mu;
  std::condition_variable cv;
  int ok = 0, full = 0, other = 0;
  const int n = 20;
  for (int i = 0; i < n; ++i) {
    (*log)->append_async(entry(i), [&](Result<Receipt> r) {
      std::lock_guard<std::mutex> l(mu);
      if (r.ok()) {
        ++ok;
      } else if (r.error().reason == "audit_queue_full") {
        ++full;
      } else {
        ++other;
      }
      cv.notify_all();
    });
  }
  {
    std::unique_lock<std::mutex> l(mu);
    EXPECT_GT(full, 0);  // refused at once, while the disk still holds every write
  }
  env.hold(false);
  std::unique_lock<std::mutex> l(mu);
  ASSERT_TRUE(cv.wait_for(l, std::chrono::seconds(10), [&] { return ok + full + other == n; }));
  EXPECT_EQ(other, 0);
  EXPECT_EQ(ok + full, n);
  EXPECT_LE(full, n - 4);
  EXPECT_EQ(static_cast<int>(export_lines(**log).size()), 1 + ok);  // the genesis checkpoint too
}

TEST_F(AuditFault, CrashAtEveryOperationLosesNoAcknowledgedRecord) {
  crash_everywhere(/*retention=*/false, /*grouped=*/false, 0.0, false);
}

TEST_F(AuditFault, TornTailsAreCutAndRecorded) {
  g_torn_cuts = 0;
  crash_everywhere(/*retention=*/false, /*grouped=*/false, 0.5, true);
  EXPECT_GT(g_torn_cuts, 10);
}

TEST_F(AuditFault, CrashDuringGroupCommits) {
  crash_everywhere(/*retention=*/false, /*grouped=*/true, 0.7, true);
}

TEST_F(AuditFault, CrashDuringRotationAndRetention) {
  crash_everywhere(/*retention=*/true, /*grouped=*/false, 0.3, true);
}

// A second crash inside recovery (cutting the tail, writing the quarantine file, the
// recovery record) must still leave a log that recovers.
TEST_F(AuditFault, CrashInsideRecovery) {
  for (uint64_t first : {7u, 12u, 19u}) {
    for (uint64_t second = 1; second < 40; ++second) {
      TempDir tmp;
      std::string dir = tmp.path() + "/log";
      std::vector<Acked> acked;
      {
        FaultInjectionEnv env(base::Env::posix());
        env.set_torn_appends(true);
        run_workload(dir, env, first, false, false, 24, &acked);
        ASSERT_TRUE(env.drop_unsynced(0.5).ok());
      }
      {
        FaultInjectionEnv env(base::Env::posix());
        env.fail_after(second);
        auto log = AuditLog::open(dir, fault_options(env.audit(), false));
        if (log.ok()) (void)(*log)->append(entry(100));
        log = Error();  // drop it
        ASSERT_TRUE(env.drop_unsynced(0.5).ok());
      }
      check_recovered(
          dir, acked, true,
          "first crash " + std::to_string(first) + ", second " + std::to_string(second));
      if (::testing::Test::HasFailure()) return;
    }
  }
}

TEST_F(AuditFault, DiskFailureFailsClosed) {
  TempDir tmp;
  FaultInjectionEnv env(base::Env::posix());
  AuditOptions o = fault_options(env.audit(), false);
  o.recovery_interval_ms = 0;  // no probe: failed until reopened
  auto log = AuditLog::open(tmp.path() + "/log", o);
  ASSERT_TRUE(log.ok());
  ASSERT_TRUE((*log)->append(entry(1)).ok());
  env.fail_after(1);
  auto r = (*log)->append(entry(2));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kAuditUnavailable);
  // Sticky without a probe: the log does not come back by itself even if the disk does.
  env.fail_after(0);
  auto again = (*log)->append(entry(3));
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.error().code, ErrorCode::kAuditUnavailable);
  EXPECT_TRUE((*log)->stats().failed);
}

// With the probe on, the log comes back once the disk does: the chain continues from the
// last acknowledged record in a new segment (checkpoint + recovery record), nothing that was
// refused is in it, and the directory verifies. Run for a failure at each of the first
// operations of a group commit (the write, the sync), with and without torn appends, and in
// the middle of a rotation.
void fail_then_recover(uint64_t fail_at, bool torn, bool pipelined) {
  SCOPED_TRACE("fail_at " + std::to_string(fail_at) + (torn ? " torn" : "") +
               (pipelined ? " pipelined" : ""));
  TempDir tmp;
  const std::string dir = tmp.path() + "/log";
  FaultInjectionEnv env(base::Env::posix());
  env.set_torn_appends(torn);
  AuditOptions o = fault_options(env.audit(), false);
  o.background_index = pipelined;
  o.pipelined_sync = pipelined;
  o.recovery_interval_ms = 20;
  auto log = AuditLog::open(dir, o);
  ASSERT_TRUE(log.ok());
  std::vector<Acked> acked;
  int i = 0;
  for (; i < 5; ++i) {
    auto r = (*log)->append(entry(i));
    ASSERT_TRUE(r.ok());
    acked.push_back({r->seq, "msg-" + std::to_string(i)});
  }
  env.fail_after(fail_at);
  std::set<std::string> refused;
  for (; i < 40; ++i) {
    auto r = (*log)->append(entry(i));
    if (!r.ok()) {
      EXPECT_EQ(r.error().code, ErrorCode::kAuditUnavailable);
      refused.insert("msg-" + std::to_string(i));
      ++i;
      break;
    }
    acked.push_back({r->seq, "msg-" + std::to_string(i)});
  }
  ASSERT_FALSE(refused.empty()) << "the fault never tripped";
  EXPECT_FALSE((*log)->available());
  // Still failing: the probe keeps failing, appends are refused at once.
  std::this_thread::sleep_for(std::chrono::milliseconds(60));
  EXPECT_FALSE((*log)->available());
  env.fail_after(0);  // the disk is back
  bool back = false;
  for (int k = 0; k < 500 && !back; ++k) {
    back = (*log)->available();
    if (!back) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(back) << "the log did not recover";
  for (int k = 0; k < 10; ++k, ++i) {
    auto r = (*log)->append(entry(i));
    ASSERT_TRUE(r.ok()) << r.error().message;
    acked.push_back({r->seq, "msg-" + std::to_string(i)});
  }
  EXPECT_GE((*log)->stats().recoveries, 1u);
  auto lines = export_lines(**log);
  log->reset();
  // Every acknowledged record is there, nothing refused is, and the chain says it recovered.
  std::set<std::string> ids;
  int recoveries = 0;
  for (const auto& l : lines) {
    json::Value v = parse(l);
    ids.insert(v.get("message_id")->as_string());
    if (v.get("event")->as_string() == "AUDIT_RECOVERY" &&
        v.get("outcome")->as_string() == "repaired")
      ++recoveries;
  }
  for (const auto& a : acked) EXPECT_TRUE(ids.count(a.message_id)) << a.message_id;
  for (const auto& r : refused)
    EXPECT_FALSE(ids.count(r)) << r << " was refused but is in the chain";
  EXPECT_GE(recoveries, 1);
  VerifyReport rep = verify_jsonl(join(lines), kSecret);
  EXPECT_TRUE(rep.ok) << rep.why << " at seq " << rep.first_bad_seq;
  VerifyReport drep = verify_dir(dir, kSecret);
  EXPECT_TRUE(drep.ok) << drep.why << " at seq " << drep.first_bad_seq;
  // And it reopens cleanly.
  auto again = AuditLog::open(dir, fault_options(env.audit(), false));
  ASSERT_TRUE(again.ok()) << again.error().message;
}

// A commit on the appender's thread (Commit::kHereIfIdle) that meets a failing disk: the
// appender is told at once, the log fails closed, and the writer, idle until then, probes the
// disk and recovers the log when it takes writes again.
TEST_F(AuditFault, AFailedCommitOnTheAppendersThreadIsRecoveredByTheWriter) {
  TempDir tmp;
  const std::string dir = tmp.path() + "/log";
  FaultInjectionEnv env(base::Env::posix());
  AuditOptions o = fault_options(env.audit(), false);
  o.recovery_interval_ms = 20;
  auto log = AuditLog::open(dir, o);
  ASSERT_TRUE(log.ok());
  // Every append here commits on this thread: the writer stays idle throughout.
  std::optional<Result<Receipt>> first;
  (*log)->append_async(
      entry(0), [&](Result<Receipt> got) { first.emplace(std::move(got)); }, Commit::kHereIfIdle);
  ASSERT_TRUE(first.has_value() && first->ok());
  env.fail_after(1);
  std::optional<Result<Receipt>> r;
  (*log)->append_async(
      entry(1), [&](Result<Receipt> got) { r.emplace(std::move(got)); }, Commit::kHereIfIdle);
  ASSERT_TRUE(r.has_value());
  ASSERT_FALSE(r->ok());
  EXPECT_EQ(r->error().code, ErrorCode::kAuditUnavailable);
  EXPECT_FALSE((*log)->available());
  env.fail_after(0);  // the disk is back
  ASSERT_TRUE(rcan::test::eventually([&] { return (*log)->available(); }))
      << "the writer never probed the disk after the appender's commit failed";
  std::optional<Result<Receipt>> again;
  (*log)->append_async(
      entry(2), [&](Result<Receipt> got) { again.emplace(std::move(got)); }, Commit::kHereIfIdle);
  ASSERT_TRUE(again.has_value());
  ASSERT_TRUE(again->ok()) << again->error().message;
  log->reset();
  auto v = verify_dir(dir, kSecret);
  EXPECT_TRUE(v.ok) << v.why;
}

TEST_F(AuditFault, DiskFailureRecoversWhenTheDiskDoes) {
  for (uint64_t k = 1; k <= 12; ++k) {
    fail_then_recover(k, false, false);
    if (::testing::Test::HasFailure()) return;
  }
  for (uint64_t k = 1; k <= 12; ++k) {
    fail_then_recover(k, true, false);
    if (::testing::Test::HasFailure()) return;
  }
  for (uint64_t k = 1; k <= 6; ++k) {
    fail_then_recover(k, true, true);
    if (::testing::Test::HasFailure()) return;
  }
}

}  // namespace
}  // namespace rcan::audit

// Many appenders + a concurrent exporter end in one valid chain; a real SIGKILL of a
// process that is appending loses no acknowledged record.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>
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

TEST(AuditConcurrency, ManyAppendersAndAnExporterMakeOneValidChain) {
  TempDir tmp;
  std::string dir = tmp.path() + "/log";
  auto opened = AuditLog::open(dir, options(64 * 1024));  // rotations while exporting
  ASSERT_TRUE(opened.ok());
  AuditLog& log = **opened;
  constexpr int kThreads = 8;
  constexpr int kPerThread = 400;
  std::mutex mu;
  std::map<uint64_t, std::string> acked;  // seq → message_id
  std::atomic<bool> done{false};
  std::atomic<int> exports{0};
  std::atomic<int> export_failures{0};

  std::thread reader([&] {
    while (!done.load()) {
      auto lines = export_lines(log);
      auto rep = verify_jsonl(join(lines), kSecret);
      if (!rep.ok) {
        ++export_failures;
        ADD_FAILURE() << "concurrent export did not verify: " << rep.why << " at "
                      << rep.first_bad_seq;
      }
      ++exports;
    }
  });
  std::vector<std::thread> writers;
  for (int t = 0; t < kThreads; ++t) {
    writers.emplace_back([&, t] {
      for (int i = 0; i < kPerThread; ++i) {
        AuditEntry e = entry(t * 100000 + i);
        auto r = log.append(e);
        ASSERT_TRUE(r.ok()) << r.error().message;
        std::lock_guard<std::mutex> l(mu);
        EXPECT_TRUE(acked.emplace(r->seq, e.message_id).second) << "seq handed out twice";
      }
    });
  }
  for (auto& w : writers) w.join();
  done = true;
  reader.join();
  EXPECT_GT(exports.load(), 0);
  EXPECT_EQ(export_failures.load(), 0);

  auto lines = export_lines(log);
  auto rep = verify_jsonl(join(lines), kSecret);
  ASSERT_TRUE(rep.ok) << rep.why;
  ASSERT_EQ(acked.size(), static_cast<size_t>(kThreads * kPerThread));
  std::map<uint64_t, std::string> stored;
  for (const auto& l : lines) {
    auto v = parse(l);
    stored[static_cast<uint64_t>(v.get("seq")->as_int())] = v.get("message_id")->as_string();
  }
  for (const auto& [seq, mid] : acked) EXPECT_EQ(stored[seq], mid) << seq;
  EXPECT_GT(log.stats().segments, 2u);
  // Group commit happened: fewer fsyncs than records.
  EXPECT_LT(log.stats().syncs, static_cast<uint64_t>(kThreads * kPerThread));
}

TEST(AuditConcurrency, AsyncAppendsAreAcknowledgedInSeqOrder) {
  TempDir tmp;
  auto opened = AuditLog::open(tmp.path() + "/log", options());
  ASSERT_TRUE(opened.ok());
  std::mutex mu;
  std::vector<uint64_t> order;
  std::atomic<int> left{500};
  for (int i = 0; i < 500; ++i) {
    (*opened)->append_async(entry(i), [&](Result<Receipt> r) {
      ASSERT_TRUE(r.ok());
      std::lock_guard<std::mutex> l(mu);
      order.push_back(r->seq);
      --left;
      left.notify_all();
    });
  }
  for (int v = left.load(); v != 0; v = left.load()) left.wait(v);
  ASSERT_EQ(order.size(), 500u);
  for (size_t i = 1; i < order.size(); ++i) EXPECT_EQ(order[i], order[i - 1] + 1);
}

// A quiet log syncs a lone group in the writer itself; a busy one hands each group to the
// syncer and writes the next. Alternating the two, from several threads: every record is
// acknowledged once, in seq order per appender, durable (readable) when acknowledged, and
// the chain verifies.
TEST(AuditConcurrency, QuietAndBurstyAppendsAckInOrderAndReadBack) {
  TempDir tmp;
  auto opened = AuditLog::open(tmp.path() + "/log", options());
  ASSERT_TRUE(opened.ok());
  AuditLog& log = **opened;
  const uint64_t before = log.stats().last_seq;  // the log's own opening record
  std::atomic<int> unreadable{0}, failed{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 3; ++t) {
    threads.emplace_back([&, t] {
      uint64_t last = 0;
      for (int round = 0; round < 30; ++round) {
        auto lone = log.append(entry(t * 10000 + round * 100));  // waits: the log goes quiet
        if (!lone.ok() || lone->seq <= last) failed.fetch_add(1);
        if (lone.ok()) {
          last = lone->seq;
          if (!log.get(lone->seq).ok()) unreadable.fetch_add(1);
        }
        std::atomic<int> left{20};
        for (int i = 1; i <= 20; ++i) {
          log.append_async(entry(t * 10000 + round * 100 + i), [&](Result<Receipt> r) {
            if (!r.ok() || !log.get(r->seq).ok()) unreadable.fetch_add(1);
            left.fetch_sub(1);
            left.notify_all();
          });
        }
        for (int v = left.load(); v != 0; v = left.load()) left.wait(v);
      }
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(failed.load(), 0);
  EXPECT_EQ(unreadable.load(), 0);
  auto st = log.stats();
  EXPECT_EQ(st.last_seq, before + 3u * 30u * 21u);
  EXPECT_LE(st.syncs, st.groups_committed);
  opened->reset();
  auto v = verify_dir(tmp.path() + "/log", kSecret);
  EXPECT_TRUE(v.ok) << v.why;
  EXPECT_EQ(v.count, before + 3u * 30u * 21u);
}

// Commit::kHereIfIdle: an idle log commits the record on the appender's own thread (the
// answer is ready before append_async returns: no hand-off to the writer and back); a log
// whose writer has work commits it on the writer, in order behind that work.
TEST(AuditConcurrency, AnIdleLogCommitsOnTheAppendersThreadABusyOneOnTheWriters) {
  TempDir tmp;
  FaultInjectionEnv env(base::Env::posix());
  AuditOptions o = options();
  o.env = env.audit();
  o.preallocate = false;
  auto opened = AuditLog::open(tmp.path() + "/log", o);
  ASSERT_TRUE(opened.ok()) << opened.error().message;
  AuditLog& log = **opened;
  const auto me = std::this_thread::get_id();

  std::optional<Result<Receipt>> here;
  std::thread::id here_on;
  log.append_async(
      entry(1),
      [&](Result<Receipt> r) {
        here.emplace(std::move(r));
        here_on = std::this_thread::get_id();
      },
      Commit::kHereIfIdle);
  ASSERT_TRUE(here.has_value()) << "an idle log answers before append_async returns";
  ASSERT_TRUE(here->ok()) << here->error().message;
  EXPECT_EQ(here_on, me);
  EXPECT_TRUE(log.get((*here)->seq).ok()) << "durable and readable when acknowledged";

  // The disk hangs under the writer's record: the next one queues behind it.
  env.hold(true);
  std::mutex mu;
  std::condition_variable cv;
  std::vector<std::pair<uint64_t, std::thread::id>> acks;
  auto note = [&](Result<Receipt> r) {
    std::lock_guard<std::mutex> l(mu);
    acks.emplace_back(r.ok() ? r->seq : 0, std::this_thread::get_id());
    cv.notify_all();
  };
  log.append_async(entry(2), note, Commit::kWriter);
  log.append_async(entry(3), note, Commit::kHereIfIdle);
  {
    std::lock_guard<std::mutex> l(mu);
    EXPECT_TRUE(acks.empty()) << "a busy log never makes the appender wait for the disk";
  }
  env.hold(false);
  std::unique_lock<std::mutex> l(mu);
  ASSERT_TRUE(cv.wait_for(l, std::chrono::seconds(10), [&] { return acks.size() == 2; }));
  EXPECT_EQ(acks[0].first, (*here)->seq + 1);
  EXPECT_EQ(acks[1].first, (*here)->seq + 2);
  for (const auto& [seq, on] : acks) EXPECT_NE(on, me) << seq;
}

// Appenders committing on their own threads and the writer committing for the others, at
// once: every record is acknowledged once, in seq order per appender, and the chain verifies.
TEST(AuditConcurrency, AppendersAndTheWriterCommittingTogetherMakeOneChain) {
  TempDir tmp;
  auto opened = AuditLog::open(tmp.path() + "/log", options(48 * 1024));  // rotations too
  ASSERT_TRUE(opened.ok());
  AuditLog& log = **opened;
  const uint64_t before = log.stats().last_seq;
  constexpr int kThreads = 4, kEach = 300;
  std::atomic<int> bad{0}, inline_commits{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      uint64_t last = 0;
      for (int i = 0; i < kEach; ++i) {
        std::atomic<int> done{0};
        std::atomic<uint64_t> seq{0};
        const bool here = i % 2 == 0;
        log.append_async(
            entry(t * 100000 + i),
            [&](Result<Receipt> r) {
              if (r.ok()) seq.store(r->seq);
              done.store(1);
              done.notify_all();
            },
            here ? Commit::kHereIfIdle : Commit::kWriter);
        if (here && done.load() == 1) inline_commits.fetch_add(1);
        done.wait(0);
        if (seq.load() <= last) bad.fetch_add(1);
        last = seq.load();
      }
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(bad.load(), 0);
  EXPECT_GT(inline_commits.load(), 0);
  opened->reset();
  auto v = verify_dir(tmp.path() + "/log", kSecret);
  EXPECT_TRUE(v.ok) << v.why;
  EXPECT_GE(v.count, before + kThreads * kEach);  // and a checkpoint per rotation
}

TEST(AuditConcurrency, IntervalSyncPolicyAcknowledgesAfterSync) {
  TempDir tmp;
  AuditOptions o = options(32 * 1024);
  o.sync_policy = SyncPolicy::kInterval;
  o.sync_interval_ms = 3;
  auto opened = AuditLog::open(tmp.path() + "/log", o);
  ASSERT_TRUE(opened.ok());
  std::vector<std::thread> ts;
  for (int t = 0; t < 4; ++t)
    ts.emplace_back([&, t] {
      for (int i = 0; i < 200; ++i) ASSERT_TRUE((*opened)->append(entry(t * 1000 + i)).ok());
    });
  for (auto& t : ts) t.join();
  auto st = (*opened)->stats();
  EXPECT_EQ(st.last_seq, 801u + (st.segments - 1));  // 800 + genesis + one checkpoint per rotation
  EXPECT_TRUE(verify_jsonl(join(export_lines(**opened)), kSecret).ok);
}

// The child appends from 4 threads and reports each acknowledged seq on a pipe; the
// parent SIGKILLs it at some instant, then reopens the log.
void kill_child_and_check(int delay_ms) {
  TempDir tmp;
  std::string dir = tmp.path() + "/log";
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::close(fds[0]);
    auto log = AuditLog::open(dir, options(256 * 1024));
    if (!log.ok()) ::_exit(3);
    std::vector<std::thread> ts;
    for (int t = 0; t < 4; ++t) {
      ts.emplace_back([&, t] {
        for (int i = 0;; ++i) {
          AuditEntry e = entry(t * 10000000 + i);
          auto r = (*log)->append(e);
          if (!r.ok()) ::_exit(4);
          std::string msg = std::to_string(r->seq) + " " + e.message_id + "\n";
          if (::write(fds[1], msg.data(), msg.size()) < 0) ::_exit(5);
        }
      });
    }
    for (auto& t : ts) t.join();
    ::_exit(0);
  }
  ::close(fds[1]);
  // The kill lands `delay_ms` after the child's first acknowledgements, not after the fork: a
  // slow start (a loaded machine, a sanitizer build) must not leave nothing to check.
  std::string data;
  char buf[65536];
  ssize_t n;
  while (std::count(data.begin(), data.end(), '\n') <= 10 &&
         (n = ::read(fds[0], buf, sizeof buf)) > 0)
    data.append(buf, static_cast<size_t>(n));
  std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
  ASSERT_EQ(::kill(pid, SIGKILL), 0);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status)) << "child exited with " << WEXITSTATUS(status);
  while ((n = ::read(fds[0], buf, sizeof buf)) > 0) data.append(buf, static_cast<size_t>(n));
  ::close(fds[0]);
  std::map<uint64_t, std::string> acked;
  std::istringstream in(data);
  uint64_t seq;
  std::string mid;
  while (in >> seq >> mid) acked[seq] = mid;
  ASSERT_GT(acked.size(), 10u) << "child acknowledged too little before the kill";

  auto log = AuditLog::open(dir, options(256 * 1024));
  ASSERT_TRUE(log.ok()) << log.error().message;
  for (const auto& [s, m] : acked) {
    auto line = (*log)->get(s);
    ASSERT_TRUE(line.ok()) << "acknowledged seq " << s << " missing after SIGKILL";
    EXPECT_EQ(parse(*line).get("message_id")->as_string(), m);
  }
  auto lines = export_lines(**log);
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_TRUE(rep.ok) << rep.why << " at " << rep.first_bad_seq;
  EXPECT_GE(rep.last_seq, acked.rbegin()->first);
  bool recovery = false;
  for (auto it = lines.rbegin(); it != lines.rend() && it - lines.rbegin() < 3; ++it)
    recovery |= kind_of(*it) == "recovery";
  EXPECT_TRUE(recovery);
  log->reset();
  EXPECT_TRUE(verify_dir(dir, kSecret).ok);
}

TEST(AuditConcurrency, SigkillLosesNoAcknowledgedRecord) {
  for (int delay : {150, 400, 900}) {
    kill_child_and_check(delay);
    if (HasFailure()) return;
  }
}

}  // namespace
}  // namespace rcan::audit

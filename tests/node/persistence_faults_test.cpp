// The node's small durable files — the state files (leases, ownership, consent, credentials),
// the HiTL pending file and the safety core's ESTOP latch — are all written with
// base::Env::write_file_atomic. Here: what it does on the real file system (mode, no
// temporary left behind, no symbolic link followed), and, through FaultInjectionEnv, that a
// write failing at any step leaves the previous file whole, and what the safety core does when
// its latch cannot be persisted — and that an ESTOP is acknowledged only once its latch file
// is durable, or with the answer saying that it is not.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <future>
#include <memory>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "base/clock.h"
#include "in_process_node.h"
#include "node/ai/hitl.h"
#include "node/safety/actuation_safety.h"
#include "node/safety/safety.h"
#include "node/safety/sim_robot.h"
#include "node/services/node_services.h"
#include "node/vocabulary/stop_backlog.h"
#include "rcan/base/env.h"
#include "rcan/errors.h"
#include "runtime/state_file.h"
#include "test_support.h"
#include "testing/fault_env.h"

namespace rcan {
namespace {

using base::Env;
using base::FaultInjectionEnv;
using test::TempDir;

unsigned mode_of(const std::string& path) {
  struct stat st {};
  EXPECT_EQ(::stat(path.c_str(), &st), 0) << path;
  return st.st_mode & 07777;
}

bool present(const std::string& path) { return ::access(path.c_str(), F_OK) == 0; }

// What when_persisted() answers for `seq` (within 5 s; otherwise a failure and "no answer").
std::pair<bool, std::string> latch_answer(node::SafetyCore& core, uint64_t seq) {
  auto answered = std::make_shared<std::promise<std::pair<bool, std::string>>>();
  auto got = answered->get_future();
  core.when_persisted(seq, [answered](bool durable, const std::string& error) {
    answered->set_value({durable, error});
  });
  if (got.wait_for(std::chrono::seconds(5)) != std::future_status::ready) {
    ADD_FAILURE() << "the latch was not answered within 5 s";
    return {false, "no answer"};
  }
  return got.get();
}

// The latch file says latched (it is written cleared at the first start, and a latch rewrites
// it in place).
bool says_latched(const std::string& path) {
  if (!present(path)) return false;
  auto v = json::parse(test::read_file(path));
  const json::Value* a = v.ok() ? v->get("estop_active") : nullptr;
  return a != nullptr && a->is_bool() && a->as_bool();
}

// ---- Env::write_file_atomic on the real file system -----------------------------------------

TEST(AtomicWrite, ReplacesTheFileWithMode0600AndNoTemporaryLeft) {
  TempDir dir;
  const std::string f = dir.file("state.json");
  { std::ofstream(f) << "old"; }
  ASSERT_EQ(::chmod(f.c_str(), 0644), 0);
  const mode_t old_mask = ::umask(0);  // the mode must not depend on the umask
  base::IoStatus s = Env::posix()->write_file_atomic(f, "new contents\n");
  ::umask(old_mask);
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(test::read_file(f), "new contents\n");
  EXPECT_EQ(mode_of(f), 0600u);
  EXPECT_FALSE(present(f + ".tmp"));
}

TEST(AtomicWrite, AStaleTemporaryIsOverwritten) {
  TempDir dir;
  const std::string f = dir.file("state.json");
  { std::ofstream(f + ".tmp") << "left over by a crash, and longer than the new contents"; }
  ASSERT_EQ(::chmod((f + ".tmp").c_str(), 0644), 0);
  ASSERT_TRUE(Env::posix()->write_file_atomic(f, "fresh").ok());
  EXPECT_EQ(test::read_file(f), "fresh");
  EXPECT_EQ(mode_of(f), 0600u);
  EXPECT_FALSE(present(f + ".tmp"));
}

TEST(AtomicWrite, DoesNotWriteThroughASymlinkedTemporary) {
  TempDir dir;
  const std::string f = dir.file("state.json");
  const std::string victim = dir.file("victim");
  { std::ofstream(f) << "previous"; }
  { std::ofstream(victim) << "not yours"; }
  ASSERT_EQ(::symlink(victim.c_str(), (f + ".tmp").c_str()), 0);
  base::IoStatus s = Env::posix()->write_file_atomic(f, "new");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("open " + f + ".tmp: "), std::string::npos) << s.error().message;
  EXPECT_EQ(test::read_file(victim), "not yours");
  EXPECT_EQ(test::read_file(f), "previous");
}

TEST(AtomicWrite, ErrorsNameTheStepTheFileAndErrno) {
  TempDir dir;
  const std::string f = dir.file("missing-dir/state.json");
  base::IoStatus s = Env::posix()->write_file_atomic(f, "x");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().message, "open " + f + ".tmp: No such file or directory");
}

// ---- each step failing -----------------------------------------------------------------------

TEST(AtomicWrite, ItsStepsAreThreeFaultPoints) {
  TempDir dir;
  FaultInjectionEnv env(Env::posix());
  ASSERT_TRUE(env.write_file_atomic(dir.file("f"), "1").ok());
  EXPECT_EQ(env.mutations(), 3u);  // the temporary's synced write, the rename, the dir sync
}

TEST(AtomicWrite, AFailureAtAnyStepLeavesTheOldOrTheNewFileWhole) {
  for (uint64_t step = 1; step <= 3; ++step) {
    SCOPED_TRACE("failing step " + std::to_string(step));
    TempDir dir;
    const std::string f = dir.file("state.json");
    ASSERT_TRUE(Env::posix()->write_file_atomic(f, "old").ok());
    FaultInjectionEnv env(Env::posix());
    env.fail_after(step);
    base::IoStatus s = env.write_file_atomic(f, "new");
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find("injected fault"), std::string::npos) << s.error().message;
    // Before the rename the old file stands; a failed directory sync comes after it.
    EXPECT_EQ(test::read_file(f), step < 3 ? "old" : "new");
    // The "process" came back: the next write goes through, a leftover temporary or not.
    env.fail_after(0);
    ASSERT_TRUE(env.write_file_atomic(f, "again").ok());
    EXPECT_EQ(test::read_file(f), "again");
    EXPECT_FALSE(present(f + ".tmp"));
  }
}

// ---- the node's state files -------------------------------------------------------------------

TEST(StateFile, AFailedWriteKeepsThePreviousFile) {
  for (uint64_t step = 1; step <= 2; ++step) {
    SCOPED_TRACE("failing step " + std::to_string(step));
    TempDir dir;
    const std::string f = dir.file("leases.json");
    ASSERT_TRUE(write_state_file(f, json::Value(json::Object{{"leases", 1}})).ok());
    FaultInjectionEnv env(Env::posix());
    env.fail_after(step);
    Status s = write_state_file(f, json::Value(json::Object{{"leases", 2}}), &env);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, ErrorCode::kInternal);
    EXPECT_NE(s.error().message.find(f + ".tmp"), std::string::npos) << s.error().message;
    auto back = read_state_file(f);
    ASSERT_TRUE(back.ok()) << back.error().message;
    EXPECT_EQ(back->get("leases")->as_int(), 1);
    EXPECT_EQ(mode_of(f), 0600u);
  }
}

node::PendingItem held(const std::string& id) {
  node::PendingItem p;
  p.message_id = id;
  p.action_type = "move";
  p.message = json::Value(json::Object{{"type", "COMMAND"}, {"message_id", id}});
  p.role = Role::kLeasee;
  return p;
}

TEST(HitlPendingFile, AFailedSaveKeepsThePreviousList) {
  for (uint64_t step = 1; step <= 2; ++step) {
    SCOPED_TRACE("failing step " + std::to_string(step));
    TempDir dir;
    const std::string f = dir.file("hitl-pending.json");
    ASSERT_TRUE(node::save_pending(f, {held("a")}).ok());
    FaultInjectionEnv env(Env::posix());
    env.fail_after(step);
    Status s = node::save_pending(f, {held("a"), held("b")}, &env);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, ErrorCode::kInternal);
    size_t skipped = 0;
    auto back = node::load_pending(f, &skipped);
    ASSERT_TRUE(back.ok()) << back.error().message;
    ASSERT_EQ(back->size(), 1u);
    EXPECT_EQ((*back)[0].message_id, "a");
    EXPECT_EQ(skipped, 0u);
    EXPECT_EQ(mode_of(f), 0600u);
  }
}

// ---- the safety core's ESTOP latch -------------------------------------------------------------

struct SafetyRig {
  SafetyRig() {
    node::SimRobotConfig sim;
    sim.battery = false;
    auto d = std::make_unique<node::SimRobot>(sim);
    robot = d.get();
    core = std::make_unique<node::SafetyCore>(std::move(d), node::SafetyConfig{}, clock);
  }
  ManualClock clock;
  node::SimRobot* robot = nullptr;
  std::unique_ptr<node::SafetyCore> core;
};

// A latch that cannot be written is still a latch: the driver is stopped and commands are
// refused at once; the write is retried (every 200 ms) and the failure shows in status() —
// persistence.durable false, persistence.error naming the file — until a write succeeds.
TEST(SafetyLatchFile, AFailedWriteKeepsTheLatchReportsItAndIsRetried) {
  TempDir dir;
  FaultInjectionEnv env(Env::posix());
  SafetyRig r;
  ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
  env.fail_after(1);
  const uint64_t stops = r.robot->stop_count();
  auto e = r.core->estop("http", "operator pressed stop");
  EXPECT_TRUE(e.newly_latched);
  EXPECT_TRUE(r.core->estop_active());
  EXPECT_GT(r.robot->stop_count(), stops);
  auto d = r.core->dispatch(node::ActuatorCommand::make_drive(0.1, 0, 100));
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().reason, "estop_active");

  EXPECT_FALSE(r.core->wait_persisted(e.state_seq, 600));
  auto st = r.core->status();
  EXPECT_TRUE(st.persistence_enabled);
  EXPECT_FALSE(st.persisted);
  EXPECT_NE(st.persist_error.find("injected fault"), std::string::npos) << st.persist_error;
  EXPECT_NE(st.persist_error.find("safety_state.json"), std::string::npos) << st.persist_error;
  auto j = json::Value(st.to_json());
  EXPECT_FALSE(j.get("persistence")->get("durable")->as_bool());
  EXPECT_EQ(j.get("persistence")->get("error")->as_string(), st.persist_error);
  EXPECT_FALSE(says_latched(dir.file("safety_state.json")));

  env.fail_after(0);  // the disk is back: the next retry persists the latch
  ASSERT_TRUE(r.core->wait_persisted(e.state_seq, 5000));
  st = r.core->status();
  EXPECT_TRUE(st.persisted);
  EXPECT_EQ(st.persist_error, "");
  auto file = json::parse(test::read_file(dir.file("safety_state.json")));
  ASSERT_TRUE(file.ok());
  EXPECT_TRUE(file->get("estop_active")->as_bool());
  EXPECT_EQ(mode_of(dir.file("safety_state.json")), 0600u);
}

ino_t inode_of(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 ? st.st_ino : 0;
}

// An ESTOP whose latch file is written on this thread once its answer is awaited (the
// persister's retry would otherwise answer a waiter that came late, with its own error): its
// state sequence and the answer (durable, and why not).
struct HereLatch {
  uint64_t seq = 0;
  bool answered = false, durable = false;
  std::string error;
};
HereLatch latch_here(SafetyRig& r) {
  auto e = r.core->estop("http", "button", 0, false);
  std::promise<std::pair<bool, std::string>> answered;
  r.core->when_persisted(e.state_seq, [&](bool d, const std::string& why) {
    answered.set_value({d, why});
  });
  r.core->persist_here_if_idle();
  auto got = answered.get_future();
  HereLatch out;
  out.seq = e.state_seq;
  if (got.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return out;
  out.answered = true;
  std::tie(out.durable, out.error) = got.get();
  return out;
}

// The in-place latch whose fdatasync fails: not durable, answered so with the sync's error,
// and the retry writes the file whole (a new inode: what the failed write left is not trusted).
TEST(SafetyLatchFile, AnInPlaceLatchWhoseSyncFailsIsNotDurableAndIsWrittenWholeOnRetry) {
  TempDir dir;
  const std::string f = dir.file("safety_state.json");
  FaultInjectionEnv env(Env::posix());
  SafetyRig r;
  ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
  const ino_t started = inode_of(f);
  ASSERT_NE(started, 0u);
  env.fail_after(2);  // the page's write goes through, its fdatasync fails
  const HereLatch l = latch_here(r);
  ASSERT_TRUE(l.answered);
  EXPECT_FALSE(l.durable);
  EXPECT_NE(l.error.find("injected fault: sync"), std::string::npos) << l.error;
  EXPECT_FALSE(r.core->status().persisted);
  env.fail_after(0);
  ASSERT_TRUE(r.core->wait_persisted(l.seq, 5000));
  EXPECT_NE(inode_of(f), started);
  EXPECT_TRUE(says_latched(f));
  EXPECT_EQ(test::read_file(f).size(), 4096u);
}

// The latch file replaced (renamed over) between the in-place latch's open and its write: the
// page would go to the old inode, which no name reaches any more. Its sync says so, and the
// latch is written whole at once: durable, and the file under the name says latched.
class ReplacingEnv final : public FaultInjectionEnv {
 public:
  using FaultInjectionEnv::FaultInjectionEnv;
  base::IoResult<std::unique_ptr<base::WritableFile>> open_existing_at(const std::string& path,
                                                                       uint64_t offset) override {
    auto opened = FaultInjectionEnv::open_existing_at(path, offset);
    const std::string copy = path + ".copy";
    { std::ofstream(copy, std::ios::binary) << test::read_file(path); }
    EXPECT_EQ(::rename(copy.c_str(), path.c_str()), 0);
    return opened;
  }
};

TEST(SafetyLatchFile, AnInPlaceLatchOverAFileReplacedMeanwhileIsWrittenWholeAtOnce) {
  TempDir dir;
  const std::string f = dir.file("safety_state.json");
  ReplacingEnv env(Env::posix());
  SafetyRig r;
  ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
  ASSERT_FALSE(says_latched(f));
  const HereLatch l = latch_here(r);
  ASSERT_TRUE(l.answered);
  EXPECT_TRUE(l.durable) << l.error;
  EXPECT_TRUE(says_latched(f));
  EXPECT_EQ(test::read_file(f).size(), 4096u);
}

// A crash in the middle of the in-place latch (its page written, the process dead at its
// fdatasync, so the ESTOP was never acknowledged as durable): the file goes back to the cleared
// page, keeps the latched one, or is torn between them. The node comes up cleared, latched by
// the ESTOP, or — torn — latched by the node (fail safe); never anything else.
TEST(SafetyLatchFile, ACrashDuringAnInPlaceLatchComesUpClearedLatchedOrLatchedByTheNode) {
  for (double keep : {0.0, 0.02, 1.0}) {  // 0.02: the new page's check over the old state
    TempDir dir;
    {
      FaultInjectionEnv env(Env::posix());
      {
        SafetyRig r;
        ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
        env.fail_after(2);
        auto e = r.core->estop("http", "button", 4);
        EXPECT_FALSE(r.core->wait_persisted(e.state_seq, 300));
      }
      ASSERT_TRUE(env.drop_unsynced(keep).ok());
    }
    EXPECT_EQ(test::read_file(dir.file("safety_state.json")).size(), 4096u) << keep;
    SafetyRig r;
    ASSERT_TRUE(r.core->open(dir.path()).ok());
    const auto st = r.core->status();
    if (keep == 0.0) {
      EXPECT_FALSE(r.core->estop_active());
    } else if (keep == 1.0) {
      EXPECT_TRUE(r.core->estop_active());
      EXPECT_EQ(st.estop_source, "http");
    } else {
      EXPECT_TRUE(r.core->estop_active());
      EXPECT_EQ(st.estop_source, "startup");
      EXPECT_NE(st.startup_note.find("check"), std::string::npos) << st.startup_note;
    }
  }
}

// The start's write of the cleared file fails (a state directory that cannot be written): the
// node starts, its status says the latch file is not durable and why, the write is retried, and
// a latch meanwhile is written whole and survives a restart.
TEST(SafetyLatchFile, AStartWhoseClearedFileCannotBeWrittenSaysSoAndRetries) {
  TempDir dir;
  const std::string f = dir.file("safety_state.json");
  {
    FaultInjectionEnv env(Env::posix());
    env.fail_after(1);
    SafetyRig r;
    ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
    EXPECT_FALSE(r.core->estop_active());
    auto st = r.core->status();
    EXPECT_FALSE(st.persisted);
    EXPECT_NE(st.persist_error.find("injected fault"), std::string::npos) << st.persist_error;
    EXPECT_FALSE(present(f));
    env.fail_after(0);
    ASSERT_TRUE(r.core->wait_persisted(r.core->state_seq(), 5000));
    EXPECT_FALSE(says_latched(f));
    EXPECT_EQ(test::read_file(f).size(), 4096u);
    EXPECT_EQ(r.core->status().persist_error, "");
  }
  {
    FaultInjectionEnv env(Env::posix());
    env.fail_after(1);
    SafetyRig r;
    ASSERT_TRUE(r.core->open(dir.path(), &env).ok());  // over the good file: nothing to write
    EXPECT_TRUE(r.core->status().persisted);
  }
  TempDir other;
  {
    FaultInjectionEnv env(Env::posix());
    env.fail_after(1);
    SafetyRig r;
    ASSERT_TRUE(r.core->open(other.path(), &env).ok());
    auto e = r.core->estop("http", "button");
    env.fail_after(0);
    ASSERT_TRUE(r.core->wait_persisted(e.state_seq, 5000));
    EXPECT_TRUE(says_latched(other.file("safety_state.json")));
  }
  SafetyRig r;
  ASSERT_TRUE(r.core->open(other.path()).ok());
  EXPECT_TRUE(r.core->estop_active());
}

// Clearing the latch when the disk fails: the robot may move again in this process, but the
// file still says latched, so a restart comes up latched (fail safe).
TEST(SafetyLatchFile, AClearThatCannotBeWrittenComesBackLatched) {
  TempDir dir;
  FaultInjectionEnv env(Env::posix());
  {
    SafetyRig r;
    ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
    auto e = r.core->estop("cli", "rcan estop");
    ASSERT_TRUE(r.core->wait_persisted(e.state_seq, 5000));
    env.fail_after(1);
    ASSERT_TRUE(r.core->resume(4, "owner").ok());
    EXPECT_FALSE(r.core->estop_active());
    EXPECT_TRUE(r.core->dispatch(node::ActuatorCommand::make_drive(0.1, 0, 100)).ok());
    EXPECT_FALSE(r.core->wait_persisted(r.core->state_seq(), 300));
    EXPECT_NE(r.core->status().persist_error.find("injected fault"), std::string::npos);
  }  // the destructor's last attempt fails too
  SafetyRig r;
  ASSERT_TRUE(r.core->open(dir.path()).ok());
  EXPECT_TRUE(r.core->estop_active());
  EXPECT_EQ(r.core->status().estop_source, "cli");
  EXPECT_EQ(r.core->status().startup_note, "ESTOP was latched before restart; still latched");
}

// when_persisted() answers without blocking: not while the latch write is held up by the disk,
// durable as soon as it is done.
TEST(SafetyLatchFile, WhenPersistedAnswersOnlyOnceTheFileIsDurable) {
  TempDir dir;
  FaultInjectionEnv env(Env::posix());
  SafetyRig r;
  ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
  env.hold(true);  // a slow disk
  auto e = r.core->estop("http", "button");
  std::promise<std::pair<bool, std::string>> answered;
  r.core->when_persisted(e.state_seq, [&](bool durable, const std::string& error) {
    answered.set_value({durable, error});
  });
  auto got = answered.get_future();
  EXPECT_EQ(got.wait_for(std::chrono::milliseconds(300)), std::future_status::timeout);
  EXPECT_FALSE(says_latched(dir.file("safety_state.json")));  // held before its write
  env.hold(false);
  ASSERT_EQ(got.wait_for(std::chrono::seconds(5)), std::future_status::ready);
  auto [durable, error] = got.get();
  EXPECT_TRUE(durable) << error;
  EXPECT_TRUE(says_latched(dir.file("safety_state.json")));
  // Already durable: answered at once, on the caller's thread.
  bool again = false;
  r.core->when_persisted(e.state_seq, [&](bool d, const std::string&) { again = d; });
  EXPECT_TRUE(again);
}

// An ESTOP from a thread that may block for the disk (one MQTT connection's) writes the latch
// file itself: the answer is decided before estop() returns, on that thread. While another
// write is under way (the persister's, on a hung disk) it does not wait: the persister writes
// the new latch after its own and answers then.
TEST(SafetyLatchFile, AnEstopThatMayWaitWritesItsLatchFileItselfUnlessAWriteIsUnderWay) {
  {
    TempDir dir;
    SafetyRig r;
    ASSERT_TRUE(r.core->open(dir.path()).ok());
    node::SafetyActuation act(*r.core, "r");
    std::atomic<bool> answered{false}, durable{false};
    std::thread::id answered_on;
    (void)act.estop(
        "mqtt", "fleet", Role::kOwner,
        [&](bool d, const std::string&) {
          durable = d;
          answered_on = std::this_thread::get_id();
          answered = true;
        },
        true);
    EXPECT_TRUE(answered.load());
    EXPECT_TRUE(durable.load());
    EXPECT_EQ(answered_on, std::this_thread::get_id());
    auto file = json::parse(test::read_file(dir.file("safety_state.json")));
    ASSERT_TRUE(file.ok());
    EXPECT_TRUE(file->get("estop_active")->as_bool());
  }
  TempDir dir;
  FaultInjectionEnv env(Env::posix());
  SafetyRig r;
  ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
  node::SafetyActuation act(*r.core, "r");
  env.hold(true);  // the persister's write of the first latch hangs
  (void)act.estop("http", "first", Role::kLeasee, {}, false);
  for (int i = 0; i < 500 && env.held() == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  ASSERT_GT(env.held(), 0u);
  std::promise<bool> second;
  const auto t0 = std::chrono::steady_clock::now();
  (void)act.estop(
      "mqtt", "second", Role::kOwner, [&](bool d, const std::string&) { second.set_value(d); },
      true);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(1));  // did not wait
  auto got = second.get_future();
  EXPECT_EQ(got.wait_for(std::chrono::milliseconds(100)), std::future_status::timeout);
  env.hold(false);
  ASSERT_EQ(got.wait_for(std::chrono::seconds(5)), std::future_status::ready);
  EXPECT_TRUE(got.get());
  auto file = json::parse(test::read_file(dir.file("safety_state.json")));
  ASSERT_TRUE(file.ok());
  EXPECT_EQ(file->get("by_level")->as_int(), role_level(Role::kOwner));
}

// A write that fails is answered at once with its error; one that hangs is answered by the
// control loop once latch_ack_timeout_ms has passed. The write goes on in both cases.
TEST(SafetyLatchFile, WhenPersistedSaysSoWhenTheWriteFailsOrHangs) {
  {
    TempDir dir;
    FaultInjectionEnv env(Env::posix());
    SafetyRig r;
    ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
    env.fail_after(1);
    auto e = r.core->estop("http", "button");
    auto [durable, error] = latch_answer(*r.core, e.state_seq);
    EXPECT_FALSE(durable);
    EXPECT_NE(error.find("injected fault"), std::string::npos) << error;
    env.fail_after(0);
    EXPECT_TRUE(r.core->wait_persisted(e.state_seq, 5000));  // still retried
  }
  {
    TempDir dir;
    FaultInjectionEnv env(Env::posix());
    SafetyRig r;
    ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
    env.hold(true);
    auto e = r.core->estop("http", "button");
    int calls = 0;
    bool durable = true;
    std::string error;
    r.core->when_persisted(e.state_seq, [&](bool d, const std::string& why) {
      ++calls;
      durable = d;
      error = why;
    });
    r.core->tick();
    EXPECT_EQ(calls, 0);
    r.clock.advance(node::SafetyConfig{}.latch_ack_timeout_ms);
    r.core->tick();
    EXPECT_EQ(calls, 1);
    EXPECT_FALSE(durable);
    EXPECT_NE(error.find("not written within 2000 ms"), std::string::npos) << error;
    env.hold(false);
    EXPECT_TRUE(r.core->wait_persisted(e.state_seq, 5000));
    EXPECT_EQ(calls, 1);  // answered once
  }
  {  // stop() answers whoever still waits (what answers them is stopped before the core)
    TempDir dir;
    FaultInjectionEnv env(Env::posix());
    SafetyRig r;
    ASSERT_TRUE(r.core->open(dir.path(), &env).ok());
    env.hold(true);
    auto e = r.core->estop("http", "button");
    int calls = 0;
    std::string error;
    r.core->when_persisted(e.state_seq, [&](bool d, const std::string& why) {
      calls += d ? 100 : 1;
      error = why;
    });
    r.core->stop();
    EXPECT_EQ(calls, 1);
    EXPECT_NE(error.find("stopped"), std::string::npos) << error;
    env.hold(false);
  }
}

// Without a state directory the latch lives in memory only, and when_persisted() says so.
TEST(SafetyLatchFile, WhenPersistedWithoutAStateDirectorySaysMemoryOnly) {
  SafetyRig r;
  auto e = r.core->estop("http", "button");
  bool durable = true;
  std::string error;
  r.core->when_persisted(e.state_seq, [&](bool d, const std::string& why) {
    durable = d;
    error = why;
  });
  EXPECT_FALSE(durable);
  EXPECT_NE(error.find("memory only"), std::string::npos) << error;
}

// ---- the ESTOP answer waits for the latch file --------------------------------------------------

// The node's pipeline over the real safety core, whose latch file is written through a
// FaultInjectionEnv.
class EstopAnswer : public node::test_node::InProcessNode {
 protected:
  EstopAnswer() : env_(Env::posix()) {
    node::SimRobotConfig sim;
    sim.battery = false;
    core_ = std::make_unique<node::SafetyCore>(std::make_unique<node::SimRobot>(sim),
                                               node::SafetyConfig{}, clock_);
    EXPECT_TRUE(core_->open(state_.path(), &env_).ok());
    actuation_ = std::make_unique<node::SafetyActuation>(*core_, "estop-answer");
  }
  void TearDown() override {
    env_.hold(false);
    InProcessNode::TearDown();
  }
  node::Actuation& actuation() override { return *actuation_; }

  // Sends an ESTOP (HTTP, any role may) and returns the answer's future.
  std::future<node::Outcome> estop() {
    node::Ingress in;
    in.body = json::Object{{"version", "1.0.0"},
                           {"message_id", new_uuid_v4()},
                           {"type", "SAFETY"},
                           {"priority", "SAFETY"},
                           {"timestamp_ms", clock_.wall_ms()},
                           {"payload", json::Object{{"safety_event", "ESTOP"}, {"reason", "t"}}}};
    in.bearer = token("guest", "gus", {"status"});
    in.transport = "http";
    in.route = "/api/stop";
    auto answer = std::make_shared<std::promise<node::Outcome>>();
    auto got = answer->get_future();
    pipeline_->submit(std::move(in),
                      [answer](node::Outcome o) { answer->set_value(std::move(o)); });
    return got;
  }

  std::string latch_file() const { return state_.path() + "/safety_state.json"; }

  TempDir state_;
  FaultInjectionEnv env_;
  std::unique_ptr<node::SafetyCore> core_;
  std::unique_ptr<node::SafetyActuation> actuation_;
};

TEST_F(EstopAnswer, ComesOnlyOnceTheLatchFileIsDurable) {
  env_.hold(true);  // the latch write is held up by a slow disk
  auto got = estop();
  EXPECT_TRUE(core_->estop_active());  // the robot stopped at once
  EXPECT_EQ(got.wait_for(std::chrono::milliseconds(500)), std::future_status::timeout)
      << "the ESTOP was acknowledged before its latch was written";
  EXPECT_FALSE(says_latched(latch_file()));
  env_.hold(false);
  ASSERT_EQ(got.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  node::Outcome o = got.get();
  EXPECT_TRUE(says_latched(latch_file()));
  ASSERT_EQ(o.status, 200) << json::dump(o.body);
  const json::Value& p = *o.body.get("payload");
  EXPECT_EQ(json::string_field(p, "result"), "estop_latched");
  EXPECT_EQ(json::string_field(p, "latch"), "durable") << json::dump(o.body);
  EXPECT_EQ(p.get("latch_error"), nullptr);
  auto file = json::parse(test::read_file(latch_file()));
  ASSERT_TRUE(file.ok());
  EXPECT_TRUE(file->get("estop_active")->as_bool());
}

TEST_F(EstopAnswer, SaysSoWhenTheLatchCannotBeWritten) {
  env_.fail_after(1);
  auto got = estop();
  ASSERT_EQ(got.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  node::Outcome o = got.get();
  ASSERT_EQ(o.status, 200) << json::dump(o.body);  // the stop happened and holds
  EXPECT_TRUE(core_->estop_active());
  const json::Value& p = *o.body.get("payload");
  EXPECT_EQ(json::string_field(p, "latch"), "not_durable") << json::dump(o.body);
  EXPECT_NE(json::string_field(p, "latch_error").find("injected fault"), std::string::npos)
      << json::dump(o.body);
  EXPECT_EQ(audited("ESTOP", 1).size(), 1u);
}

// ---- Stops recorded during an audit outage (docs/SECURITY.md R14) -----------------------------

audit::AuditEntry stop_entry(int i) {
  audit::AuditEntry e;
  e.principal = "owner-1";
  e.ruri = "rcan://local.rcan/acme/bot/00000001";
  e.message_id = "stop-" + std::to_string(i);
  e.event = "ESTOP";
  e.outcome = "ok";
  e.sub = "owner-1";
  e.reason = "button";
  e.detail.set("transport", "http");
  return e;
}

TEST(StopBacklog, ASpillFileKeepsStopsAcrossARestartPrivateAndInOrder) {
  TempDir dir;
  const std::string f = dir.file("stops-unrecorded.jsonl");
  {
    node::StopBacklog b(f);
    for (int i = 0; i < 3; ++i) b.keep(stop_entry(i));
    EXPECT_EQ(b.pending(), 3u);
  }
  EXPECT_EQ(mode_of(f), 0600u);
  node::StopBacklog again(f);  // a restart: the file's records are still owed to the log
  EXPECT_EQ(again.pending(), 3u);
  auto got = again.take();
  ASSERT_EQ(got.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(got[static_cast<size_t>(i)].message_id, "stop-" + std::to_string(i));
    EXPECT_EQ(json::canonical(json::Value(audit::to_object(got[static_cast<size_t>(i)]))),
              json::canonical(json::Value(audit::to_object(stop_entry(i)))));
  }
  EXPECT_FALSE(present(f));
  EXPECT_TRUE(again.empty());
  EXPECT_EQ(again.lost(), 0u);
}

TEST(StopBacklog, WhenTheSpillFileFailsMemoryKeepsThemAndWhatCannotBeKeptIsCounted) {
  TempDir dir;
  FaultInjectionEnv env(Env::posix());
  env.fail_after(1);  // every write to the spill file fails
  node::StopBacklog b(dir.file("stops-unrecorded.jsonl"), &env,
                      {.spill_records = 10, .memory_records = 5});
  for (int i = 0; i < 8; ++i) b.keep(stop_entry(i));
  EXPECT_EQ(b.pending(), 5u);
  EXPECT_EQ(b.lost(), 3u);  // counted, logged and in the status — never silent
  EXPECT_EQ(b.to_json().get("lost")->as_int(), 3);
  auto got = b.take();
  ASSERT_EQ(got.size(), 5u);
  EXPECT_EQ(got[0].message_id, "stop-0");
  // Both tiers full: spill 10, memory 5, the rest counted.
  env.fail_after(0);
  node::StopBacklog c(dir.file("other.jsonl"), &env, {.spill_records = 10, .memory_records = 5});
  for (int i = 0; i < 20; ++i) c.keep(stop_entry(i));
  EXPECT_EQ(c.pending(), 15u);
  EXPECT_EQ(c.lost(), 5u);
  EXPECT_EQ(c.take().size(), 15u);
}

TEST(StopBacklog, ATornLastLineIsCountedNotTakenAsARecord) {
  TempDir dir;
  const std::string f = dir.file("stops-unrecorded.jsonl");
  {
    node::StopBacklog b(f);
    b.keep(stop_entry(0));
    b.keep(stop_entry(1));
  }
  { std::ofstream(f, std::ios::app) << R"({"principal":"owner-1","event":"ES)"; }
  { std::ofstream(f, std::ios::app) << "\n"; }  // and a line that is no record at all
  node::StopBacklog b(f);
  auto got = b.take();
  EXPECT_EQ(got.size(), 2u);
  EXPECT_EQ(b.lost(), 1u);
}

// More stops than the old in-memory list held (1,000) during one outage: every one of them is
// recorded once the log writes again.
TEST(StopBacklog, EveryStopDuringAnAuditOutageIsRecordedAfterIt) {
  TempDir dir;
  FaultInjectionEnv env(Env::posix());
  audit::AuditOptions ao;
  ao.secret = "stop-backlog-test-chain-secret-0123456789";
  ao.robot_ruri = "rcan://local.rcan/acme/bot/00000001";
  ao.preallocate = false;
  ao.recovery_interval_ms = 20;
  ao.env = env.audit();
  auto log = audit::AuditLog::open(dir.file("audit"), ao);
  ASSERT_TRUE(log.ok()) << log.error().message;
  node::test_node::FakeActuation act;
  node::NodeSettings ns;
  ns.ruri = ao.robot_ruri;
  ns.state_dir = dir.file("state");
  ASSERT_EQ(::mkdir(ns.state_dir.c_str(), 0700), 0);
  node::NodeServices svc(ns, Clock::system(), node::AuthOptions{}, act, **log);
  env.fail_after(1);
  const int n = 1200;
  for (int i = 0; i < n; ++i) svc.trail.write(stop_entry(i));
  auto settle = [&] {
    for (int k = 0; k < 1000 && svc.trail.inflight.load() > 0; ++k)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  };
  settle();
  EXPECT_FALSE((*log)->available());
  EXPECT_EQ(svc.trail.stop_backlog.pending(), static_cast<uint64_t>(n));
  env.fail_after(0);  // the disk is back
  for (int k = 0; k < 500 && !(*log)->available(); ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_TRUE((*log)->available());
  audit::AuditEntry next = stop_entry(n);
  next.event = "COMMAND";
  svc.trail.write(next);  // the first record after the outage brings the backlog with it
  settle();
  int late = 0;
  ASSERT_TRUE((*log)
                  ->export_range(0, INT64_MAX,
                                 [&](std::string_view line) {
                                   auto v = json::parse(line);
                                   const json::Value* d = v.ok() ? v->get("detail") : nullptr;
                                   const json::Value* f =
                                       d ? d->get("recorded_after_audit_outage") : nullptr;
                                   if (f && f->is_bool() && f->as_bool()) ++late;
                                   return true;
                                 })
                  .ok());
  EXPECT_EQ(late, n);
  EXPECT_EQ(svc.trail.stop_backlog.lost(), 0u);
  EXPECT_TRUE(svc.trail.stop_backlog.empty());
}

}  // namespace
}  // namespace rcan

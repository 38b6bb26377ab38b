// SafetyCore: the one owner of the actuators. Nothing reaches a Driver except through it
// (docs/ARCHITECTURE.md, seed §4.3). Example:
//
//   SafetyCore core(std::move(driver), config, Clock::system());
//   core.open(state_dir);                  // comes up latched if it was latched
//   core.start();                          // the control loop
//   auto r = core.dispatch(cmd, {.session_id = id});
//   core.estop("operator", "button");     // from any thread, at any time
//
// Guarantees:
//   * ESTOP is a latch. estop() stops the driver before it returns and before anything else;
//     from then on no dispatch() reaches the driver until resume(). The latch survives a
//     restart (the state file in the state directory; written durably, retried until it is).
//   * resume() clears the latch for LEASEE and above only (INSUFFICIENT_PRIVILEGES below); it
//     moves nothing: the robot stays stopped until the next command.
//   * dispatch() refuses while latched (COMMAND_REJECTED / estop_active, HTTP 423), past the
//     command's deadline (MESSAGE_STALE), and outside the limits (speeds, joint ranges and
//     speeds, drive duration, workspace), which it clamps or rejects by policy
//     (COMMAND_REJECTED / limit_exceeded). Limits are min(config, the driver's envelope),
//     fixed at construction; nothing raises them.
//   * Every drive ends: its duration (0 → max_drive_duration_ms) is enforced by the driver and
//     again by the control loop on the monotonic clock.
//   * Deadman: a control session armed with a heartbeat timeout (arm_deadman) that goes
//     silent while it holds control or owns the motion in progress safe-stops the robot and
//     emits NETWORK_LOSS_SAFE_STOP {session_id, elapsed_ms}.
//   * Safe-stop (deadman expiry, workspace guard trip, drive-TTL overrun) is not a latch: the
//     next accepted motion command clears it. A command of a control session whose heartbeat
//     was lost is refused (SAFE_STOP / heartbeat_lost) until that session feeds its deadman
//     again; a command of no (or an unarmed) session is bounded by its own duration.
//   * Re-arm after ESTOP: every new latch bumps the ESTOP epoch. A control session records the
//     epoch it was armed at (arm_deadman() of a new session, or rearm()); while its epoch is
//     older than the current one its motion commands are refused (COMMAND_REJECTED /
//     rearm_required, HTTP 423) even after RESUME, until rearm(): a hold or a stream that
//     started before the ESTOP does not drive again by itself. Stops are never refused.
//
// Time: deadlines, TTLs and heartbeats use Clock::mono_ms(); `since`/`ts` fields wall_ms.
// Threads: every public method is thread-safe. start() runs the control loop on the core's own
// thread; tests may call tick() by hand with a ManualClock instead. The event callback runs on
// the thread that calls tick() and must not block.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <unordered_map>
#include <vector>

#include "base/clock.h"
#include "base/thread_annotations.h"
#include "config/safety_types.h"
#include "node/safety/driver.h"
#include "node/safety/latch_file.h"
#include "rcan/base/env.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::node {

// The limit policy and the workspace rectangle are the config's own types (safety_types.h).
using config::limit_policy_name;
using config::LimitPolicy;
using config::Workspace;

struct SafetyLimits {
  double max_linear_mps = 1.0;
  double max_angular_radps = 2.0;
  double max_joint_speed_radps = 1.0;
  JointArray joint_min_rad{-3.0, -1.8, -2.4, -3.0, -1.8, -3.0};
  JointArray joint_max_rad{3.0, 1.8, 2.4, 3.0, 1.8, 3.0};
  int64_t max_drive_duration_ms = 5000;
  Workspace workspace;
  json::Object to_json() const;
};

struct SafetyConfig {
  // The `safety` block as the file gives it (config/safety_types.h). The core reads from it
  // estop_on_startup (always come up latched), estop_on_driver_fault (a driver fault latches
  // ESTOP, source "driver", besides the safe stop, so that motion needs an explicit RESUME
  // once the driver is back), heartbeat_timeout_ms (arm_deadman(id, 0)) and speed_policy
  // (the policy of a dispatch that names none). Its speed caps and joint ranges reach the core
  // through `limits`, which rcand computes from them and the driver's envelope.
  config::SafetyConfig file;
  SafetyLimits limits;
  int64_t tick_period_ms = 20;  // 50 Hz control loop
  // While the driver is at rest (Driver::at_rest()) and no drive TTL is running, the loop
  // sleeps up to this long instead — woken early by a command, a session or watchdog feed,
  // and always on time for the next heartbeat or watchdog deadline. An idle robot then costs
  // one wake-up a second instead of fifty. 0 or ≤ tick_period_ms: always the full rate.
  int64_t idle_tick_ms = 1000;
  int64_t watchdog_timeout_ms = 0;  // brain watchdog; 0 = disabled
  // A drive still commanded this long after its deadline is stopped by tick() (safe-stop).
  int64_t drive_ttl_grace_ms = 100;
  // estop() waits at most this long for a dispatch already inside Driver::apply() (see
  // estop()). The stop itself never waits.
  int64_t estop_fence_timeout_ms = 100;
  // when_persisted() answers "not durable" if the latch write has not finished this long after
  // it was asked (a hung disk); the write itself goes on and is retried.
  int64_t latch_ack_timeout_ms = 2000;
};

struct DispatchOptions {
  int64_t deadline_mono_ms = 0;  // 0 = no deadline; else refused when now > deadline
  std::string session_id;        // empty = session-less
  // A session-less command from a stream: the ESTOP epoch the stream is armed at; refused
  // (rearm_required) while it is older than the current epoch.
  std::optional<uint64_t> stream_epoch;
  std::optional<LimitPolicy> policy;  // default: SafetyConfig::file.speed_policy
};

struct DispatchOutcome {
  bool clamped = false;
  std::vector<std::string> clamps;  // one line per clamp, e.g. "linear_mps 2 -> 1 (max_linear_mps)"
  ActuatorCommand applied;          // what reached the driver
  json::Object to_json() const;
};

struct SafetyEvent {
  std::string type;        // "NETWORK_LOSS_SAFE_STOP", "WATCHDOG_TIMEOUT", "WORKSPACE_SAFE_STOP",
                           // "DRIVE_TTL_SAFE_STOP", "DRIVER_FAULT", "DRIVER_RECOVERED"
  std::string session_id;  // NETWORK_LOSS_SAFE_STOP
  int64_t elapsed_ms = 0;  // since the last heartbeat / watchdog feed
  int64_t timeout_ms = 0;
  std::string detail;
  int64_t wall_ms = 0;
  int64_t mono_ms = 0;
  json::Object to_json() const;
};

struct LatencyStats {
  uint64_t count = 0;
  int64_t last_ns = 0;
  int64_t p50_ns = 0;  // over the last (up to) 4096 samples
  int64_t p99_ns = 0;
  int64_t max_ns = 0;  // since start
  json::Object to_json() const;
};

struct SafetyStatus {
  bool estop_active = false;
  std::string estop_source;
  std::string estop_reason;
  int64_t estop_since_wall_ms = 0;
  uint64_t estop_epoch = 0;  // SafetyCore::estop_epoch()
  bool safe_stop_active = false;
  std::string safe_stop_reason;  // "NETWORK_LOSS_SAFE_STOP", "workspace", "drive_ttl",
                                 // "driver_fault"
  std::string driver_fault;      // non-empty while the driver reports a fault
  std::string safe_stop_session;
  int64_t safe_stop_since_wall_ms = 0;
  SafetyLimits limits;
  LimitPolicy policy = LimitPolicy::kClamp;
  RobotState robot;  // with ts / loop_latency_ms / loop_count / paused filled
  DriverInfo driver;
  LatencyStats estop_latency;  // estop() call → Driver::stop() returned
  uint64_t estop_fence_timeouts = 0;
  bool persistence_enabled = false;
  bool persisted = true;      // the latest latch state is durable
  std::string persist_error;  // last persistence error, empty when none
  std::string startup_note;   // e.g. "state file corrupt: …; came up latched (fail safe)"
  size_t sessions = 0;
  bool running = false;  // tick thread running
  json::Object to_json() const;
};

struct EstopResult {
  bool newly_latched = false;  // false when it was already latched (first source/reason kept)
  // True when no dispatch was left inside Driver::apply() at return (the normal case). False
  // only if the fence timed out: that straggler stops the driver itself right after applying.
  bool fenced = true;
  int64_t stop_latency_ns = 0;    // call → Driver::stop() returned
  int64_t return_latency_ns = 0;  // call → estop() returning (fence included, not persistence)
  uint64_t state_seq = 0;         // pass to wait_persisted() or when_persisted()
};

// when_persisted()'s answer: durable, or why not (the write's error, the time limit, no state
// directory). Called exactly once.
using LatchFn = std::function<void(bool durable, const std::string& error)>;

class SafetyCore {
 public:
  using EventFn = std::function<void(const SafetyEvent&)>;

  // `driver` must not be null. `clock` must outlive the core.
  SafetyCore(std::unique_ptr<Driver> driver, SafetyConfig cfg, Clock& clock = Clock::system());
  ~SafetyCore();  // stop(), then flush pending persistence
  SafetyCore(const SafetyCore&) = delete;
  SafetyCore& operator=(const SafetyCore&) = delete;

  // Loads the persisted latch from `state_dir` (created 0700 if missing) and starts the
  // persister. Missing file → not latched (unless estop_on_startup); corrupt/unreadable file →
  // latched, source "startup", startup_note says why (the bad file is kept as *.corrupt).
  // A missing file, or a cleared one of an older form, is written cleared in the fixed form
  // before open() returns, so that the first latch rewrites it in place (a failure is retried
  // by the persister and shown in status()). Call once, before start(). Without open() the latch
  // lives in memory only. The latch file is read and written through `env` (nullptr →
  // base::Env::posix(); tests inject faults with it).
  Status open(const std::string& state_dir, base::Env* env = nullptr);

  void set_event_callback(EventFn fn);

  // The control loop thread (tick every tick_period_ms). stop() also stops the driver.
  void start();
  void stop();
  // One control-loop iteration: steps the driver by the monotonic time since the last tick,
  // then enforces drive TTLs, the workspace guard, heartbeats and the watchdog.
  void tick();
  // How long the loop thread may sleep after a tick (ms; 0 = keep the full rate): the driver
  // at rest, no drive TTL running, and up to idle_tick_ms or the next heartbeat / watchdog
  // deadline, whichever comes first.
  int64_t rest_for_ms() const;

  // SAFETY lane. O(1) and lock-free up to the driver stop: one atomic store, then
  // Driver::stop(). Then a lock-free fence (waits only for a dispatch already inside
  // Driver::apply(), bounded by estop_fence_timeout_ms), a second stop(), and the latch
  // metadata; persistence happens on the persister thread (wait_persisted() to wait for it).
  // After it returns (fenced), no dispatch reaches the driver until resume().
  // `by_level`: the role level of the principal asking (0: the node itself — watchdog,
  // start-up). A latch remembers the highest level that latched it (in its state file too).
  // `wake_persister` false: the caller writes the latch file itself next (persist_here_if_idle).
  EstopResult estop(std::string_view source, std::string_view reason, int by_level = 0,
                    bool wake_persister = true);
  // Writes the latch file on the calling thread when it is behind and no write is under way
  // (otherwise the persister thread does, as after estop()), and answers when_persisted()
  // waiters that it made durable, on this thread. It may block for the disk: for a thread that
  // serves one channel, whose ESTOP has already stopped the robot (audit::Commit::kHereIfIdle
  // is the audit log's counterpart). A failed write is retried by the persister.
  void persist_here_if_idle() EXCLUDES(meta_mu_);
  // Clears the latch for a principal of LEASEE or above whose level is at least the latch's
  // (OWNER and above clear any latch). Errors: INSUFFICIENT_PRIVILEGES, estop_clear_forbidden.
  Status resume(int principal_role_level, std::string_view source);
  bool estop_active() const { return latched_.load(std::memory_order_acquire); }
  // Control-loop turns so far (at least one a second while the loop runs; the systemd
  // watchdog feeds only while it advances).
  uint64_t loop_count() const { return loop_count_.load(std::memory_order_relaxed); }
  bool safe_stop_active() const { return safe_stop_.load(std::memory_order_acquire); }
  // Waits until the latch state `seq` (or later) is durable; false on timeout (a failing
  // write is retried every 200 ms; status().persist_error says why) or without open().
  bool wait_persisted(uint64_t seq, int64_t timeout_ms);
  // The same without blocking: `fn` is called once — durable, as soon as the latch state `seq`
  // (or later) is; not durable with the reason as soon as a write of it fails (it is still
  // retried), when it is not done within SafetyConfig::latch_ack_timeout_ms (checked by the
  // control loop: start(), or tick() by hand), at stop() or destruction, or at once without
  // open(). It
  // runs on the persister or control-loop thread, or on the caller's when already decided;
  // it must not block.
  void when_persisted(uint64_t seq, LatchFn fn);
  // The sequence number of the current latch state (bumps on every latch/clear).
  uint64_t state_seq() const;

  Result<DispatchOutcome> dispatch(const ActuatorCommand& cmd, const DispatchOptions& opts = {});
  // Dry run: every refusal dispatch() would give right now (latch, deadline, lost heartbeat,
  // limits) and the command it would apply, without touching the driver. A later dispatch()
  // re-checks everything (the state may have changed in between).
  Result<DispatchOutcome> check(const ActuatorCommand& cmd, const DispatchOptions& opts = {}) const;

  // Deadman. timeout_ms <= 0 → SafetyConfig::file.heartbeat_timeout_ms. Registering an existing
  // session refreshes it.
  void arm_deadman(const std::string& session_id, int64_t timeout_ms = 0);
  // Unknown session → NOT_FOUND. Revives a session whose heartbeat was lost.
  Status feed_deadman(const std::string& session_id);
  // Removes the session; if it owned motion in progress or held control, the driver is
  // stopped (an orderly end, no event).
  void disarm_deadman(const std::string& session_id);
  // The node marks the session that holds control (claim/release).
  void set_deadman_holds_control(const std::string& session_id, bool holds_control);
  // Re-arms a control session after an ESTOP: its motion commands are accepted again (once the
  // latch is cleared). Unknown session → NOT_FOUND. Re-arming while latched arms it at the
  // current epoch: a later RESUME then lets it drive.
  Status rearm(const std::string& session_id);
  // Bumps on every new ESTOP latch (and once at open() when the node comes up latched).
  uint64_t estop_epoch() const { return estop_epoch_.load(std::memory_order_acquire); }

  // Brain watchdog (optional; SafetyConfig::watchdog_timeout_ms > 0). Armed by the first feed;
  // expiry latches ESTOP (source "watchdog") and emits WATCHDOG_TIMEOUT.
  void feed_watchdog();

  SafetyStatus status() const;
  RobotState robot_state() const;  // telemetry snapshot (ts/loop fields filled)
  const SafetyLimits& limits() const { return limits_; }
  DriverInfo driver_info() const { return driver_info_; }
  LatencyStats estop_latency() const;

 private:
  struct Deadman {  // one per control session with a heartbeat timeout
    int64_t timeout_ms = 0;
    int64_t last_heartbeat_mono = 0;
    bool holds_control = false;
    bool lost = false;
    uint64_t armed_epoch = 0;  // the ESTOP epoch it was armed at (a new session, or rearm())
  };

  Result<DispatchOutcome> precheck(const ActuatorCommand& cmd, const DispatchOptions& opts,
                                   int64_t now) const;
  Result<ActuatorCommand> limit_command(const ActuatorCommand& cmd, LimitPolicy policy,
                                        const RobotState& now, DispatchOutcome& out) const;
  void enter_safe_stop(std::string reason, std::string session);
  void record_latency(int64_t ns);
  void step_driver_to_locked(int64_t now) REQUIRES(apply_mu_);
  // The steps of tick() (safety.cpp).
  struct HealthChange {
    bool started = false;  // a fault began (detail says which)
    bool cleared = false;
    std::string detail;
  };
  SafetyEvent event_at(int64_t now, std::string type, int64_t elapsed, int64_t timeout,
                       std::string detail) const;
  void guard_motion_locked(int64_t now, const RobotState& st, std::vector<SafetyEvent>& events)
      REQUIRES(apply_mu_);
  HealthChange check_health_locked() REQUIRES(apply_mu_);
  void on_health_change(int64_t now, const HealthChange& change, std::vector<SafetyEvent>& events);
  int64_t check_deadmen(int64_t now, const std::string& owner, bool moving,
                        std::vector<SafetyEvent>& events) EXCLUDES(deadman_mu_);
  // Wakes a resting loop (new motion, session or watchdog deadline). Cheap when not resting.
  void wake_ticker();
  void persist_loop();
  struct PersistWaiter {  // a when_persisted() call not answered yet
    uint64_t seq = 0;
    int64_t deadline_mono = 0;
    LatchFn fn;
  };
  // Takes the waiters that `pred` selects out of persist_waiters_ (to be called unlocked).
  template <typename Pred>
  std::vector<PersistWaiter> take_waiters_locked(Pred pred) REQUIRES(meta_mu_);
  void expire_persist_waiters(int64_t now);
  void request_persist(uint64_t seq);
  void emit(const SafetyEvent& ev);
  RobotState decorate(RobotState st) const;

  const std::unique_ptr<Driver> driver_;
  const SafetyConfig cfg_;
  Clock& clock_;
  const DriverInfo driver_info_;
  const SafetyLimits limits_;  // effective: min(config, hardware)

  // The SAFETY lane flag: read by dispatch() (before and under apply_mu_) and tick().
  std::atomic<bool> latched_{false};
  std::atomic<bool> safe_stop_{false};
  std::atomic<bool> driver_faulted_{false};  // set/cleared by tick() from Driver::health()
  std::atomic<uint64_t> estop_epoch_{0};     // bumped before every latch store
  // Odd while a dispatch() may be inside Driver::apply() (bumped under apply_mu_).
  std::atomic<uint64_t> apply_seq_{0};
  std::atomic<uint64_t> fence_timeouts_{0};

  // Serialises Driver::apply/step/state. Held only around those calls.
  mutable Mutex apply_mu_;
  std::string motion_owner_ GUARDED_BY(apply_mu_);         // the session of the last motion command
  int64_t drive_deadline_mono_ GUARDED_BY(apply_mu_) = 0;  // 0 = no active drive
  int64_t last_tick_mono_ GUARDED_BY(apply_mu_) = 0;

  // Latch metadata, safe-stop metadata, persistence bookkeeping.
  mutable Mutex meta_mu_;
  LatchState latch_ GUARDED_BY(meta_mu_);
  uint64_t latch_seq_ GUARDED_BY(meta_mu_) = 0;  // bumps on every latch change
  uint64_t persisted_seq_ GUARDED_BY(meta_mu_) = 0;
  std::string persist_error_ GUARDED_BY(meta_mu_);
  std::string startup_note_ GUARDED_BY(meta_mu_);
  std::string safe_stop_reason_ GUARDED_BY(meta_mu_);
  std::string safe_stop_session_ GUARDED_BY(meta_mu_);
  int64_t safe_stop_since_wall_ms_ GUARDED_BY(meta_mu_) = 0;
  std::string driver_fault_ GUARDED_BY(meta_mu_);
  // A latch file write is under way (by open(), the persister or a persist_here_if_idle() caller);
  // whoever set it owns latch_file_ until it clears it.
  bool persist_busy_ GUARDED_BY(meta_mu_) = false;
  // The latch file (set once by open()). Used by open(), then only by the thread that holds
  // persist_busy_ (the persister or a persist_here_if_idle() caller), whose hand-over under
  // meta_mu_ orders the accesses.
  std::optional<LatchFile> latch_file_;
  // Writes the latest latch state (persist_busy_ set by the caller, meta_mu_ held on entry and
  // on return, released meanwhile) and answers the waiters it decided.
  Status write_latest_locked() REQUIRES(meta_mu_);
  bool persist_enabled_ = false;  // set once by open()
  bool persist_quit_ GUARDED_BY(meta_mu_) = false;
  CondVar persist_cv_;  // the persister waits on meta_mu_
  CondVar durable_cv_;  // wait_persisted() waits on meta_mu_
  std::vector<PersistWaiter> persist_waiters_ GUARDED_BY(meta_mu_);
  std::thread persister_;

  mutable Mutex deadman_mu_;
  std::unordered_map<std::string, Deadman> deadmen_ GUARDED_BY(deadman_mu_);  // by session id
  int64_t watchdog_last_feed_mono_ GUARDED_BY(deadman_mu_) = 0;               // 0 = not armed

  mutable Mutex event_mu_;
  EventFn on_event_ GUARDED_BY(event_mu_);

  mutable Mutex stats_mu_;
  std::vector<int64_t> latency_ring_ GUARDED_BY(stats_mu_);
  size_t latency_next_ GUARDED_BY(stats_mu_) = 0;
  uint64_t latency_count_ GUARDED_BY(stats_mu_) = 0;
  int64_t latency_last_ns_ GUARDED_BY(stats_mu_) = 0;
  int64_t latency_max_ns_ GUARDED_BY(stats_mu_) = 0;

  std::atomic<uint64_t> loop_count_{0};
  std::atomic<int64_t> loop_latency_us_{0};

  Mutex thread_mu_;  // start()/stop()
  std::thread ticker_ GUARDED_BY(thread_mu_);
  std::atomic<bool> running_{false};
  Mutex tick_wait_mu_;
  CondVar tick_wait_cv_;
  bool wake_requested_ GUARDED_BY(tick_wait_mu_) = false;
  // True while the loop thread may be sleeping at its idle rate: dispatch() then brings the
  // driver up to date before applying, and anything that adds work wakes the loop.
  std::atomic<bool> resting_{false};
};

}  // namespace rcan::node

#include "node/safety/safety.h"

#include <fcntl.h>
#include <pthread.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iterator>

#include "base/clock.h"
#include "runtime/log.h"

// How the guarantees of safety.h are kept:
//   * estop() sets an atomic flag and calls Driver::stop() first (no lock, no I/O on that
//     path), then fences out a dispatch() that was already inside the driver (a lock-free wait
//     for that one apply, then a second stop()), then hands the new latch state to the
//     persister thread, which writes the latch file (LatchFile, latch_file.h: in place or
//     replaced whole, durably) and retries every 200 ms until it is durable. A write torn by a
//     crash fails the file's check and the node comes up latched.
//   * The deadman table (deadmen_, by control session id) is scanned by tick(); a lost
//     deadman is revived by feed_deadman(), but only the next accepted command clears the
//     safe-stop it caused.
//   * The ESTOP latency statistics use the steady clock (real elapsed time), not Clock.

namespace rcan::node {
namespace {

constexpr size_t kLatencyRing = 4096;
constexpr int64_t kMaxStepMs = 60'000;
constexpr int kLevelLeasee = 3;
constexpr int kLevelOwner = 4;

json::Value joints_json(const JointArray& a) {
  json::Array out;
  for (double d : a) out.emplace_back(d);
  return json::Value(std::move(out));
}

SafetyLimits effective_limits(const SafetyLimits& cfg, const DriverInfo& hw) {
  SafetyLimits l = cfg;
  auto cap = [](double c, double h) { return h > 0 ? std::min(c, h) : c; };
  l.max_linear_mps = cap(std::max(0.0, cfg.max_linear_mps), hw.max_linear_mps);
  l.max_angular_radps = cap(std::max(0.0, cfg.max_angular_radps), hw.max_angular_radps);
  l.max_joint_speed_radps = cap(std::max(0.0, cfg.max_joint_speed_radps), hw.max_joint_speed_radps);
  if (hw.has_arm) {
    for (int i = 0; i < kArmJoints; ++i) {
      l.joint_min_rad[i] = std::max(cfg.joint_min_rad[i], hw.joint_min_rad[i]);
      l.joint_max_rad[i] = std::min(cfg.joint_max_rad[i], hw.joint_max_rad[i]);
      if (l.joint_min_rad[i] > l.joint_max_rad[i]) l.joint_max_rad[i] = l.joint_min_rad[i];
    }
  }
  if (l.max_drive_duration_ms <= 0) l.max_drive_duration_ms = 1000;
  return l;
}

}  // namespace

json::Object SafetyLimits::to_json() const {
  return json::Object{{"max_linear_mps", max_linear_mps},
                      {"max_angular_radps", max_angular_radps},
                      {"max_joint_speed_radps", max_joint_speed_radps},
                      {"joint_min_rad", joints_json(joint_min_rad)},
                      {"joint_max_rad", joints_json(joint_max_rad)},
                      {"max_drive_duration_ms", max_drive_duration_ms},
                      {"workspace", json::Object{{"enabled", workspace.enabled},
                                                 {"min_x", workspace.x_min},
                                                 {"max_x", workspace.x_max},
                                                 {"min_y", workspace.y_min},
                                                 {"max_y", workspace.y_max}}}};
}

json::Object DispatchOutcome::to_json() const {
  json::Array c;
  for (const auto& s : clamps) c.emplace_back(s);
  return json::Object{
      {"clamped", clamped}, {"clamps", json::Value(std::move(c))}, {"applied", applied.to_json()}};
}

json::Object SafetyEvent::to_json() const {
  json::Object o{{"type", type}};
  if (!session_id.empty()) o.set("session_id", session_id);
  o.set("elapsed_ms", elapsed_ms);
  if (timeout_ms > 0) o.set("timeout_ms", timeout_ms);
  if (!detail.empty()) o.set("detail", detail);
  o.set("timestamp_ms", wall_ms);
  return o;
}

json::Object LatencyStats::to_json() const {
  return json::Object{{"count", static_cast<int64_t>(count)},
                      {"last_ns", last_ns},
                      {"p50_ns", p50_ns},
                      {"p99_ns", p99_ns},
                      {"max_ns", max_ns}};
}

json::Object SafetyStatus::to_json() const {
  json::Object o;
  o.set("estop_active", estop_active);
  if (estop_active) {
    o.set("estop", json::Object{{"source", estop_source},
                                {"reason", estop_reason},
                                {"since_ms", estop_since_wall_ms}});
  }
  o.set("estop_epoch", static_cast<int64_t>(estop_epoch));
  o.set("safe_stop", safe_stop_active);
  if (safe_stop_active) {
    json::Object s{{"reason", safe_stop_reason}, {"since_ms", safe_stop_since_wall_ms}};
    if (!safe_stop_session.empty()) s.set("session_id", safe_stop_session);
    o.set("safe_stop_detail", std::move(s));
  }
  if (!driver_fault.empty()) o.set("driver_fault", driver_fault);
  o.set("state", estop_active       ? "estop"
                 : safe_stop_active ? "safe_stop"
                 : robot.stopped    ? "idle"
                                    : "moving");
  o.set("limit_policy", limit_policy_name(policy));
  o.set("limits", limits.to_json());
  o.set("robot", robot.to_json());
  o.set("driver", driver.to_json());
  o.set("estop_latency", estop_latency.to_json());
  o.set("estop_fence_timeouts", static_cast<int64_t>(estop_fence_timeouts));
  o.set("persistence", json::Object{{"enabled", persistence_enabled},
                                    {"durable", persisted},
                                    {"error", persist_error.empty() ? json::Value()
                                                                    : json::Value(persist_error)}});
  if (!startup_note.empty()) o.set("startup_note", startup_note);
  o.set("sessions", static_cast<int64_t>(sessions));
  o.set("running", running);
  return o;
}

SafetyCore::SafetyCore(std::unique_ptr<Driver> driver, SafetyConfig cfg, Clock& clock)
    : driver_(std::move(driver)),
      cfg_(std::move(cfg)),
      clock_(clock),
      driver_info_(driver_->describe()),
      limits_(effective_limits(cfg_.limits, driver_info_)) {
  latency_ring_.reserve(kLatencyRing);
  last_tick_mono_ = clock_.mono_ms();
  if (cfg_.file.estop_on_startup) {
    latched_.store(true);
    latch_ = LatchState{true, "startup", "estop_on_startup", clock_.wall_ms()};
    driver_->stop();
  }
}

SafetyCore::~SafetyCore() {
  stop();
  {
    MutexLock lock(meta_mu_);
    persist_quit_ = true;
  }
  persist_cv_.notify_all();
  if (persister_.joinable()) persister_.join();
  std::vector<PersistWaiter> left;
  std::string why;
  {
    MutexLock lock(meta_mu_);
    left = take_waiters_locked([](const PersistWaiter&) { return true; });
    why = persist_error_.empty() ? "shutting down before the latch was written" : persist_error_;
  }
  for (auto& w : left) w.fn(false, why);
}

Status SafetyCore::open(const std::string& state_dir, base::Env* env) {
  namespace fs = std::filesystem;
  {
    MutexLock lock(meta_mu_);
    if (persist_enabled_) return Error(ErrorCode::kInternal, "SafetyCore::open called twice");
  }
  std::error_code ec;
  fs::create_directories(state_dir, ec);
  if (ec)
    return Error(ErrorCode::kInternal,
                 "cannot create safety state dir " + state_dir + ": " + ec.message());
  ::chmod(state_dir.c_str(), 0700);
  latch_file_.emplace(state_dir, env);

  // A file that cannot be read is as good as a corrupt one: the node comes up latched.
  auto read = latch_file_->read();
  LatchRead file =
      read.ok() ? std::move(read).value() : LatchRead{false, true, "state file unreadable", {}};
  const bool corrupt = file.corrupt;
  const bool missing = file.missing;
  const std::string& why = file.why;
  const LatchState& loaded = file.state;
  if (corrupt) latch_file_->set_aside();

  bool need_write = false;
  bool write_cleared = false;
  LatchState cleared;
  {
    MutexLock lock(meta_mu_);
    persist_enabled_ = true;
    if (corrupt) {
      latch_ = LatchState{true, "startup", why + "; came up latched (fail safe)", clock_.wall_ms()};
      startup_note_ = latch_.reason;
      need_write = true;
    } else if (missing) {
      if (!latch_.active) startup_note_ = "no safety state file (first start)";
      need_write = latch_.active;  // estop_on_startup
    } else if (loaded.active) {
      latch_ = loaded;
      startup_note_ = "ESTOP was latched before restart; still latched";
    } else if (latch_.active) {
      need_write = true;  // estop_on_startup over a cleared file
    }
    if (latch_.active) {
      estop_epoch_.fetch_add(1, std::memory_order_acq_rel);
      latched_.store(true, std::memory_order_release);
    }
    if (need_write) ++latch_seq_;
    // No file yet, or a cleared one of an older form: written now, cleared, in the fixed form,
    // so that the first latch is rewritten in place like every later one (one pwrite and one
    // fdatasync, not a new file, a rename and a directory sync on the first ESTOP's path).
    // It says what a missing file says. Should it fail, it is retried like a latch's write, and
    // a latch meanwhile writes the file whole.
    write_cleared = !latch_.active && !corrupt && (missing || !latch_file_->fixed());
    if (write_cleared) {
      cleared = latch_;
      persist_busy_ = true;  // the file is this thread's until it is written
    }
  }
  if (write_cleared) {
    Status s = latch_file_->write(cleared, clock_.wall_ms());
    if (!s.ok())
      log(LogLevel::kWarn, "safety_state_not_written",
          json::Object{{"error", s.error().message},
                       {"note", "retried every 200 ms; the status shows persistence.error"}});
    {
      MutexLock lock(meta_mu_);
      persist_busy_ = false;
      if (!s.ok()) {  // the persister retries it, and the status says so before any ESTOP
        persist_error_ = s.error().message;
        ++latch_seq_;
      }
    }
    persist_cv_.notify_all();
  }
  if (latched_.load()) driver_->stop();
  persister_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "safety-persist");
    persist_loop();
  });
  return Status::Ok();
}

void SafetyCore::set_event_callback(EventFn fn) {
  MutexLock lock(event_mu_);
  on_event_ = std::move(fn);
}

void SafetyCore::emit(const SafetyEvent& ev) {
  EventFn fn;
  {
    MutexLock lock(event_mu_);
    fn = on_event_;
  }
  if (fn) fn(ev);
}

// ---- ESTOP / RESUME -------------------------------------------------------------------------

EstopResult SafetyCore::estop(std::string_view source, std::string_view reason, int by_level,
                              bool wake_persister) {
  const int64_t t0 = steady_ns();
  // The epoch first: a session armed from here on is armed at the new epoch, one armed before
  // (a hold that started before this ESTOP) needs rearm() after the RESUME.
  estop_epoch_.fetch_add(1, std::memory_order_seq_cst);
  latched_.store(true, std::memory_order_seq_cst);
  driver_->stop();  // first, before any lock or I/O
  const int64_t ns = steady_ns() - t0;

  // Fence without a lock: a dispatch() that read the latch as clear before we set it may be
  // inside Driver::apply() right now (apply_seq_ odd). Wait for that one apply only (not for
  // the threads queued behind it: they re-check the latch under the lock and must see it, by
  // the seq_cst order of our latch store / seq load against their seq increment / latch
  // load), then stop again, so nothing applied before this point survives. The wait is
  // bounded; on timeout the straggler stops the driver itself right after its apply.
  EstopResult r;
  r.stop_latency_ns = ns;
  const uint64_t seq = apply_seq_.load(std::memory_order_seq_cst);
  if (seq & 1u) {
    const int64_t limit = t0 + std::max<int64_t>(0, cfg_.estop_fence_timeout_ms) * 1'000'000;
    int spins = 0;
    while (apply_seq_.load(std::memory_order_acquire) == seq) {
      if (steady_ns() > limit) {
        r.fenced = false;
        fence_timeouts_.fetch_add(1, std::memory_order_relaxed);
        break;
      }
      if (++spins > 64) std::this_thread::yield();
    }
  }
  driver_->stop();
  record_latency(ns);

  {
    MutexLock lock(meta_mu_);
    latched_.store(true, std::memory_order_release);  // a racing resume() must not win silently
    if (!latch_.active) {
      latch_ =
          LatchState{true, std::string(source), std::string(reason), clock_.wall_ms(), by_level};
      ++latch_seq_;
      r.newly_latched = true;
    } else if (by_level > latch_.by_level) {
      // Latched again by a higher role: clearing it now needs that role.
      latch_.by_level = by_level;
      ++latch_seq_;
      r.newly_latched = true;  // persisted like a new latch
    }
    r.state_seq = latch_seq_;
  }
  if (r.newly_latched && wake_persister) persist_cv_.notify_all();
  r.return_latency_ns = steady_ns() - t0;
  return r;
}

Status SafetyCore::resume(int principal_role_level, std::string_view source) {
  if (principal_role_level < kLevelLeasee) {
    return Error(ErrorCode::kInsufficientPrivileges,
                 "clearing ESTOP requires LEASEE (level 3) or above", "", "estop_clear_forbidden");
  }
  {
    MutexLock lock(meta_mu_);
    if (!latch_.active && !latched_.load()) return Status::Ok();  // nothing latched
    // Whoever latched it decides who may clear it: a role at least theirs, or OWNER.
    if (principal_role_level < std::min(latch_.by_level, kLevelOwner)) {
      return Error(ErrorCode::kInsufficientPrivileges,
                   "this ESTOP was latched by role level " + std::to_string(latch_.by_level) +
                       "; clearing it needs that level or OWNER",
                   "", "estop_clear_forbidden");
    }
    latch_ = LatchState{false, std::string(source), "resume", clock_.wall_ms()};
    ++latch_seq_;
    latched_.store(false, std::memory_order_release);
  }
  {
    MutexLock lock(deadman_mu_);
    watchdog_last_feed_mono_ = 0;  // re-armed by the next feed
  }
  persist_cv_.notify_all();
  return Status::Ok();
}

bool SafetyCore::wait_persisted(uint64_t seq, int64_t timeout_ms) {
  MutexLock lock(meta_mu_);
  if (!persist_enabled_) return false;
  const auto deadline = steady_now() + std::chrono::milliseconds(timeout_ms);
  while (persisted_seq_ < seq)
    if (durable_cv_.wait_until(meta_mu_, deadline) == std::cv_status::timeout)
      return persisted_seq_ >= seq;
  return true;
}

void SafetyCore::when_persisted(uint64_t seq, LatchFn fn) {
  bool memory_only = false;
  {
    MutexLock lock(meta_mu_);
    memory_only = !persist_enabled_;
    if (!memory_only && persisted_seq_ < seq) {
      persist_waiters_.push_back(PersistWaiter{
          seq, clock_.mono_ms() + std::max<int64_t>(0, cfg_.latch_ack_timeout_ms), std::move(fn)});
      fn = nullptr;
    }
  }
  if (!fn) {
    wake_ticker();  // a new deadline for a resting control loop
  } else if (memory_only) {
    fn(false, "no safety state directory: the latch is kept in memory only");
  } else {
    fn(true, "");
  }
}

template <typename Pred>
std::vector<SafetyCore::PersistWaiter> SafetyCore::take_waiters_locked(Pred pred) {
  std::vector<PersistWaiter> out;
  auto keep = std::partition(persist_waiters_.begin(), persist_waiters_.end(),
                             [&](const PersistWaiter& w) { return !pred(w); });
  std::move(keep, persist_waiters_.end(), std::back_inserter(out));
  persist_waiters_.erase(keep, persist_waiters_.end());
  return out;
}

void SafetyCore::expire_persist_waiters(int64_t now) {
  std::vector<PersistWaiter> late;
  {
    MutexLock lock(meta_mu_);
    if (persist_waiters_.empty()) return;
    late = take_waiters_locked([&](const PersistWaiter& w) { return now >= w.deadline_mono; });
  }
  for (auto& w : late)
    w.fn(false, "the latch file was not written within " +
                    std::to_string(cfg_.latch_ack_timeout_ms) + " ms (still trying)");
}

uint64_t SafetyCore::state_seq() const {
  MutexLock lock(meta_mu_);
  return latch_seq_;
}

void SafetyCore::record_latency(int64_t ns) {
  MutexLock lock(stats_mu_);
  if (latency_ring_.size() < kLatencyRing) {
    latency_ring_.push_back(ns);
  } else {
    latency_ring_[latency_next_] = ns;
  }
  latency_next_ = (latency_next_ + 1) % kLatencyRing;
  ++latency_count_;
  latency_last_ns_ = ns;
  latency_max_ns_ = std::max(latency_max_ns_, ns);
}

LatencyStats SafetyCore::estop_latency() const {
  std::vector<int64_t> v;
  LatencyStats s;
  {
    MutexLock lock(stats_mu_);
    v = latency_ring_;
    s.count = latency_count_;
    s.last_ns = latency_last_ns_;
    s.max_ns = latency_max_ns_;
  }
  if (!v.empty()) {
    std::sort(v.begin(), v.end());
    s.p50_ns = v[(v.size() - 1) / 2];
    s.p99_ns = v[std::min(v.size() - 1, (v.size() * 99) / 100)];
  }
  return s;
}

// ---- persistence ----------------------------------------------------------------------------

Status SafetyCore::write_latest_locked() {
  const uint64_t seq = latch_seq_;
  const LatchState snapshot = latch_;
  meta_mu_.unlock();
  Status st = latch_file_->write(snapshot, clock_.wall_ms());
  meta_mu_.lock();
  std::vector<PersistWaiter> answered;
  if (st.ok()) {
    persisted_seq_ = std::max(persisted_seq_, seq);
    persist_error_.clear();
    durable_cv_.notify_all();
    const uint64_t durable = persisted_seq_;
    answered = take_waiters_locked([durable](const PersistWaiter& w) { return w.seq <= durable; });
  } else {
    persist_error_ = st.error().message;
    durable_cv_.notify_all();
    answered = take_waiters_locked([seq](const PersistWaiter& w) { return w.seq <= seq; });
  }
  if (!answered.empty()) {  // answered unlocked: a callback may ask for the status
    const std::string error = persist_error_;
    meta_mu_.unlock();
    for (auto& w : answered) w.fn(st.ok(), error);
    meta_mu_.lock();
  }
  return st;
}

void SafetyCore::persist_here_if_idle() {
  ReleasableMutexLock lock(meta_mu_);
  if (!persist_enabled_ || persist_busy_ || persisted_seq_ >= latch_seq_) return;
  persist_busy_ = true;
  (void)write_latest_locked();
  persist_busy_ = false;
  // Behind still (a newer change, or this write failed: retried), or shutting down while this
  // thread wrote: the persister's turn. Otherwise it sleeps on.
  const bool hand_over = persisted_seq_ < latch_seq_ || persist_quit_;
  lock.unlock();
  if (hand_over) persist_cv_.notify_all();
}

void SafetyCore::persist_loop() {
  ReleasableMutexLock lock(meta_mu_);
  for (;;) {
    while (persist_busy_ || (!persist_quit_ && persisted_seq_ >= latch_seq_))
      persist_cv_.wait(meta_mu_);
    if (persisted_seq_ >= latch_seq_) return;  // shutting down, nothing pending
    const uint64_t seq = latch_seq_;
    persist_busy_ = true;
    Status st = write_latest_locked();
    persist_busy_ = false;
    if (st.ok()) continue;
    if (persist_quit_) return;
    // Retry every 200 ms, sooner on a new change or shutdown (which makes one last attempt).
    const auto retry_at = steady_now() + std::chrono::milliseconds(200);
    while (!persist_quit_ && latch_seq_ == seq)
      if (persist_cv_.wait_until(meta_mu_, retry_at) == std::cv_status::timeout) break;
  }
}

// ---- sessions / watchdog --------------------------------------------------------------------

void SafetyCore::arm_deadman(const std::string& session_id, int64_t timeout_ms) {
  {
    MutexLock lock(deadman_mu_);
    auto [it, fresh] = deadmen_.try_emplace(session_id);
    Deadman& s = it->second;
    // A new session is armed at the current epoch; re-registering one (a renewing claim) keeps
    // its epoch: only rearm() re-arms after an ESTOP.
    if (fresh) s.armed_epoch = estop_epoch_.load(std::memory_order_acquire);
    s.timeout_ms = timeout_ms > 0 ? timeout_ms : int64_t{cfg_.file.heartbeat_timeout_ms};
    s.last_heartbeat_mono = clock_.mono_ms();
    s.lost = false;
  }
  wake_ticker();  // a new deadline, possibly sooner than the loop's idle sleep
}

Status SafetyCore::feed_deadman(const std::string& session_id) {
  bool revived = false;
  {
    MutexLock lock(deadman_mu_);
    auto it = deadmen_.find(session_id);
    if (it == deadmen_.end())
      return Error(ErrorCode::kNotFound, "unknown session", "session_id", "unknown_session");
    it->second.last_heartbeat_mono = clock_.mono_ms();
    revived = it->second.lost;
    it->second.lost = false;
  }
  if (revived) wake_ticker();  // a heartbeat only moves a live deadline later
  return Status::Ok();
}

Status SafetyCore::rearm(const std::string& session_id) {
  MutexLock lock(deadman_mu_);
  auto it = deadmen_.find(session_id);
  if (it == deadmen_.end())
    return Error(ErrorCode::kNotFound, "unknown session", "session_id", "unknown_session");
  it->second.armed_epoch = estop_epoch_.load(std::memory_order_acquire);
  return Status::Ok();
}

void SafetyCore::disarm_deadman(const std::string& session_id) {
  bool held = false;
  {
    MutexLock lock(deadman_mu_);
    auto it = deadmen_.find(session_id);
    if (it == deadmen_.end()) return;
    held = it->second.holds_control;
    deadmen_.erase(it);
  }
  MutexLock lock(apply_mu_);
  if (held || (!session_id.empty() && motion_owner_ == session_id)) {
    if (!driver_->state().stopped || held) {
      driver_->stop();
      drive_deadline_mono_ = 0;
    }
    if (motion_owner_ == session_id) motion_owner_.clear();
  }
}

void SafetyCore::set_deadman_holds_control(const std::string& session_id, bool holds_control) {
  MutexLock lock(deadman_mu_);
  auto it = deadmen_.find(session_id);
  if (it != deadmen_.end()) it->second.holds_control = holds_control;
}

void SafetyCore::feed_watchdog() {
  bool armed = false;
  {
    MutexLock lock(deadman_mu_);
    armed = watchdog_last_feed_mono_ == 0;
    watchdog_last_feed_mono_ = clock_.mono_ms();
    if (watchdog_last_feed_mono_ == 0) watchdog_last_feed_mono_ = 1;
  }
  if (armed) wake_ticker();  // a feed only moves an armed deadline later
}

void SafetyCore::enter_safe_stop(std::string reason, std::string session) {
  MutexLock lock(meta_mu_);
  safe_stop_reason_ = std::move(reason);
  safe_stop_session_ = std::move(session);
  safe_stop_since_wall_ms_ = clock_.wall_ms();
  safe_stop_.store(true, std::memory_order_release);
}

// ---- control loop ---------------------------------------------------------------------------

// One pass of the control loop: the driver stepped to now, then each guard in turn (drive TTL,
// workspace, driver health, deadman sessions, the watchdog); every stop is made before any event
// is emitted.
void SafetyCore::tick() {
  const int64_t t0 = steady_ns();
  const int64_t now = clock_.mono_ms();
  std::vector<SafetyEvent> events;
  std::string owner;
  bool moving = false;
  HealthChange health;
  {
    MutexLock lock(apply_mu_);
    step_driver_to_locked(now);
    // Only now, with the driver stepped to `now` under apply_mu_, is a rest over: until here a
    // dispatch() still catches the driver up itself (see start()).
    resting_.store(false, std::memory_order_seq_cst);
    if (latched_.load(std::memory_order_acquire)) driver_->stop();  // belt and braces
    const RobotState st = driver_->state();
    guard_motion_locked(now, st, events);
    health = check_health_locked();
    owner = motion_owner_;
    moving = !st.stopped;
  }
  on_health_change(now, health, events);
  const int64_t watchdog_elapsed = check_deadmen(now, owner, moving, events);

  for (const auto& ev : events) {
    if (ev.type == "DRIVER_FAULT" || ev.type == "DRIVER_RECOVERED") continue;  // handled above
    driver_->stop();
    if (ev.type == "NETWORK_LOSS_SAFE_STOP") {
      enter_safe_stop("NETWORK_LOSS_SAFE_STOP", ev.session_id);
    } else if (ev.type == "WORKSPACE_SAFE_STOP") {
      enter_safe_stop("workspace", "");
    } else {
      enter_safe_stop("drive_ttl", "");
    }
  }
  if (!events.empty()) {
    MutexLock lock(apply_mu_);
    drive_deadline_mono_ = 0;
  }
  if (watchdog_elapsed > 0) {
    (void)estop("watchdog", "brain watchdog timeout");
    events.push_back(event_at(now, "WATCHDOG_TIMEOUT", watchdog_elapsed, cfg_.watchdog_timeout_ms,
                              "no watchdog feed; ESTOP latched"));
  }

  expire_persist_waiters(now);
  loop_count_.fetch_add(1, std::memory_order_relaxed);
  loop_latency_us_.store((steady_ns() - t0) / 1000, std::memory_order_relaxed);
  for (const auto& ev : events) emit(ev);
}

SafetyEvent SafetyCore::event_at(int64_t now, std::string type, int64_t elapsed, int64_t timeout,
                                 std::string detail) const {
  SafetyEvent ev;
  ev.type = std::move(type);
  ev.elapsed_ms = elapsed;
  ev.timeout_ms = timeout;
  ev.detail = std::move(detail);
  ev.wall_ms = clock_.wall_ms();
  ev.mono_ms = now;
  return ev;
}

// The drive's TTL on the monotonic clock, and the workspace guard: the braking distance ahead
// must not take the base further out.
void SafetyCore::guard_motion_locked(int64_t now, const RobotState& st,
                                     std::vector<SafetyEvent>& events) {
  if (drive_deadline_mono_ > 0 && now >= drive_deadline_mono_) {
    const bool still_driving = st.target_linear_mps != 0.0 || st.target_angular_radps != 0.0;
    if (!still_driving) {
      drive_deadline_mono_ = 0;
    } else if (now > drive_deadline_mono_ + cfg_.drive_ttl_grace_ms) {
      driver_->stop();
      events.push_back(event_at(now, "DRIVE_TTL_SAFE_STOP", now - drive_deadline_mono_, 0,
                                "the driver kept driving past the command's duration"));
      drive_deadline_mono_ = 0;
    }
  }
  const Workspace& ws = limits_.workspace;
  if (ws.enabled && st.linear_mps != 0.0) {
    const double brake = driver_info_.brake_decel_mps2;
    const double dist = brake > 0 ? st.linear_mps * std::abs(st.linear_mps) / (2.0 * brake) : 0.0;
    const double px = st.x + dist * std::cos(st.theta);
    const double py = st.y + dist * std::sin(st.theta);
    const double here = ws.distance_outside(st.x, st.y);
    const double ahead = ws.distance_outside(px, py);
    if (ahead > 1e-3 && ahead > here) {
      driver_->stop();
      drive_deadline_mono_ = 0;
      events.push_back(
          event_at(now, "WORKSPACE_SAFE_STOP", 0, 0, "the base was about to leave the workspace"));
    }
  }
}

// Driver health: a fault stops the driver at once and holds motion off until it clears.
SafetyCore::HealthChange SafetyCore::check_health_locked() {
  HealthChange change;
  const DriverHealth health = driver_->health();
  if (!health.ok && !driver_faulted_.load(std::memory_order_acquire)) {
    driver_->stop();
    drive_deadline_mono_ = 0;
    driver_faulted_.store(true, std::memory_order_release);
    change.started = true;
    change.detail = health.fault.empty() ? std::string("the driver reports a fault") : health.fault;
  } else if (health.ok && driver_faulted_.load(std::memory_order_acquire)) {
    driver_faulted_.store(false, std::memory_order_release);
    change.cleared = true;
  }
  return change;
}

// A fault that began: safe stop, DRIVER_FAULT, and ESTOP when safety.estop_on_driver_fault; one
// that cleared: DRIVER_RECOVERED naming it.
void SafetyCore::on_health_change(int64_t now, const HealthChange& change,
                                  std::vector<SafetyEvent>& events) {
  if (change.started) {
    {
      MutexLock lock(meta_mu_);
      driver_fault_ = change.detail;
    }
    enter_safe_stop("driver_fault", "");
    events.push_back(event_at(now, "DRIVER_FAULT", 0, 0, change.detail));
    if (cfg_.file.estop_on_driver_fault) (void)estop("driver", change.detail);
  } else if (change.cleared) {
    std::string was;
    {
      MutexLock lock(meta_mu_);
      was.swap(driver_fault_);
    }
    events.push_back(
        event_at(now, "DRIVER_RECOVERED", 0, 0, "the driver is healthy again (was: " + was + ")"));
  }
}

// Deadman sessions past their timeout (a safe stop when the session holds control or owns the
// motion), and the watchdog: returns how long it went unfed when it fired (disarming it), else 0.
int64_t SafetyCore::check_deadmen(int64_t now, const std::string& owner, bool moving,
                                  std::vector<SafetyEvent>& events) {
  MutexLock lock(deadman_mu_);
  for (auto& [id, s] : deadmen_) {
    const int64_t elapsed = now - s.last_heartbeat_mono;
    if (s.lost || elapsed <= s.timeout_ms) continue;
    s.lost = true;
    if (s.holds_control || (moving && id == owner)) {
      SafetyEvent ev =
          event_at(now, "NETWORK_LOSS_SAFE_STOP", elapsed, s.timeout_ms, "heartbeat timeout");
      ev.session_id = id;
      events.push_back(std::move(ev));
    }
  }
  if (cfg_.watchdog_timeout_ms > 0 && watchdog_last_feed_mono_ != 0 &&
      now - watchdog_last_feed_mono_ > cfg_.watchdog_timeout_ms) {
    const int64_t elapsed = now - watchdog_last_feed_mono_;
    watchdog_last_feed_mono_ = 0;
    return elapsed;
  }
  return 0;
}

// Steps the driver from the last tick (or catch-up) to `now`; never backwards. Holds apply_mu_.
void SafetyCore::step_driver_to_locked(int64_t now) {
  if (now > last_tick_mono_) driver_->step(std::min(now - last_tick_mono_, kMaxStepMs));
  last_tick_mono_ = std::max(last_tick_mono_, now);
}

int64_t SafetyCore::rest_for_ms() const {
  if (cfg_.idle_tick_ms <= cfg_.tick_period_ms) return 0;
  const int64_t now = clock_.mono_ms();
  int64_t until = now + cfg_.idle_tick_ms;
  {
    MutexLock lock(apply_mu_);
    if (drive_deadline_mono_ != 0 || !driver_->at_rest()) return 0;
  }
  {
    MutexLock lock(deadman_mu_);
    // tick() acts once a deadline has passed (elapsed > timeout): wake 1 ms after it.
    for (const auto& [id, s] : deadmen_)
      if (!s.lost) until = std::min(until, s.last_heartbeat_mono + s.timeout_ms + 1);
    if (cfg_.watchdog_timeout_ms > 0 && watchdog_last_feed_mono_ != 0)
      until = std::min(until, watchdog_last_feed_mono_ + cfg_.watchdog_timeout_ms + 1);
  }
  {
    MutexLock lock(meta_mu_);
    for (const auto& w : persist_waiters_) until = std::min(until, w.deadline_mono);
  }
  const int64_t rest = until - now;
  return rest > cfg_.tick_period_ms ? rest : 0;
}

void SafetyCore::wake_ticker() {
  if (!resting_.load(std::memory_order_seq_cst)) return;
  {
    MutexLock wl(tick_wait_mu_);
    wake_requested_ = true;
  }
  tick_wait_cv_.notify_all();
}

void SafetyCore::start() {
  MutexLock lock(thread_mu_);
  if (running_.load()) return;
  running_.store(true);
  {
    MutexLock l2(apply_mu_);
    last_tick_mono_ = clock_.mono_ms();
  }
  ticker_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "safety-tick");
    const auto period = std::chrono::milliseconds(std::max<int64_t>(1, cfg_.tick_period_ms));
    auto next = steady_now() + period;
    while (running_.load(std::memory_order_acquire)) {
      tick();
      {
        MutexLock wl(tick_wait_mu_);
        wake_requested_ = false;
      }
      // Announce the rest before checking whether we may: a dispatch() or session change that
      // the check does not see then sees resting_ and wakes us (see wake_ticker()).
      resting_.store(true, std::memory_order_seq_cst);
      const int64_t rest_ms = rest_for_ms();
      MutexLock wl(tick_wait_mu_);
      if (rest_ms > 0) {
        const auto wake_at = steady_now() + std::chrono::milliseconds(rest_ms);
        while (!wake_requested_ && running_.load(std::memory_order_acquire))
          if (tick_wait_cv_.wait_until(tick_wait_mu_, wake_at) == std::cv_status::timeout) break;
        // resting_ stays set until the next tick() has stepped the driver (it clears it under
        // apply_mu_): a command arriving between this wake-up and that step still brings the
        // driver up to its own moment, instead of being integrated over the whole rest.
        next = steady_now() + period;
        continue;
      }
      resting_.store(false, std::memory_order_seq_cst);
      while (running_.load(std::memory_order_acquire))
        if (tick_wait_cv_.wait_until(tick_wait_mu_, next) == std::cv_status::timeout) break;
      next += period;
      const auto now = steady_now();
      if (next < now) next = now + period;  // overran: do not try to catch up
    }
  });
}

void SafetyCore::stop() {
  {
    MutexLock lock(thread_mu_);
    if (ticker_.joinable()) {
      {
        MutexLock wl(tick_wait_mu_);
        running_.store(false, std::memory_order_release);
      }
      tick_wait_cv_.notify_all();
      ticker_.join();
    }
    running_.store(false);
    driver_->stop();
    MutexLock al(apply_mu_);
    driver_->stop();
    drive_deadline_mono_ = 0;
  }
  // Whoever waits for the latch file is answered now, while what it answers through (the
  // node's services and transports, stopped before the core) still exists.
  std::vector<PersistWaiter> left;
  {
    MutexLock ml(meta_mu_);
    left = take_waiters_locked([](const PersistWaiter&) { return true; });
  }
  for (auto& w : left) w.fn(false, "the safety core stopped before the latch file was written");
}

// ---- status ---------------------------------------------------------------------------------

RobotState SafetyCore::decorate(RobotState st) const {
  st.ts = clock_.wall_ms();
  st.loop_latency_ms =
      static_cast<double>(loop_latency_us_.load(std::memory_order_relaxed)) / 1000.0;
  st.loop_count = loop_count_.load(std::memory_order_relaxed);
  st.paused =
      latched_.load(std::memory_order_acquire) || safe_stop_.load(std::memory_order_acquire);
  return st;
}

RobotState SafetyCore::robot_state() const {
  RobotState st;
  {
    MutexLock lock(apply_mu_);
    st = driver_->state();
  }
  return decorate(st);
}

SafetyStatus SafetyCore::status() const {
  SafetyStatus s;
  s.robot = robot_state();
  s.driver = driver_info_;
  s.limits = limits_;
  s.policy = cfg_.file.speed_policy;
  s.estop_latency = estop_latency();
  {
    MutexLock lock(meta_mu_);
    s.estop_active = latched_.load(std::memory_order_acquire);
    s.estop_epoch = estop_epoch_.load(std::memory_order_acquire);
    if (s.estop_active) {
      s.estop_source = latch_.source;
      s.estop_reason = latch_.reason;
      s.estop_since_wall_ms = latch_.since_wall_ms;
    }
    s.safe_stop_active = safe_stop_.load(std::memory_order_acquire);
    if (s.safe_stop_active) {
      s.safe_stop_reason = safe_stop_reason_;
      s.safe_stop_session = safe_stop_session_;
      s.safe_stop_since_wall_ms = safe_stop_since_wall_ms_;
    }
    s.driver_fault = driver_fault_;
    s.estop_fence_timeouts = fence_timeouts_.load(std::memory_order_relaxed);
    s.persistence_enabled = persist_enabled_;
    s.persisted = !persist_enabled_ || persisted_seq_ >= latch_seq_;
    s.persist_error = persist_error_;
    s.startup_note = startup_note_;
  }
  {
    MutexLock lock(deadman_mu_);
    s.sessions = deadmen_.size();
  }
  s.running = running_.load();
  return s;
}

}  // namespace rcan::node

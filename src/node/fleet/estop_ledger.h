// What a fleet member remembers of its fleet's ESTOPs and RESUMEs (docs/FLEET.md, "A standing
// ESTOP has a bound"), so that a captured ESTOP cannot latch the robot again once the fleet has
// resumed it.
//
// A retained ESTOP on the fleet's estop topic is obeyed whatever its age: it is the fleet's
// standing order. Anyone who can write the topic can put a captured one back after the
// operator's RESUME (its token and signature are still good) and force the robot to reconnect.
// The ledger bounds that order:
//   * a fleet ESTOP this robot honoured is superseded by the next fleet RESUME it applies and is
//     never obeyed again (live or retained), until its token expires and the entry is dropped
//     (the token no longer verifies from then on either);
//   * a retained ESTOP must not be older (its own timestamp_ms) than the last fleet RESUME
//     applied by more than kClockMarginMs (coordinators' clocks may differ).
// A new ESTOP — an id never honoured, or one stamped after the RESUME, or any live one not yet
// superseded — is obeyed as before. Kept in <state_dir>/fleet_estops.json (0600, written
// atomically on every change) and read back at start-up, so a restart forgets nothing.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "base/thread_annotations.h"
#include "rcan/json.h"

namespace rcan::node {

class FleetEstopLedger {
 public:
  // `path` empty: kept in memory only. Reads the file: one of another fleet or member, or one
  // that does not parse, is logged and not taken.
  FleetEstopLedger(std::string path, std::string fleet_id, std::string member_id, int64_t now_s);

  enum class Verdict { kObey, kSuperseded, kOlderThanResume };
  // Whether the fleet ESTOP `id` stamped `ts_ms` may latch; `standing`: the retained copy.
  Verdict judge(const std::string& id, int64_t ts_ms, bool standing) const EXCLUDES(mu_);
  // The robot latched fleet ESTOP `id` (its token expires at `exp_s`, unix seconds).
  void honoured(const std::string& id, int64_t ts_ms, std::optional<int64_t> exp_s, int64_t now_s)
      EXCLUDES(mu_);
  // The robot applied a fleet RESUME stamped `ts_ms`: every ESTOP honoured so far is superseded.
  void resumed(int64_t ts_ms, int64_t now_s) EXCLUDES(mu_);

  int64_t last_resume_ms() const EXCLUDES(mu_);
  size_t size() const EXCLUDES(mu_);

  // How much older than the last RESUME a standing ESTOP's stamp may be and still be obeyed:
  // the freshness window every message is held to (the senders' clocks may differ by that).
  static constexpr int64_t kClockMarginMs = 30'000;

  // Entries kept at most (the oldest are dropped first; a dropped superseded ESTOP is still
  // older than the RESUME that superseded it).
  static constexpr size_t kMaxEntries = 1024;

 private:
  struct Entry {
    int64_t ts_ms = 0;
    int64_t exp_s = 0;  // 0: the token had no exp (kept until crowded out)
    bool superseded = false;
  };
  void restore() EXCLUDES(mu_);
  void prune_locked(int64_t now_s) REQUIRES(mu_);
  void persist_locked() REQUIRES(mu_);

  const std::string path_, fleet_id_, member_id_;
  mutable Mutex mu_;
  std::map<std::string, Entry> entries_ GUARDED_BY(mu_);
  int64_t last_resume_ms_ GUARDED_BY(mu_) = 0;
};

}  // namespace rcan::node

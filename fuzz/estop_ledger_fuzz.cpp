// libFuzzer target: a fleet member's ESTOP ledger file (src/node/fleet/estop_ledger.h), as
// rcand reads `fleet_estops.json` at start-up. Must never crash, and whatever the file says, a
// new fleet ESTOP is obeyed: live, or retained and stamped after the last RESUME the file
// records — a damaged or hostile ledger may never keep the robot from stopping.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <string>

#include "node/fleet/estop_ledger.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using rcan::node::FleetEstopLedger;
  static const std::string path =
      (std::getenv("TMPDIR") ? std::string(std::getenv("TMPDIR")) : std::string("/tmp")) +
      "/rcan-estop-ledger-fuzz-" + std::to_string(::getpid()) + ".json";
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  constexpr int64_t kNow = 1'800'000'000;
  FleetEstopLedger ledger(path, "yard", "robot-a", kNow);
  // Judged before anything is written back: what the file alone says.
  // An id longer than any the file may hold (restore() takes ids of at most 256 bytes).
  const std::string fresh(300, 'n');
  if (ledger.judge(fresh, kNow * 1000, false) != FleetEstopLedger::Verdict::kObey) std::abort();
  const int64_t last = ledger.last_resume_ms();
  if (last < std::numeric_limits<int64_t>::max() &&
      ledger.judge(fresh, last + 1, true) != FleetEstopLedger::Verdict::kObey)
    std::abort();
  ::unlink(path.c_str());
  return 0;
}

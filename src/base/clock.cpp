#include "base/clock.h"

namespace rcan {
namespace {

class SystemClock final : public Clock {
 public:
  int64_t wall_ms() const override { return unix_ms(); }
  int64_t mono_ms() const override { return steady_ms(); }
};

}  // namespace

Clock& Clock::system() {
  static SystemClock clock;
  return clock;
}

}  // namespace rcan

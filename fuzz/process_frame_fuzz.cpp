// libFuzzer target: the byte stream a driver process sends rcand (drivers/process/frame.h).
// FrameDecoder splits it into frames and parse_incoming() validates each: neither may crash,
// a frame is never longer than the maximum, an error is sticky, and a state the parser accepts
// holds finite numbers only (nothing non-finite may reach the safety core).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "drivers/process/frame.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  drivers::FrameDecoder dec;
  // Fed in uneven pieces, as recv() returns them.
  size_t off = 0, piece = 1;
  while (off < size) {
    const size_t n = std::min(piece, size - off);
    dec.feed(reinterpret_cast<const char*>(data) + off, n);
    off += n;
    piece = piece * 3 + 1;
    while (true) {
      auto f = dec.next();
      if (!f.ok()) {
        if (f.error().message.empty()) std::abort();
        if (dec.next().ok()) std::abort();  // sticky
        return 0;
      }
      if (!*f) break;
      if ((*f)->empty() || (*f)->size() > drivers::kMaxFramePayload) std::abort();
      auto in = drivers::parse_incoming(**f);
      if (!in.ok()) {
        if (in.error().message.empty()) std::abort();
        continue;
      }
      const node::RobotState& s = in->state;
      for (double d : {s.x, s.y, s.theta, s.linear_mps, s.angular_radps, s.target_linear_mps,
                       s.target_angular_radps, s.odometry_m, s.battery_v, s.battery_pct})
        if (!std::isfinite(d)) std::abort();
      for (double d : s.joints_rad)
        if (!std::isfinite(d)) std::abort();
    }
  }
  return 0;
}

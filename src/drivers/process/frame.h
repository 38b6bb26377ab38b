// The driver-process protocol's frames and messages (docs/DRIVERS.md §Driver processes).
//
// A frame is a 4-byte big-endian unsigned length N (1 ≤ N ≤ kMaxFramePayload) followed by N
// bytes: one JSON object (UTF-8) with a string member "type". rcand writes describe, apply,
// stop and heartbeat frames (encode_*); the process answers with describe, heartbeat and state
// frames, which parse_incoming() validates strictly: an unknown type, a missing required
// member, a member of the wrong type or a non-finite number is an error (the driver treats it
// as a fault). Nothing here does I/O; FrameDecoder takes bytes as they arrive.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "node/safety/driver.h"
#include "rcan/result.h"

namespace rcan::drivers {

inline constexpr uint32_t kProtocolVersion = 1;
inline constexpr size_t kFrameHeaderBytes = 4;
inline constexpr size_t kMaxFramePayload = 65536;

// The 4-byte header and `payload`.
std::string encode_frame(std::string_view payload);

// rcand → process.
std::string encode_describe(uint64_t seq, uint32_t heartbeat_ms, uint32_t heartbeat_timeout_ms);
std::string encode_apply(uint64_t seq, const node::ActuatorCommand& cmd);
std::string encode_stop(uint64_t seq);
std::string encode_heartbeat(uint64_t seq);

// Splits a byte stream into frame payloads. An error (zero or oversize length) is sticky: the
// stream cannot be resynchronised, the connection must be dropped.
class FrameDecoder {
 public:
  explicit FrameDecoder(size_t max_payload = kMaxFramePayload) : max_(max_payload) {}
  void feed(const char* data, size_t n);
  // The next complete payload; nullopt while more bytes are needed.
  Result<std::optional<std::string>> next();
  size_t buffered() const { return buf_.size() - off_; }

 private:
  size_t max_;
  std::string buf_;
  size_t off_ = 0;
  std::optional<Error> err_;
};

// A validated message from the process.
struct Incoming {
  enum class Kind { kDescribe, kHeartbeat, kState };
  Kind kind = Kind::kHeartbeat;
  // describe
  uint32_t protocol = 0;
  std::string name;
  std::optional<double> max_linear_mps;
  std::optional<double> max_angular_radps;
  // heartbeat: the process's own fault (empty: healthy)
  std::string fault;
  // state
  node::RobotState state;
};

// Validates one frame payload as a message from the process.
Result<Incoming> parse_incoming(std::string_view payload);

}  // namespace rcan::drivers

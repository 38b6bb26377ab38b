// libFuzzer: `.rcan.yaml` parsing (src/config/config.cpp) on arbitrary text. Must never crash,
// hang or blow up memory: alias bombs, recursive aliases, deep nesting and oversized input
// must end in an Error. Accepted configs must satisfy the loader's own invariants.
//
// Links rcan_node (yaml-cpp): fuzz/CMakeLists.txt needs
//   target_link_libraries(config_fuzz PRIVATE rcan_node)
// Seeds: fuzz/corpus/config/ (the profiles, the example and the test fixtures).
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "config/config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  rcan::config::ConfigOptions opts;
  opts.default_data_dir = "/nonexistent/rcand-fuzz";
  opts.device_id = "0a1b2c3d";  // so that profile-shaped inputs with {device_id} get deep
  auto r = rcan::config::parse_config_text(text, opts);
  if (!r.ok()) {
    const rcan::Error& e = r.error();
    if (e.code != rcan::ErrorCode::kSchemaValidationFailed || e.message.empty() || e.reason.empty())
      std::abort();
    if (e.message.size() > 4096) std::abort();  // messages quote input, but bounded
    return 0;
  }
  const rcan::config::NodeConfig& c = *r;
  auto again = rcan::parse_ruri(c.ruri);
  if (!again.ok() || again->str() != c.ruri) std::abort();
  if (c.server.port == 0 || c.security.replay_window_s < 5 || c.security.replay_window_s > 300)
    std::abort();
  if (!(c.safety.max_linear_speed_mps > 0) || !(c.safety.max_angular_speed_radps > 0)) std::abort();
  for (const auto& j : c.safety.joint_limits)
    if (!(j.min_rad < j.max_rad)) std::abort();
  for (const auto& g : c.agent.confidence_gates)
    if (!(g.min_confidence >= 0 && g.min_confidence <= 1)) std::abort();
  for (const auto& h : c.agent.hitl_gates)
    if (h.auth_timeout_ms == 0 || h.authorized_roles.empty()) std::abort();
  if (c.data_dir.empty() || c.security.key_dir.empty() || c.security.audit.dir.empty())
    std::abort();
  return 0;
}

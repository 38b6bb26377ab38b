// Shared helpers for the audit tests (header-only).
#pragma once

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "rcan/audit/audit_log.h"
#include "rcan/audit/verify.h"
#include "rcan/json.h"

namespace rcan::audit::testutil {

inline constexpr const char* kSecret =
    "0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef";

inline AuditEntry entry(int i) {
  AuditEntry e;
  e.principal = "operator@rcan://local.rcan/opencastor/rover/abc123";
  e.ruri = "rcan://registry.rcan.dev/acme/rover/v1/unit-001";
  e.timestamp_ms = 1740000000000 + i;
  e.message_id = "msg-" + std::to_string(i);
  e.event = "COMMAND";
  e.outcome = "ok";
  e.sub = "user-" + std::to_string(i % 7);
  e.action = "move_forward";
  if (i % 3 == 0) {
    AiBlock ai;
    ai.provider = "anthropic";
    ai.model = "claude";
    if (i % 2 == 0) ai.confidence = 0.5 + (i % 10) / 100.0;
    ai.escalated = false;
    e.ai = ai;
  }
  if (i % 5 == 0) e.watermark_token = "rcan-wm-v1:" + std::string(31, '0') + std::to_string(i % 10);
  return e;
}

inline AuditOptions options(uint64_t max_segment_bytes = 64ull << 20) {
  AuditOptions o;
  o.secret = kSecret;
  o.max_segment_bytes = max_segment_bytes;
  o.robot_ruri = "rcan://registry.rcan.dev/acme/rover/v1/unit-001";
  return o;
}

inline std::vector<std::string> export_lines(const AuditLog& log) {
  std::vector<std::string> out;
  Status s = log.export_range(INT64_MIN, INT64_MAX, [&](std::string_view l) {
    out.emplace_back(l);
    return true;
  });
  EXPECT_TRUE(s.ok()) << s.error().message;
  return out;
}

inline std::vector<std::string> export_dir_lines(const std::string& dir) {
  std::vector<std::string> out;
  Status s = export_dir(dir, INT64_MIN, INT64_MAX, [&](std::string_view l) {
    out.emplace_back(l);
    return true;
  });
  EXPECT_TRUE(s.ok()) << s.error().message;
  return out;
}

inline std::string join(const std::vector<std::string>& lines) {
  std::string s;
  for (const auto& l : lines) s += l + "\n";
  return s;
}

inline json::Value parse(std::string_view line) {
  json::ParseOptions o;
  o.max_bytes = 8u << 20;
  auto v = json::parse(line, o);
  EXPECT_TRUE(v.ok()) << line;
  return v.ok() ? std::move(v).value() : json::Value();
}

inline std::string kind_of(const std::string& line) {
  auto v = parse(line);
  const json::Value* k = v.get("kind");
  return k && k->is_string() ? k->as_string() : "";
}

inline void write_file(const std::string& path, const std::string& data, mode_t mode = 0600) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << data;
  ::chmod(path.c_str(), mode);
}

// The durable records of `event` in `log`, oldest first, once there are `expected` of them
// (records are written asynchronously) or 5 s have passed.
inline std::vector<json::Value> records_of(AuditLog& log, const std::string& event,
                                           size_t expected) {
  std::vector<json::Value> out;
  for (int i = 0; i < 500; ++i) {
    out.clear();
    const AuditStats st = log.stats();
    for (uint64_t seq = st.first_seq; seq != 0 && seq <= st.last_seq; ++seq) {
      auto line = log.get(seq);
      if (!line.ok()) continue;
      auto v = json::parse(*line);
      if (v.ok() && json::string_field(*v, "event") == event) out.push_back(*v);
    }
    if (out.size() >= expected) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return out;
}

}  // namespace rcan::audit::testutil

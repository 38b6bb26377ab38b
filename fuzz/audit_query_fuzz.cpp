// libFuzzer target: the query string of GET /api/audit (node/api/audit_query.h). The input is
// split as a URL query (name=value&…); parse_audit_query() must name the parameter it refuses,
// and a query it accepts runs against a small real audit log (created once) without crashing,
// returning at most `limit` records in seq order, each matching the query's event filter.
#include <stdlib.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <string_view>

#include "node/api/audit_query.h"
#include "rcan/audit/audit_log.h"

namespace {

std::string g_dir;  // removed at exit, after the log is closed

const rcan::audit::AuditLog& log_once() {
  static std::unique_ptr<rcan::audit::AuditLog> log = [] {
    std::string tmpl =
        (std::filesystem::temp_directory_path() / "rcan-audit-query-fuzz-XXXXXX").string();
    if (mkdtemp(tmpl.data()) == nullptr) std::abort();
    g_dir = tmpl;
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(g_dir, ec);
    });
    const char* dir = g_dir.c_str();
    rcan::audit::AuditOptions o;
    o.secret = "fuzz-chain-secret-0123456789abcdef";
    o.robot_ruri = "rcan://local.rcan/acme/rover/0a1b2c3d";
    o.max_segment_bytes = 64 << 10;
    o.preallocate = false;
    auto opened = rcan::audit::AuditLog::open(std::string(dir) + "/log", std::move(o));
    if (!opened.ok()) std::abort();
    for (int i = 0; i < 300; ++i) {
      rcan::audit::AuditEntry e;
      e.principal = i % 3 ? "alice" : "bob";
      e.ruri = "rcan://local.rcan/acme/rover/0a1b2c3d";
      e.timestamp_ms = 1740000000000 + int64_t{i} * 1000;
      e.message_id = "m-" + std::to_string(i % 50);
      e.event = i % 5 ? "COMMAND" : "ESTOP";
      e.outcome = i % 4 ? "ok" : "blocked";
      if (!(*opened)->append(std::move(e)).ok()) std::abort();
    }
    return std::move(opened).value();
  }();
  return *log;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  std::string_view in(reinterpret_cast<const char*>(data), size);
  std::map<std::string, std::string, std::less<>> params;
  size_t i = 0;
  while (i <= in.size()) {
    size_t amp = in.find('&', i);
    if (amp == std::string_view::npos) amp = in.size();
    std::string_view pair = in.substr(i, amp - i);
    size_t eq = pair.find('=');
    if (eq != std::string_view::npos) params[std::string(pair.substr(0, eq))] = pair.substr(eq + 1);
    i = amp + 1;
  }
  auto q = node::parse_audit_query(
      [&](std::string_view name) -> std::optional<std::string_view> {
        auto it = params.find(name);
        if (it == params.end()) return std::nullopt;
        return std::string_view(it->second);
      },
      50);
  if (!q.ok()) {
    if (q.error().field.empty() || q.error().message.empty()) std::abort();
    return 0;
  }
  q->scan_budget = 500;
  node::AuditPage page = node::run_audit_query(log_once(), *q);
  if (page.entries.size() > q->limit) std::abort();
  int64_t prev = 0;
  for (const auto& e : page.entries) {
    const int64_t seq = json::int_field(e, "seq");
    if (seq <= prev) std::abort();
    prev = seq;
    if (q->before && static_cast<uint64_t>(seq) >= q->before) std::abort();
    if (q->after && static_cast<uint64_t>(seq) <= q->after) std::abort();
  }
  return 0;
}

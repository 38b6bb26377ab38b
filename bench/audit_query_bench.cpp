// The dashboard's audit view on a large log: GET /api/audit's query (node/api/audit_query.h)
// over N records (default 1,000,000) in a real audit log on disk — what the node does for each
// page, measured without the HTTP hop (loopback adds well under a millisecond).
//
//   audit_query_bench [--records 1000000] [--dir DIR] [--keep 1]
//
// Prints, each over 20 repetitions (p50 / max): the first page (limit 100) and the bytes of its
// JSON answer; the next, older page by its cursor; a search by message_id (the sidecar index);
// a time window in the middle of the log; an event filter; a text search that runs out of its
// scan budget (how long one budget of records takes). Writing the log is timed too.
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include "node/api/audit_query.h"
#include "rcan/audit/audit_log.h"
#include "rcan/json.h"

using namespace rcan;
namespace fs = std::filesystem;

namespace {

constexpr int64_t kT0 = 1760000000000;

double now_ms() {
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

audit::AuditEntry make_entry(uint64_t i) {
  audit::AuditEntry e;
  e.principal = "operator-" + std::to_string(i % 13);
  e.ruri = "rcan://local.rcan/acme/rover/0a1b2c3d";
  e.timestamp_ms = kT0 + static_cast<int64_t>(i) * 100;  // ten a second
  e.message_id = "msg-" + std::to_string(i);
  e.event = i % 50 == 0 ? "ESTOP" : (i % 7 == 0 ? "COMMAND_REJECTED" : "COMMAND");
  e.outcome = i % 7 == 0 ? "blocked" : "ok";
  e.sub = "user-" + std::to_string(i % 101);
  e.action = i % 3 ? "move" : "arm";
  e.detail.set("linear", 0.25);
  e.detail.set("duration_ms", 500);
  return e;
}

// Appends `n` records with up to 4,096 in flight (group commit).
bool fill(audit::AuditLog& log, uint64_t n) {
  std::mutex mu;
  std::condition_variable cv;
  uint64_t done = 0, in_flight = 0;
  bool failed = false;
  for (uint64_t i = 1; i <= n; ++i) {
    {
      std::unique_lock<std::mutex> lk(mu);
      cv.wait(lk, [&] { return in_flight < 4096; });
      if (failed) return false;
      ++in_flight;
    }
    log.append_async(make_entry(i), [&](Result<audit::Receipt> r) {
      std::lock_guard<std::mutex> lk(mu);
      if (!r.ok()) failed = true;
      --in_flight;
      ++done;
      cv.notify_all();
    });
  }
  std::unique_lock<std::mutex> lk(mu);
  cv.wait(lk, [&] { return done == n; });
  return !failed;
}

struct Timing {
  std::vector<double> ms;
  size_t bytes = 0, entries = 0;
  uint64_t scanned = 0;
};

Timing measure(const audit::AuditLog& log, const std::function<node::AuditQuery()>& make) {
  Timing t;
  for (int rep = 0; rep < 20; ++rep) {
    node::AuditQuery q = make();
    double t0 = now_ms();
    node::AuditPage page = node::run_audit_query(log, q);
    // The answer as the route writes it (node.cpp list_audit).
    json::Object body{{"count", static_cast<int64_t>(page.entries.size())},
                      {"entries", std::move(page.entries)},
                      {"unreadable", std::move(page.unreadable)}};
    std::string text = json::dump(json::Value(std::move(body)));
    t.ms.push_back(now_ms() - t0);
    t.bytes = text.size();
    t.entries = static_cast<size_t>(json::int_field(*json::parse(text), "count"));
    t.scanned = page.scanned;
  }
  std::sort(t.ms.begin(), t.ms.end());
  return t;
}

void print(const char* what, const Timing& t) {
  std::printf("%-44s p50 %7.2f ms  max %7.2f ms  %5zu records  %8zu bytes  scanned %llu\n", what,
              t.ms[t.ms.size() / 2], t.ms.back(), t.entries, t.bytes,
              static_cast<unsigned long long>(t.scanned));
}

}  // namespace

int main(int argc, char** argv) {
  uint64_t records = 1'000'000;
  std::string dir;
  bool keep = false;
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string a = argv[i];
    if (a == "--records")
      records = std::strtoull(argv[i + 1], nullptr, 10);
    else if (a == "--dir")
      dir = argv[i + 1];
    else if (a == "--keep")
      keep = std::atoi(argv[i + 1]) != 0;
  }
  if (records < 1000 || records > 100'000'000) {
    std::fprintf(stderr,
                 "usage: audit_query_bench [--records 1000..100000000] [--dir DIR] [--keep 0|1]\n");
    return 2;
  }
  const bool made_dir = dir.empty();
  if (made_dir)
    dir = (fs::temp_directory_path() / ("audit_query_bench_" + std::to_string(getpid()))).string();
  std::error_code mk;
  fs::create_directories(dir, mk);
  audit::AuditOptions o;
  o.secret = "bench-chain-secret-0123456789abcdef";
  o.robot_ruri = "rcan://local.rcan/acme/rover/0a1b2c3d";
  auto opened = audit::AuditLog::open(dir + "/audit", std::move(o));
  if (!opened.ok()) {
    std::fprintf(stderr, "audit log: %s\n", opened.error().message.c_str());
    return 1;
  }
  auto& log = **opened;
  const uint64_t have = log.stats().last_seq;
  if (have < records) {
    const double t0 = now_ms();
    if (!fill(log, records - have)) {
      std::fprintf(stderr, "audit_query_bench: appending failed\n");
      return 1;
    }
    const double s = (now_ms() - t0) / 1000;
    std::printf("wrote %llu records in %.1f s (%.0f records/s)\n",
                static_cast<unsigned long long>(records - have), s,
                static_cast<double>(records - have) / s);
  }
  const audit::AuditStats st = log.stats();
  std::printf("audit_query_bench: %llu records in %llu segments (%.0f MiB)\n",
              static_cast<unsigned long long>(st.last_seq),
              static_cast<unsigned long long>(st.segments),
              static_cast<double>(st.total_bytes) / (1 << 20));

  node::AuditPage first = node::run_audit_query(log, [] {
    node::AuditQuery q;
    q.limit = 100;
    return q;
  }());
  const uint64_t cursor = first.next_before;
  const std::string mid_id = "msg-" + std::to_string(records / 2);
  print("first page (limit 100)", measure(log, [] {
          node::AuditQuery q;
          q.limit = 100;
          return q;
        }));
  print("next page by its cursor", measure(log, [&] {
          node::AuditQuery q;
          q.limit = 100;
          q.before = cursor;
          return q;
        }));
  print(("message_id " + mid_id + " (indexed)").c_str(), measure(log, [&] {
          node::AuditQuery q;
          q.message_id = mid_id;
          return q;
        }));
  print("time window of 60 s mid-log", measure(log, [&] {
          node::AuditQuery q;
          q.limit = 100;
          q.from_ms = kT0 + static_cast<int64_t>(records / 2) * 100;
          q.to_ms = q.from_ms + 60'000;
          return q;
        }));
  print("event ESTOP (every 50th record)", measure(log, [] {
          node::AuditQuery q;
          q.limit = 100;
          q.event = "ESTOP";
          return q;
        }));
  print("text absent: one scan budget", measure(log, [] {
          node::AuditQuery q;
          q.limit = 100;
          q.text = "no such text anywhere";
          return q;
        }));
  opened->reset();
  if (made_dir && !keep) {
    std::error_code ec;
    fs::remove_all(dir, ec);
  } else {
    std::printf("log kept in %s\n", dir.c_str());
  }
  return 0;
}

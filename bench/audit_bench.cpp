// audit_bench — durable append throughput and latency of rcan::audit::AuditLog.
//
//   audit_bench [--dir D] [--seconds S] [--big N] [--probe M] [--window W] [--policy
//   group|interval]
//
// 1. Durable appends/s with 1, 4 and 16 appending threads (each thread calls the blocking
//    append(), which returns only after the fdatasync covering the record), with p50 /
//    p99 / max append-to-acknowledge latency; then the same with append_async() and W
//    records in flight per thread (how the node's I/O threads use the log).
// 2. Append cost when the log holds 1 thousand records vs N records (--big, default
//    1,000,000; the README reports a 10,000,000 run): the log is filled with async
//    appends, then M (--probe) blocking appends from 16 threads are timed.
// Every number is for records that are durable (fdatasync'ed) when acknowledged.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "rcan/audit/audit_log.h"

using namespace rcan::audit;
using Clock = std::chrono::steady_clock;

namespace {

constexpr const char* kSecret = "bench-secret-0123456789abcdef0123456789abcdef";

AuditEntry make_entry(uint64_t i) {
  AuditEntry e;
  e.principal = "operator@rcan://local.rcan/opencastor/rover/abc123";
  e.ruri = "rcan://registry.rcan.dev/acme/rover/v1/unit-001";
  e.message_id = "7d3f2a10-5b7c-4c1e-9f2a-" + std::to_string(100000000000 + i);
  e.event = "COMMAND";
  e.outcome = "ok";
  e.sub = "user-42";
  e.action = "move_forward";
  AiBlock ai;
  ai.provider = "anthropic";
  ai.model = "claude-sonnet";
  ai.confidence = 0.91;
  ai.thought_id = "th-" + std::to_string(i);
  e.ai = ai;
  e.watermark_token = "rcan-wm-v1:0123456789abcdef0123456789abcdef";
  return e;
}

struct RunResult {
  double seconds = 0;
  uint64_t records = 0;
  std::vector<double> lat_us;
  uint64_t syncs = 0;
};

double pct(std::vector<double>& v, double p) {
  if (v.empty()) return 0;
  size_t k = static_cast<size_t>(p * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<long>(k), v.end());
  return v[k];
}

// `threads` threads call append() until `seconds` pass or `total` records are done.
RunResult run_appenders(AuditLog& log, int threads, double seconds, uint64_t total,
                        std::atomic<uint64_t>& counter) {
  RunResult r;
  std::mutex mu;
  std::atomic<uint64_t> done{0};
  auto deadline = Clock::now() + std::chrono::duration<double>(seconds);
  uint64_t syncs0 = log.stats().syncs;
  auto t0 = Clock::now();
  std::vector<std::thread> ts;
  for (int t = 0; t < threads; ++t) {
    ts.emplace_back([&] {
      std::vector<double> lat;
      lat.reserve(1 << 16);
      for (;;) {
        if (total ? done.load() >= total : Clock::now() >= deadline) break;
        AuditEntry e = make_entry(counter.fetch_add(1));
        auto a = Clock::now();
        auto res = log.append(std::move(e));
        auto b = Clock::now();
        if (!res.ok()) {
          std::fprintf(stderr, "append failed: %s\n", res.error().message.c_str());
          std::exit(1);
        }
        lat.push_back(std::chrono::duration<double, std::micro>(b - a).count());
        done.fetch_add(1);
      }
      std::lock_guard<std::mutex> l(mu);
      r.lat_us.insert(r.lat_us.end(), lat.begin(), lat.end());
    });
  }
  for (auto& t : ts) t.join();
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  r.records = done.load();
  r.syncs = log.stats().syncs - syncs0;
  return r;
}

// `threads` threads each keep up to `window` append_async() records in flight (what a
// node's I/O threads do: they never block on the disk) for `seconds`.
RunResult run_async_appenders(AuditLog& log, int threads, int window, double seconds,
                              std::atomic<uint64_t>& counter) {
  RunResult r;
  std::mutex mu;
  std::atomic<uint64_t> done{0};
  auto deadline = Clock::now() + std::chrono::duration<double>(seconds);
  uint64_t syncs0 = log.stats().syncs;
  auto t0 = Clock::now();
  std::vector<std::thread> ts;
  for (int t = 0; t < threads; ++t) {
    ts.emplace_back([&] {
      std::vector<double> lat;
      lat.reserve(1 << 18);
      std::mutex lmu;
      std::atomic<int> inflight{0};
      while (Clock::now() < deadline) {
        int v = inflight.load();
        if (v >= window) {
          inflight.wait(v);
          continue;
        }
        inflight.fetch_add(1);
        auto a = Clock::now();
        log.append_async(make_entry(counter.fetch_add(1)), [&, a](rcan::Result<Receipt> res) {
          auto b = Clock::now();
          if (!res.ok()) {
            std::fprintf(stderr, "append failed: %s\n", res.error().message.c_str());
            std::exit(1);
          }
          {
            std::lock_guard<std::mutex> l(lmu);
            lat.push_back(std::chrono::duration<double, std::micro>(b - a).count());
          }
          done.fetch_add(1);
          inflight.fetch_sub(1);
          inflight.notify_all();
        });
      }
      for (int v = inflight.load(); v != 0; v = inflight.load()) inflight.wait(v);
      std::lock_guard<std::mutex> l(mu);
      std::lock_guard<std::mutex> l2(lmu);
      r.lat_us.insert(r.lat_us.end(), lat.begin(), lat.end());
    });
  }
  for (auto& t : ts) t.join();
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  r.records = done.load();
  r.syncs = log.stats().syncs - syncs0;
  return r;
}

void print(const char* label, RunResult& r) {
  double rate = static_cast<double>(r.records) / r.seconds;
  double p50 = pct(r.lat_us, 0.50), p99 = pct(r.lat_us, 0.99);
  double mx = r.lat_us.empty() ? 0 : *std::max_element(r.lat_us.begin(), r.lat_us.end());
  std::printf(
      "%-34s %10.0f rec/s  p50 %7.0f us  p99 %7.0f us  max %8.0f us  (%llu rec, %.2f rec/fsync)\n",
      label, rate, p50, p99, mx, static_cast<unsigned long long>(r.records),
      r.syncs ? static_cast<double>(r.records) / static_cast<double>(r.syncs) : 0.0);
  std::fflush(stdout);
}

// Fills the log to `target` records with async appends (many in flight → big groups).
void fill(AuditLog& log, uint64_t target, std::atomic<uint64_t>& counter) {
  std::atomic<uint64_t> inflight{0};
  auto t0 = Clock::now();
  uint64_t start = log.stats().last_seq;
  uint64_t last_print = start;
  while (log.stats().last_seq + inflight.load() < target) {
    while (inflight.load() > 20000) std::this_thread::sleep_for(std::chrono::microseconds(200));
    inflight.fetch_add(1);
    log.append_async(make_entry(counter.fetch_add(1)), [&](rcan::Result<Receipt> r) {
      if (!r.ok()) {
        std::fprintf(stderr, "fill failed: %s\n", r.error().message.c_str());
        std::exit(1);
      }
      inflight.fetch_sub(1);
    });
    uint64_t now = log.stats().last_seq;
    if (now - last_print >= 1000000) {
      last_print = now;
      double s = std::chrono::duration<double>(Clock::now() - t0).count();
      std::printf("  … %llu records (%.0f rec/s fill)\n", static_cast<unsigned long long>(now),
                  static_cast<double>(now - start) / s);
      std::fflush(stdout);
    }
  }
  while (inflight.load() > 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

}  // namespace

int main(int argc, char** argv) {
  std::string base = "/tmp";
  if (const char* t = std::getenv("TMPDIR"); t && *t) base = t;
  double seconds = 3.0;
  uint64_t big = 1000000;
  uint64_t probe = 50000;
  SyncPolicy policy = SyncPolicy::kPerGroup;
  int window = 8;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--dir")
      base = next();
    else if (a == "--seconds")
      seconds = std::stod(next());
    else if (a == "--big")
      big = std::stoull(next());
    else if (a == "--probe")
      probe = std::stoull(next());
    else if (a == "--window")
      window = std::stoi(next());
    else if (a == "--policy")
      policy = next() == "interval" ? SyncPolicy::kInterval : SyncPolicy::kPerGroup;
    else {
      std::fprintf(stderr,
                   "usage: audit_bench [--dir D] [--seconds S] [--big N] [--probe M] [--window W] "
                   "[--policy group|interval]\n");
      return 2;
    }
  }
  std::string root = base + "/rcan-audit-bench-" + std::to_string(::getpid());
  std::filesystem::create_directories(root);
  AuditOptions o;
  o.secret = kSecret;
  o.sync_policy = policy;
  std::atomic<uint64_t> counter{0};

  std::printf("audit_bench: dir %s, policy %s, %u hardware threads\n", root.c_str(),
              policy == SyncPolicy::kPerGroup ? "fdatasync per group" : "fdatasync every 2 ms",
              std::thread::hardware_concurrency());
  std::printf("== durable appends (blocking append(), %.1f s each) ==\n", seconds);
  for (int threads : {1, 4, 16}) {
    std::string dir = root + "/t" + std::to_string(threads);
    auto log = AuditLog::open(dir, o);
    if (!log.ok()) {
      std::fprintf(stderr, "open: %s\n", log.error().message.c_str());
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // let the spare settle
    RunResult r = run_appenders(**log, threads, seconds, 0, counter);
    std::string label = std::to_string(threads) + " appending thread" + (threads > 1 ? "s" : "");
    print(label.c_str(), r);
  }

  std::printf("== durable appends (append_async(), %d in flight per thread, %.1f s each) ==\n",
              window, seconds);
  for (int threads : {1, 4, 16}) {
    std::string dir = root + "/a" + std::to_string(threads);
    auto log = AuditLog::open(dir, o);
    if (!log.ok()) return 1;
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // let the spare settle
    RunResult r = run_async_appenders(**log, threads, window, seconds, counter);
    std::string label = std::to_string(threads) + " appending thread" + (threads > 1 ? "s" : "");
    print(label.c_str(), r);
  }

  std::printf("== append cost vs log size (%llu blocking appends from 16 threads) ==\n",
              static_cast<unsigned long long>(probe));
  {
    std::string dir = root + "/size";
    auto log = AuditLog::open(dir, o);
    if (!log.ok()) return 1;
    uint64_t first_id = counter.load();
    fill(**log, 1000, counter);
    RunResult small = run_appenders(**log, 16, 0, probe, counter);
    std::string l1 = "at " + std::to_string((*log)->stats().last_seq - small.records) + " records";
    print(l1.c_str(), small);
    std::printf("  filling to %llu records…\n", static_cast<unsigned long long>(big));
    auto t0 = Clock::now();
    fill(**log, big, counter);
    double fs = std::chrono::duration<double>(Clock::now() - t0).count();
    auto st = (*log)->stats();
    std::printf("  filled in %.1f s; %llu segments, %.2f GB\n", fs,
                static_cast<unsigned long long>(st.segments),
                static_cast<double>(st.total_bytes) / 1e9);
    RunResult large = run_appenders(**log, 16, 0, probe, counter);
    std::string l2 = "at " + std::to_string((*log)->stats().last_seq - large.records) + " records";
    print(l2.c_str(), large);
    double c_small = small.seconds / static_cast<double>(small.records) * 1e6;
    double c_large = large.seconds / static_cast<double>(large.records) * 1e6;
    std::printf("append cost: %.2f us/record at 1k, %.2f us/record at %llu (ratio %.3f)\n", c_small,
                c_large, static_cast<unsigned long long>(big), c_large / c_small);
    // Index lookups at size.
    auto q0 = Clock::now();
    auto found = (*log)->find_by_message_id("7d3f2a10-5b7c-4c1e-9f2a-" +
                                            std::to_string(100000000000 + first_id + 500));
    double q = std::chrono::duration<double, std::milli>(Clock::now() - q0).count();
    std::printf("find_by_message_id at %llu records: %zu hit(s) in %.2f ms\n",
                static_cast<unsigned long long>(st.last_seq), found.ok() ? found->size() : 0, q);
  }
  std::filesystem::remove_all(root);
  return 0;
}

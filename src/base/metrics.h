// Metrics — counters, gauges and latency histograms, rendered in Prometheus text format
// (GET /metrics). Label sets are small and fixed by the node (route, status, stage), so a
// mutex-protected map per family is enough; hot counters are atomics.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "base/thread_annotations.h"

namespace rcan {

// Latency histogram in microseconds with fixed buckets; lock-free observe().
class Histogram {
 public:
  // Finer between 100 µs and 2.5 ms, where a durable command's stages fall.
  static constexpr std::array<double, 20> kBucketsUs{
      10,  25,   50,   100,  150,  200,   250,   300,   400,    500,
      750, 1000, 1500, 2500, 5000, 10000, 25000, 50000, 100000, 1000000};
  void observe_us(double us);
  // Approximate quantile (0..1) from the buckets, in microseconds.
  double quantile_us(double q) const;
  uint64_t count() const { return count_.load(std::memory_order_relaxed); }
  double sum_us() const {
    return static_cast<double>(sum_ns_.load(std::memory_order_relaxed)) / 1000.0;
  }
  uint64_t bucket(size_t i) const { return buckets_[i].load(std::memory_order_relaxed); }

 private:
  std::array<std::atomic<uint64_t>, kBucketsUs.size() + 1> buckets_{};
  std::atomic<uint64_t> count_{0};
  std::atomic<uint64_t> sum_ns_{0};
};

class Metrics {
 public:
  // requests_total{route,status}
  void count_request(const std::string& route, int status) EXCLUDES(mu_);
  // pipeline_stage_seconds{stage}
  Histogram& stage(const std::string& name) EXCLUDES(mu_);
  // rcan_audit_records_total{event}
  void count_audit(const std::string& event) EXCLUDES(mu_);
  // Named gauges computed at render time (e.g. audit queue depth, estop state).
  void add_gauge(std::string name, std::string help, std::function<double()> fn) EXCLUDES(mu_);
  void add_counter_fn(std::string name, std::string help, std::function<double()> fn) EXCLUDES(mu_);

  std::string render() const EXCLUDES(mu_);

 private:
  mutable Mutex mu_;
  // Looked up without building a key (every answer counts itself).
  struct RouteStatusLess {
    using is_transparent = void;
    template <class A, class B>
    bool operator()(const A& a, const B& b) const {
      const int c = std::string_view(a.first).compare(std::string_view(b.first));
      return c < 0 || (c == 0 && a.second < b.second);
    }
  };
  std::map<std::pair<std::string, int>, uint64_t, RouteStatusLess> requests_ GUARDED_BY(mu_);
  std::map<std::string, uint64_t, std::less<>> audit_events_ GUARDED_BY(mu_);
  std::map<std::string, std::unique_ptr<Histogram>, std::less<>> stages_ GUARDED_BY(mu_);
  struct Fn {
    std::string name, help, type;
    std::function<double()> fn;
  };
  std::vector<Fn> fns_ GUARDED_BY(mu_);
};

}  // namespace rcan

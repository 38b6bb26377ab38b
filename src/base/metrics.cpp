#include "base/metrics.h"

#include <charconv>
#include <memory>

namespace rcan {

void Histogram::observe_us(double us) {
  size_t i = 0;
  while (i < kBucketsUs.size() && us > kBucketsUs[i]) ++i;
  buckets_[i].fetch_add(1, std::memory_order_relaxed);
  count_.fetch_add(1, std::memory_order_relaxed);
  sum_ns_.fetch_add(static_cast<uint64_t>(us * 1000.0), std::memory_order_relaxed);
}

double Histogram::quantile_us(double q) const {
  uint64_t total = count();
  if (total == 0) return 0;
  uint64_t target = static_cast<uint64_t>(q * static_cast<double>(total));
  uint64_t acc = 0;
  for (size_t i = 0; i < buckets_.size(); ++i) {
    acc += bucket(i);
    if (acc > target) return i < kBucketsUs.size() ? kBucketsUs[i] : kBucketsUs.back() * 10;
  }
  return kBucketsUs.back();
}

void Metrics::count_request(const std::string& route, int status) {
  MutexLock lock(mu_);
  auto it = requests_.find(std::pair<std::string_view, int>(route, status));
  if (it != requests_.end()) {
    ++it->second;
  } else {
    requests_.emplace(std::pair<std::string, int>(route, status), 1);
  }
}

Histogram& Metrics::stage(const std::string& name) {
  MutexLock lock(mu_);
  auto& h = stages_[name];
  if (!h) h = std::make_unique<Histogram>();
  return *h;
}

void Metrics::count_audit(const std::string& event) {
  MutexLock lock(mu_);
  auto it = audit_events_.find(event);
  if (it != audit_events_.end()) {
    ++it->second;
  } else {
    audit_events_.emplace(event, 1);
  }
}

void Metrics::add_gauge(std::string name, std::string help, std::function<double()> fn) {
  MutexLock lock(mu_);
  fns_.push_back(Fn{std::move(name), std::move(help), "gauge", std::move(fn)});
}

void Metrics::add_counter_fn(std::string name, std::string help, std::function<double()> fn) {
  MutexLock lock(mu_);
  fns_.push_back(Fn{std::move(name), std::move(help), "counter", std::move(fn)});
}

namespace {
// The shortest form that reads back exactly, %g style as Prometheus' own clients write values
// and bucket bounds ("0.00015", "0.0001", "1e-05"; not "0.00014999999999999999").
std::string num(double v) {
  char b[64];
  auto r = std::to_chars(b, b + sizeof b, v, std::chars_format::general);
  return std::string(b, r.ptr);
}
std::string escape_label(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '\\' || c == '"') out.push_back('\\');
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out.push_back(c);
  }
  return out;
}
}  // namespace

std::string Metrics::render() const {
  MutexLock lock(mu_);
  std::string out;
  out += "# HELP rcan_requests_total Requests answered, by route and HTTP status.\n";
  out += "# TYPE rcan_requests_total counter\n";
  for (const auto& [k, v] : requests_) {
    out += "rcan_requests_total{route=\"" + escape_label(k.first) + "\",status=\"" +
           std::to_string(k.second) + "\"} " + std::to_string(v) + "\n";
  }
  out += "# HELP rcan_audit_records_total Audit records written, by event.\n";
  out += "# TYPE rcan_audit_records_total counter\n";
  for (const auto& [k, v] : audit_events_)
    out +=
        "rcan_audit_records_total{event=\"" + escape_label(k) + "\"} " + std::to_string(v) + "\n";
  out += "# HELP rcan_pipeline_stage_seconds Time spent per pipeline stage.\n";
  out += "# TYPE rcan_pipeline_stage_seconds histogram\n";
  for (const auto& [name, h] : stages_) {
    uint64_t acc = 0;
    for (size_t i = 0; i < Histogram::kBucketsUs.size(); ++i) {
      acc += h->bucket(i);
      out += "rcan_pipeline_stage_seconds_bucket{stage=\"" + name + "\",le=\"" +
             num(Histogram::kBucketsUs[i] / 1e6) + "\"} " + std::to_string(acc) + "\n";
    }
    out += "rcan_pipeline_stage_seconds_bucket{stage=\"" + name + "\",le=\"+Inf\"} " +
           std::to_string(h->count()) + "\n";
    out +=
        "rcan_pipeline_stage_seconds_sum{stage=\"" + name + "\"} " + num(h->sum_us() / 1e6) + "\n";
    out += "rcan_pipeline_stage_seconds_count{stage=\"" + name + "\"} " +
           std::to_string(h->count()) + "\n";
  }
  for (const auto& f : fns_) {
    out += "# HELP " + f.name + " " + f.help + "\n# TYPE " + f.name + " " + f.type + "\n";
    out += f.name + " " + num(f.fn()) + "\n";
  }
  return out;
}

}  // namespace rcan

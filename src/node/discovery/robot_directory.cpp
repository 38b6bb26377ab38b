#include "node/discovery/robot_directory.h"

#include <algorithm>
#include <chrono>

#include "base/clock.h"
#include "runtime/log.h"

namespace rcan::node {
namespace {

// An answer's body, cut for a log line or a reason shown to an operator.
std::string shorten(std::string s) {
  if (s.size() > 200) s = s.substr(0, 200) + "…";
  return s;
}

}  // namespace

RobotDirectory::RobotDirectory(const config::DashboardConfig& cfg, const Clock& clock)
    : cfg_(cfg), clock_(clock) {
  for (const std::string& url : cfg_.robots) {
    auto u = parse_web_url(url);  // the configuration checked it
    if (!u.ok()) continue;
    u->path = "/";
    urls_.push_back(url);
    bases_.push_back(*u);
  }
  MutexLock lock(mu_);
  states_.resize(urls_.size());
}

RobotDirectory::~RobotDirectory() { stop(); }

void RobotDirectory::start() {
  if (cfg_.mdns && !mdns_) {
    mdns_ = std::make_unique<MdnsBrowser>();
    mdns_->start();
  }
  if (urls_.empty() || poller_.joinable()) return;
  poller_ = std::thread([this] { loop(); });
}

void RobotDirectory::stop() {
  {
    MutexLock lock(mu_);
    quit_ = true;
    cv_.notify_all();
  }
  if (poller_.joinable()) poller_.join();
  if (mdns_) mdns_->stop();
}

bool RobotDirectory::configured(const std::string& url) const {
  for (const std::string& u : urls_)
    if (u == url) return true;
  return false;
}

RobotDirectory::State RobotDirectory::read_one(const HttpUrl& base) const {
  State s;
  HttpUrl u = base;
  u.path = "/api/discovery";
  HttpRequestOptions o;
  o.ca_file = cfg_.ca_file;
  o.max_body = 16 * 1024;
  const int64_t t0 = clock_.mono_ms();
  auto r = http_request("GET", u, "", static_cast<int>(std::min<uint32_t>(cfg_.poll_ms, 2000)), o);
  s.latency_ms = clock_.mono_ms() - t0;
  s.checked_ms = clock_.wall_ms();
  if (!r.ok()) {
    s.status = "unreachable";
    s.error = r.error().message;
    return s;
  }
  auto v = json::parse(r->body);
  const json::Value* txt = v.ok() && v->is_object() ? v->get("txt_record") : nullptr;
  if (r->status != 200 || !txt || !txt->is_object()) {
    s.status = "unreachable";
    s.error = "GET /api/discovery answered " + std::to_string(r->status) +
              (txt ? "" : " without a txt_record") + ": " + shorten(r->body);
    return s;
  }
  s.reachable = true;
  s.name = json::string_field(*txt, "name");
  s.ruri = json::string_field(*txt, "ruri");
  s.model = json::string_field(*txt, "model");
  s.version = json::string_field(*txt, "version");
  const std::string word = json::string_field(*txt, "status");
  s.status = word == "available" || word == "claimed" || word == "estop" ? word : "unknown";
  return s;
}

void RobotDirectory::loop() {
  while (true) {
    // Every robot at once: one that does not answer must not age the others' state.
    std::vector<State> fresh(bases_.size());
    std::vector<std::thread> readers;
    readers.reserve(bases_.size());
    for (size_t i = 0; i < bases_.size(); ++i)
      readers.emplace_back([this, i, &fresh] { fresh[i] = read_one(bases_[i]); });
    for (auto& t : readers) t.join();
    MutexLock lock(mu_);
    for (size_t i = 0; i < fresh.size(); ++i) {
      if (states_[i].checked_ms == 0 || states_[i].reachable != fresh[i].reachable)
        rcan::log(fresh[i].reachable ? LogLevel::kInfo : LogLevel::kWarn,
                  fresh[i].reachable ? "dashboard_robot_reachable" : "dashboard_robot_unreachable",
                  json::Object{{"url", urls_[i]}, {"error", fresh[i].error}});
      states_[i] = std::move(fresh[i]);
    }
    const auto until = steady_now() + std::chrono::milliseconds(cfg_.poll_ms);
    while (!quit_ && steady_now() < until) cv_.wait_until(mu_, until);
    if (quit_) return;
  }
}

json::Array RobotDirectory::snapshot() const {
  MutexLock lock(mu_);
  json::Array out;
  for (size_t i = 0; i < urls_.size(); ++i) {
    const State& s = states_[i];
    json::Object o{{"url", urls_[i]},
                   {"name", s.name},
                   {"ruri", s.ruri},
                   {"model", s.model},
                   {"version", s.version},
                   {"status", s.status},
                   {"reachable", s.reachable},
                   {"checked_ms", s.checked_ms},
                   {"latency_ms", s.latency_ms}};
    if (!s.error.empty()) o.set("error", s.error);
    out.emplace_back(std::move(o));
  }
  return out;
}

json::Array RobotDirectory::discovered(const std::string& self_ruri) const {
  json::Array out;
  if (!mdns_) return out;
  auto txt = [](const MdnsRobot& m, const char* k) {
    auto it = m.txt.find(k);
    return it == m.txt.end() ? std::string() : it->second;
  };
  for (const MdnsRobot& m : mdns_->robots()) {
    if (txt(m, "ruri") == self_ruri || configured(m.url())) continue;
    const std::string word = txt(m, "status");
    out.emplace_back(json::Object{
        {"url", m.url()},
        {"name", txt(m, "name").empty() ? m.instance : txt(m, "name")},
        {"ruri", txt(m, "ruri")},
        {"model", txt(m, "model")},
        {"version", txt(m, "version")},
        {"status", word == "available" || word == "claimed" || word == "estop" ? word : "unknown"},
        {"interface", m.interface},
        {"source", "mdns"}});
  }
  return out;
}

std::string RobotDirectory::mdns_state() const {
  if (!mdns_) return "off";
  std::string why = mdns_->unavailable();
  return why.empty() ? "on" : why;
}

std::vector<RobotDirectory::StopResult> RobotDirectory::relay_stop(
    const std::vector<std::string>& urls, const std::string& authorization,
    const std::string& reason) const {
  std::vector<StopResult> results(urls.size());
  std::vector<std::thread> senders;
  senders.reserve(urls.size());
  const std::string body = json::dump(json::Object{{"reason", reason}});
  for (size_t i = 0; i < urls.size(); ++i) {
    senders.emplace_back([&, i] {
      StopResult& r = results[i];
      r.url = urls[i];
      auto u = parse_web_url(urls[i]);
      if (!u.ok()) {
        r.result = "unreachable";
        r.detail = u.error().message;
        return;
      }
      u->path = "/api/stop";
      HttpRequestOptions o;
      o.ca_file = cfg_.ca_file;
      o.max_body = 64 * 1024;
      o.headers.emplace_back("Authorization", authorization);
      const int64_t t0 = clock_.mono_ms();
      auto a = http_request("POST", *u, body, static_cast<int>(cfg_.stop_timeout_ms), o);
      r.elapsed_ms = clock_.mono_ms() - t0;
      if (!a.ok()) {
        const std::string& m = a.error().message;
        r.result = m.find("timed out") != std::string::npos ||
                           m.find("no answer within") != std::string::npos
                       ? "timeout"
                       : "unreachable";
        r.detail = m;
        return;
      }
      r.http_status = a->status;
      auto v = json::parse(a->body);
      if (a->status == 200) {
        r.result = "confirmed";
        return;
      }
      r.result = "refused";
      if (v.ok() && v->is_object())
        if (const json::Value* p = v->get("payload"); p && p->is_object()) {
          r.error_code = json::string_field(*p, "error_code");
          r.detail = json::string_field(*p, "error");
        }
      if (r.detail.empty())
        r.detail = "HTTP " + std::to_string(a->status) + ": " + shorten(a->body);
    });
  }
  for (auto& t : senders) t.join();
  return results;
}

}  // namespace rcan::node

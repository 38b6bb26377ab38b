#include "node/admission/registry_trust.h"

#include <algorithm>
#include <chrono>

#include "node/admission/registry_feed.h"
#include "runtime/http_client.h"
#include "runtime/state_file.h"

namespace rcan::node {
namespace {

constexpr int kCallTimeoutMs = 2000;
constexpr int64_t kEarlyRefreshEveryMs = 60'000;
constexpr size_t kMaxQueuedIntrospections = 64;
constexpr int64_t kActiveAnswerMs = 60'000;
constexpr int64_t kInactiveAnswerMs = 30'000;
// A failed fetch of the keys is tried again this soon at the latest (the keys are ageing).
constexpr int64_t kKeysRetryMs = 30'000;
// Introspection calls a minute at most: a flood of unverifiable tokens costs the registry this.
constexpr int kMaxIntrospectionsPerMinute = 120;

}  // namespace

bool IntrospectionAnswers::answered(std::string_view token) const {
  MutexLock l(mu_);
  auto it = answers_.find(std::string(token));
  return it != answers_.end() && it->second.until_ms > clock_.wall_ms();
}

std::optional<json::Object> IntrospectionAnswers::claims(std::string_view token) const {
  MutexLock l(mu_);
  auto it = answers_.find(std::string(token));
  if (it == answers_.end()) return std::nullopt;
  if (it->second.until_ms <= clock_.wall_ms()) {
    answers_.erase(it);
    return std::nullopt;
  }
  return it->second.claims;
}

void IntrospectionAnswers::put(const std::string& token, Answer answer) {
  const int64_t now = clock_.wall_ms();
  MutexLock l(mu_);
  if (answers_.size() >= capacity_) {
    for (auto it = answers_.begin(); it != answers_.end();)
      it = it->second.until_ms <= now ? answers_.erase(it) : std::next(it);
    if (answers_.size() >= capacity_) answers_.erase(answers_.begin());
  }
  answers_[token] = std::move(answer);
}

size_t IntrospectionAnswers::size() const {
  MutexLock l(mu_);
  return answers_.size();
}

RegistryTrust::RegistryTrust(RegistryTrustOptions opts, Clock& clock, Authenticator& auth,
                             RevocationList& revocations, Metrics& metrics, TrustRecorder record,
                             base::Env* env)
    : link_(std::move(opts), clock, std::move(record), env),
      auth_(auth),
      metrics_(metrics),
      keys_(link_, auth),
      feed_(link_, revocations),
      answers_(clock) {}

RegistryTrust::~RegistryTrust() { stop(); }

void RegistryTrust::prime(int timeout_ms) {
  feed_.load_cursor();
  auth_.on_unknown_followed_key(
      link_.issuer(),
      [this](const std::string&, std::string_view token) {
        request_early_refresh();
        request_introspection(token);
      },
      [this](std::string_view token) { return introspected(token); });
  if (!keys_.fetch(timeout_ms)) keys_.load_cache();
  add_metrics();
}

void RegistryTrust::add_metrics() {
  auto counter = [this](const char* name, const char* help, const std::atomic<uint64_t>& v) {
    metrics_.add_counter_fn(name, help, [&v] { return static_cast<double>(v.load()); });
  };
  counter("rcan_registry_jwks_fetches_total", "Fetches of the registry's keys.", keys_.fetches());
  counter("rcan_registry_jwks_failures_total",
          "Fetches of the registry's keys that failed or were refused.", keys_.failures());
  counter("rcan_registry_revocation_polls_total", "Polls of the registry's revocation feed.",
          feed_.polls());
  counter("rcan_registry_revocation_failures_total",
          "Polls of the registry's revocation feed that failed.", feed_.failures());
  counter("rcan_registry_revocations_applied_total",
          "Revocations from the registry added to the node's list.", feed_.applied());
  counter("rcan_registry_revocations_skipped_total",
          "Revocations from the registry skipped: the feed's table was full.", feed_.skipped());
  counter("rcan_registry_introspections_total", "Tokens the registry was asked about (RFC 7662).",
          introspections_);
  counter("rcan_registry_introspection_failures_total",
          "Introspection calls that failed (the token is refused for 30 s).",
          introspection_failures_);
  metrics_.add_gauge("rcan_registry_keys", "Registry keys the node verifies tokens with.",
                     [this] { return static_cast<double>(keys_.key_count()); });
}

void RegistryTrust::start() {
  thread_ = std::thread([this] { run(); });
}

void RegistryTrust::stop() {
  {
    MutexLock l(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void RegistryTrust::request_early_refresh() {
  const int64_t now = link_.clock().mono_ms();
  int64_t last = last_early_ms_.load();
  if (last != 0 && now - last < kEarlyRefreshEveryMs) return;
  if (!last_early_ms_.compare_exchange_strong(last, now)) return;  // another thread asked
  {
    MutexLock l(mu_);
    early_ = true;
  }
  cv_.notify_all();
}

void RegistryTrust::request_introspection(std::string_view token) {
  {
    // Under mu_ (then the answers' lock): a token whose call is running, or whose answer was
    // stored just before that call ended, is not queued again — the registry is asked once.
    MutexLock l(mu_);
    if (token == introspecting_) return;
    if (answers_.answered(token)) return;
    if (to_introspect_.size() >= kMaxQueuedIntrospections) return;
    for (const auto& t : to_introspect_)
      if (t == token) return;
    to_introspect_.emplace_back(token);
  }
  cv_.notify_all();
}

// RFC 7662: POST token=<jwt>, with the robot's own registry key. Any failure is cached as
// "inactive" for kInactiveAnswerMs, so an unverifiable token costs the registry one call.
void RegistryTrust::introspect(const std::string& token, int timeout_ms) {
  ++introspections_;
  const RegistryTrustOptions& opts = link_.options();
  const int64_t now = link_.clock().wall_ms();
  IntrospectionAnswers::Answer answer{std::nullopt, now + kInactiveAnswerMs};
  std::string err;
  // The robot's key from joining the registry (rcand's registry_join.h).
  auto state = read_state_file(link_.dir() + "/state.json", link_.env());
  const json::Value* key = state.ok() ? state->get("robot_key") : nullptr;
  auto u = parse_web_url(link_.url("/oauth/introspect"));
  if (!key || !key->is_string() || key->as_string().empty()) {
    err = "no robot key from the registry (registry.key_file, registration)";
  } else if (!u.ok()) {
    err = u.error().message;
  } else {
    HttpRequestOptions o;
    o.ca_file = opts.ca_file;
    o.content_type = "application/x-www-form-urlencoded";
    o.headers.emplace_back("Authorization", "Bearer " + key->as_string());
    // A compact JWS is base64url and dots: nothing in it needs form encoding.
    auto a = http_request("POST", *u, "token=" + token, timeout_ms, o);
    if (!a.ok()) {
      err = a.error().message;
    } else if (a->status != 200) {
      err = registry_refusal(a->status, a->body);
    } else if (auto parsed =
                   parse_introspection_answer(a->body, now, kActiveAnswerMs, kInactiveAnswerMs);
               !parsed.ok()) {
      err = parsed.error().message;
    } else {
      answer = IntrospectionAnswers::Answer{std::move(parsed->claims), parsed->until_ms};
    }
  }
  if (!err.empty()) {
    ++introspection_failures_;
    link_.failed("registry introspection", err);
  }
  link_.record({"TOKEN_INTROSPECTED",
                err.empty() ? "ok" : "error",
                "",
                {{"registry", opts.registry_url},
                 {"active", answer.claims.has_value()},
                 {"error", err.empty() ? json::Value() : json::Value(err)}}});
  answers_.put(token, std::move(answer));
}

// The schedule is kept on the injected clock's monotonic milliseconds; the waits between
// turns are real time.
void RegistryTrust::run() {
  Clock& clock = link_.clock();
  const int64_t keys_every = int64_t{link_.options().jwks_refresh_s} * 1000;
  const int64_t revs_every = int64_t{link_.options().revocations_refresh_s} * 1000;
  int64_t next_keys = clock.mono_ms() + keys_every;
  int64_t next_revs = clock.mono_ms();
  int64_t window_start = clock.mono_ms();
  int window_calls = 0;
  ReleasableMutexLock l(mu_);
  while (!stopping_) {
    if (early_ || clock.mono_ms() >= next_keys) {
      early_ = false;
      l.unlock();
      const bool ok = keys_.fetch(kCallTimeoutMs);
      l.lock();
      // A failed fetch is tried again sooner than the schedule (the keys are ageing).
      next_keys = clock.mono_ms() + (ok ? keys_every : std::min(keys_every, kKeysRetryMs));
      continue;
    }
    // Revocations before introspections: a flood of unverifiable tokens must not delay them.
    if (clock.mono_ms() >= next_revs) {
      l.unlock();
      (void)feed_.poll(kCallTimeoutMs);
      l.lock();
      next_revs = clock.mono_ms() + revs_every;
      continue;
    }
    if (!to_introspect_.empty()) {  // after an early fetch of the keys, which may settle it
      std::string token = std::move(to_introspect_.front());
      to_introspect_.pop_front();
      if (clock.mono_ms() - window_start >= 60'000) {
        window_start = clock.mono_ms();
        window_calls = 0;
      }
      if (window_calls >= kMaxIntrospectionsPerMinute) continue;  // dropped: stays refused
      ++window_calls;
      introspecting_ = token;
      l.unlock();
      introspect(token, kCallTimeoutMs);  // stores the answer before the token is let go
      l.lock();
      introspecting_.clear();
      continue;
    }
    const int64_t wait_ms = std::min(next_keys, next_revs) - clock.mono_ms();
    if (wait_ms > 0) cv_.wait_for(mu_, std::chrono::milliseconds(wait_ms));
  }
}

json::Value RegistryTrust::status_json() const {
  const RegistryTrustOptions& o = link_.options();
  return json::Object{{"registry_url", o.registry_url},
                      {"rrn", o.rrn},
                      {"issuer", o.issuer},
                      {"trust_tokens", true},
                      {"jwks", keys_.status_json()},
                      {"revocations", feed_.status_json()},
                      {"last_error", link_.last_error()}};
}

}  // namespace rcan::node

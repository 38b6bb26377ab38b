#include "registry_trust.h"

#include <algorithm>
#include <chrono>

#include "identity.h"
#include "node/admission/registry_feed.h"
#include "node/services/node_services.h"
#include "runtime/http_client.h"
#include "runtime/log.h"
#include "runtime/state_file.h"

namespace rcan::rcand {
namespace {

constexpr int kCallTimeoutMs = 2000;
constexpr int64_t kEarlyRefreshEveryMs = 60'000;
constexpr int kMaxPagesPerPoll = 20;
constexpr size_t kMaxQueuedIntrospections = 64;
constexpr size_t kMaxIntrospectionAnswers = 10'000;
constexpr int64_t kActiveAnswerMs = 60'000;
constexpr int64_t kInactiveAnswerMs = 30'000;
// Introspection calls a minute at most: a flood of unverifiable tokens costs the registry this.
constexpr int kMaxIntrospectionsPerMinute = 120;

}  // namespace

RegistryTrust::RegistryTrust(const config::NodeConfig& cfg, node::NodeServices& svc)
    : cfg_(cfg),
      svc_(svc),
      issuer_(cfg.registry.issuer.empty() ? cfg.registry_url : cfg.registry.issuer),
      dir_(cfg.data_dir + "/registry") {}

RegistryTrust::~RegistryTrust() { stop(); }

std::string RegistryTrust::url(const std::string& path) const {
  std::string base = cfg_.registry_url;
  while (!base.empty() && base.back() == '/') base.pop_back();
  return base + path;
}

void RegistryTrust::failed(const std::string& what, const std::string& error) {
  {
    std::lock_guard<std::mutex> l(mu_);
    (what.rfind("registry keys", 0) == 0 ? keys_error_ : revs_error_) = what + ": " + error;
  }
  log(LogLevel::kWarn, "registry_trust_failed", json::Object{{"what", what}, {"error", error}});
}

bool RegistryTrust::install(const std::string& text, int64_t fetched_ms, const char* source) {
  auto set = node::parse_registry_jwks(text);
  if (!set.ok()) {
    failed("registry keys", set.error().message);
    svc_.record("REGISTRY_KEYS_REJECTED", "error")
        .by_system()
        .reason("malformed_jwks")
        .detail("registry", cfg_.registry_url)
        .detail("source", std::string(source))
        .detail("error", set.error().message)
        .write();
    return false;
  }
  auto doc = json::parse(text, {.max_depth = 8, .max_bytes = node::kMaxRegistryJwksBytes});
  const std::string canon = doc.ok() ? json::canonical(*doc) : text;
  std::vector<std::string> kids;
  for (const auto& k : set->keys) kids.push_back(k.kid());
  bool changed;
  {
    std::lock_guard<std::mutex> l(mu_);
    changed = canon != installed_;
    installed_ = canon;
    key_count_ = set->keys.size();
    kids_ = kids;
    keys_source_ = source;
  }
  if (changed) {
    svc_.auth.set_followed_issuer_keys(issuer_, std::move(set->keys));
    json::Array ids;
    for (const auto& k : kids) ids.emplace_back(k);
    svc_.record("REGISTRY_KEYS_UPDATED", "ok")
        .by_system()
        .detail("registry", cfg_.registry_url)
        .detail("issuer", issuer_)
        .detail("source", std::string(source))
        .detail("kids", json::Value(std::move(ids)))
        .detail("skipped", static_cast<int64_t>(set->skipped))
        .write();
  }
  fetched_ms_.store(std::max(fetched_ms_.load(), fetched_ms));
  return true;
}

bool RegistryTrust::fetch_jwks(int timeout_ms) {
  ++jwks_fetches_;
  auto u = parse_web_url(url("/.well-known/jwks.json"));
  if (!u.ok()) return failed("registry keys", u.error().message), ++jwks_failures_, false;
  HttpRequestOptions o;
  o.ca_file = cfg_.registry.ca_file;
  auto a = http_request("GET", *u, "", timeout_ms, o);
  std::string err = !a.ok()            ? a.error().message
                    : a->status != 200 ? "the registry answered " + std::to_string(a->status)
                                       : std::string();
  if (!err.empty()) return failed("registry keys", err), ++jwks_failures_, false;
  const int64_t now = svc_.clock.wall_ms();
  if (!install(a->body, now, "fetched")) {
    ++jwks_failures_;
    return false;
  }
  auto doc = json::parse(a->body, {.max_depth = 8, .max_bytes = node::kMaxRegistryJwksBytes});
  if (!doc.ok()) return true;  // install() parsed it: not reached
  json::Object cache{{"registry_url", cfg_.registry_url},
                     {"issuer", issuer_},
                     {"fetched_at_ms", now},
                     {"jwks", *doc}};
  {
    std::lock_guard<std::mutex> l(mu_);
    keys_error_.clear();
  }
  Status s = make_private_dir(dir_);
  if (s.ok()) s = write_state_file(dir_ + "/jwks.json", json::Value(std::move(cache)));
  if (!s.ok()) failed("registry keys cache", s.error().message);
  return true;
}

// <data-dir>/registry/revocations_cursor.json, when the cursor moved since it was last saved.
void RegistryTrust::save_cursor() {
  int64_t since;
  {
    std::lock_guard<std::mutex> l(mu_);
    if (since_ == saved_since_) return;
    since = since_;
  }
  Status s = make_private_dir(dir_);
  if (s.ok())
    s = write_state_file(
        dir_ + "/revocations_cursor.json",
        json::Value(json::Object{{"registry_url", cfg_.registry_url}, {"since", since}}));
  if (!s.ok()) return failed("registry revocations cursor", s.error().message);
  std::lock_guard<std::mutex> l(mu_);
  saved_since_ = since;
}

bool RegistryTrust::poll_revocations(int timeout_ms) {
  ++rev_polls_;
  HttpRequestOptions o;
  o.ca_file = cfg_.registry.ca_file;
  for (int page = 0; page < kMaxPagesPerPoll; ++page) {
    int64_t since;
    {
      std::lock_guard<std::mutex> l(mu_);
      since = since_;
    }
    auto u = parse_web_url(url("/api/v1/revocations?since=" + std::to_string(since)));
    if (!u.ok()) return failed("registry revocations", u.error().message), ++rev_failures_, false;
    auto a = http_request("GET", *u, "", timeout_ms, o);
    std::string err = !a.ok()            ? a.error().message
                      : a->status != 200 ? "the registry answered " + std::to_string(a->status)
                                         : std::string();
    if (!err.empty()) return failed("registry revocations", err), ++rev_failures_, false;
    auto p = node::parse_revocation_page(a->body, since);
    if (!p.ok()) return failed("registry revocations", p.error().message), ++rev_failures_, false;
    const int64_t now_ms = svc_.clock.wall_ms();
    for (const auto& e : p->entries) {
      node::Revocation r;
      r.kind = e.jti.empty() ? node::Revocation::Kind::kSubject : node::Revocation::Kind::kJti;
      r.iss = issuer_;
      r.value = e.jti.empty() ? e.sub : e.jti;
      if (!e.jti.empty()) r.exp = e.exp;
      r.at_ms = e.revoked_at_ms.value_or(now_ms);
      r.by = node::PrincipalId{issuer_, "registry"};
      r.reason = "registry revocation " + std::to_string(e.seq);
      r.feed = true;  // its own table: a flood of the feed never crowds out the OWNER's entries
      auto added = svc_.revocations.add(r, now_ms / 1000);  // persisted; closes its streams
      // A full feed table is not a fault to wait out: the entry is skipped, counted and
      // recorded, and the feed read on (a stalled cursor would stop every later revocation).
      const bool skipped = !added.ok() && added.error().reason == "revocation_feed_full";
      auto rec = svc_.record("TOKEN_REVOKED", added.ok() ? (*added ? "ok" : "unchanged")
                                              : skipped  ? "skipped"
                                                         : "failed");
      rec.by_system()
          .detail("source", "registry")
          .detail("registry_seq", e.seq)
          .detail("kind", std::string(node::revocation_kind_name(r.kind)))
          .detail("iss", issuer_);
      if (added.ok() || skipped)
        rec.detail(std::string(node::revocation_kind_name(r.kind)), r.value);
      if (skipped) rec.reason("revocation_feed_full");
      rec.write();
      if (skipped) {
        ++revocations_skipped_;
        log(LogLevel::kWarn, "registry_revocation_skipped",
            json::Object{{"seq", e.seq}, {"error", added.error().message}});
        std::lock_guard<std::mutex> l(mu_);
        since_ = e.seq;
        continue;
      }
      if (!added.ok()) {
        ++rev_failures_;
        save_cursor();  // what was applied before it stays applied
        return failed("registry revocations", added.error().message), false;
      }
      ++revocations_applied_;
      std::lock_guard<std::mutex> l(mu_);
      since_ = e.seq;
    }
    {
      std::lock_guard<std::mutex> l(mu_);
      since_ = std::max(since_, p->next_since);
      last_poll_ms_ = now_ms;
    }
    save_cursor();
    if (p->entries.size() < node::kRevocationPageSize) break;
  }
  std::lock_guard<std::mutex> l(mu_);
  if (revs_error_.rfind("registry revocations:", 0) == 0) revs_error_.clear();
  return true;
}

void RegistryTrust::prime(int timeout_ms) {
  if (auto c = read_state_file(dir_ + "/revocations_cursor.json"); c.ok()) {
    const json::Value* u = c->get("registry_url");
    const json::Value* s = c->get("since");
    if (u && u->is_string() && u->as_string() == cfg_.registry_url && s && s->is_int()) {
      std::lock_guard<std::mutex> l(mu_);
      since_ = saved_since_ = s->as_int();
    }
  }
  svc_.auth.on_unknown_followed_key(
      issuer_,
      [this](const std::string&, std::string_view token) {
        request_early_refresh();
        request_introspection(token);
      },
      [this](std::string_view token) { return introspected(token); });
  if (!fetch_jwks(timeout_ms)) {
    auto c = read_state_file(dir_ + "/jwks.json");
    const json::Value* u = c.ok() ? c->get("registry_url") : nullptr;
    const json::Value* i = c.ok() ? c->get("issuer") : nullptr;
    const json::Value* at = c.ok() ? c->get("fetched_at_ms") : nullptr;
    const json::Value* jwks = c.ok() ? c->get("jwks") : nullptr;
    if (u && u->is_string() && u->as_string() == cfg_.registry_url && i && i->is_string() &&
        i->as_string() == issuer_ && at && at->is_int() && jwks)
      install(json::dump(*jwks), at->as_int(), "cache");
  }
  svc_.registry_status = [this] { return status_json(); };
  auto& m = svc_.metrics;
  auto counter = [&m](const char* name, const char* help, const std::atomic<uint64_t>& v) {
    m.add_counter_fn(name, help, [&v] { return static_cast<double>(v.load()); });
  };
  counter("rcan_registry_jwks_fetches_total", "Fetches of the registry's keys.", jwks_fetches_);
  counter("rcan_registry_jwks_failures_total",
          "Fetches of the registry's keys that failed or were refused.", jwks_failures_);
  counter("rcan_registry_revocation_polls_total", "Polls of the registry's revocation feed.",
          rev_polls_);
  counter("rcan_registry_revocation_failures_total",
          "Polls of the registry's revocation feed that failed.", rev_failures_);
  counter("rcan_registry_revocations_applied_total",
          "Revocations from the registry added to the node's list.", revocations_applied_);
  counter("rcan_registry_revocations_skipped_total",
          "Revocations from the registry skipped: the feed's table was full.",
          revocations_skipped_);
  counter("rcan_registry_introspections_total", "Tokens the registry was asked about (RFC 7662).",
          introspections_);
  counter("rcan_registry_introspection_failures_total",
          "Introspection calls that failed (the token is refused for 30 s).",
          introspection_failures_);
  m.add_gauge("rcan_registry_keys", "Registry keys the node verifies tokens with.", [this] {
    std::lock_guard<std::mutex> l(mu_);
    return static_cast<double>(key_count_);
  });
}

void RegistryTrust::start() {
  thread_ = std::thread([this] { run(); });
}

void RegistryTrust::stop() {
  {
    std::lock_guard<std::mutex> l(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void RegistryTrust::request_early_refresh() {
  const int64_t now = svc_.clock.mono_ms();
  int64_t last = last_early_ms_.load();
  if (last != 0 && now - last < kEarlyRefreshEveryMs) return;
  if (!last_early_ms_.compare_exchange_strong(last, now)) return;  // another thread asked
  {
    std::lock_guard<std::mutex> l(mu_);
    early_ = true;
  }
  cv_.notify_all();
}

void RegistryTrust::request_introspection(std::string_view token) {
  {
    // Under mu_ (then answers_mu_): a token whose call is running, or whose answer was stored
    // just before that call ended, is not queued again — the registry is asked once.
    std::lock_guard<std::mutex> l(mu_);
    if (token == introspecting_) return;
    {
      std::lock_guard<std::mutex> a(answers_mu_);
      auto it = answers_.find(std::string(token));
      if (it != answers_.end() && it->second.until_ms > svc_.clock.wall_ms()) return;
    }
    if (to_introspect_.size() >= kMaxQueuedIntrospections) return;
    for (const auto& t : to_introspect_)
      if (t == token) return;
    to_introspect_.emplace_back(token);
  }
  cv_.notify_all();
}

std::optional<json::Object> RegistryTrust::introspected(std::string_view token) const {
  std::lock_guard<std::mutex> a(answers_mu_);
  auto it = answers_.find(std::string(token));
  if (it == answers_.end()) return std::nullopt;
  if (it->second.until_ms <= svc_.clock.wall_ms()) {
    answers_.erase(it);
    return std::nullopt;
  }
  return it->second.claims;
}

// RFC 7662: POST token=<jwt>, with the robot's own registry key. Any failure is cached as
// "inactive" for kInactiveAnswerMs, so an unverifiable token costs the registry one call.
void RegistryTrust::introspect(const std::string& token, int timeout_ms) {
  ++introspections_;
  const int64_t now = svc_.clock.wall_ms();
  Answer answer{std::nullopt, now + kInactiveAnswerMs};
  std::string err;
  auto state = read_state_file(dir_ + "/state.json");  // registry_join.h
  const json::Value* key = state.ok() ? state->get("robot_key") : nullptr;
  auto u = parse_web_url(url("/oauth/introspect"));
  if (!key || !key->is_string() || key->as_string().empty()) {
    err = "no robot key from the registry (registry.key_file, registration)";
  } else if (!u.ok()) {
    err = u.error().message;
  } else {
    HttpRequestOptions o;
    o.ca_file = cfg_.registry.ca_file;
    o.content_type = "application/x-www-form-urlencoded";
    o.headers.emplace_back("Authorization", "Bearer " + key->as_string());
    // A compact JWS is base64url and dots: nothing in it needs form encoding.
    auto a = http_request("POST", *u, "token=" + token, timeout_ms, o);
    if (!a.ok()) {
      err = a.error().message;
    } else if (a->status != 200) {
      err = node::registry_refusal(a->status, a->body);
    } else if (auto parsed = node::parse_introspection_answer(a->body, now, kActiveAnswerMs,
                                                              kInactiveAnswerMs);
               !parsed.ok()) {
      err = parsed.error().message;
    } else {
      answer = Answer{std::move(parsed->claims), parsed->until_ms};
    }
  }
  if (!err.empty()) {
    ++introspection_failures_;
    failed("registry introspection", err);
  }
  svc_.record("TOKEN_INTROSPECTED", err.empty() ? "ok" : "error")
      .by_system()
      .detail("registry", cfg_.registry_url)
      .detail("active", answer.claims.has_value())
      .detail("error", err.empty() ? json::Value() : json::Value(err))
      .write();
  std::lock_guard<std::mutex> a(answers_mu_);
  if (answers_.size() >= kMaxIntrospectionAnswers) {
    for (auto it = answers_.begin(); it != answers_.end();)
      it = it->second.until_ms <= now ? answers_.erase(it) : std::next(it);
    if (answers_.size() >= kMaxIntrospectionAnswers) answers_.erase(answers_.begin());
  }
  answers_[token] = std::move(answer);
}

void RegistryTrust::run() {
  using Clock = std::chrono::steady_clock;
  const auto keys_every = std::chrono::seconds(cfg_.registry.jwks_refresh_s);
  const auto revs_every = std::chrono::seconds(cfg_.registry.revocations_refresh_s);
  auto next_keys = Clock::now() + keys_every;
  auto next_revs = Clock::now();
  auto window_start = Clock::now();
  int window_calls = 0;
  std::unique_lock<std::mutex> l(mu_);
  while (!stopping_) {
    if (early_ || Clock::now() >= next_keys) {
      early_ = false;
      l.unlock();
      const bool ok = fetch_jwks(kCallTimeoutMs);
      l.lock();
      // A failed fetch is tried again sooner than the schedule (the keys are ageing).
      next_keys =
          Clock::now() +
          (ok ? keys_every : std::min<Clock::duration>(keys_every, std::chrono::seconds(30)));
      continue;
    }
    // Revocations before introspections: a flood of unverifiable tokens must not delay them.
    if (Clock::now() >= next_revs) {
      l.unlock();
      (void)poll_revocations(kCallTimeoutMs);
      l.lock();
      next_revs = Clock::now() + revs_every;
      continue;
    }
    if (!to_introspect_.empty()) {  // after an early fetch of the keys, which may settle it
      std::string token = std::move(to_introspect_.front());
      to_introspect_.pop_front();
      if (Clock::now() - window_start >= std::chrono::minutes(1)) {
        window_start = Clock::now();
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
    cv_.wait_until(l, std::min(next_keys, next_revs),
                   [this] { return stopping_ || early_ || !to_introspect_.empty(); });
  }
}

json::Value RegistryTrust::status_json() const {
  std::lock_guard<std::mutex> l(mu_);
  json::Array kids;
  for (const auto& k : kids_) kids.emplace_back(k);
  const int64_t at = fetched_ms_.load();
  return json::Object{
      {"registry_url", cfg_.registry_url},
      {"rrn", svc_.settings.rrn},
      {"issuer", issuer_},
      {"trust_tokens", true},
      {"jwks", json::Object{{"fetched_at_ms", at ? json::Value(at) : json::Value()},
                            {"fresh_until_ms",
                             at ? json::Value(at + int64_t{cfg_.registry.max_key_age_s} * 1000)
                                : json::Value()},
                            {"key_count", static_cast<int64_t>(key_count_)},
                            {"kids", std::move(kids)},
                            {"source", keys_source_}}},
      {"revocations",
       json::Object{{"since", since_},
                    {"last_poll_ms", last_poll_ms_ ? json::Value(last_poll_ms_) : json::Value()},
                    {"applied", static_cast<int64_t>(revocations_applied_.load())}}},
      {"last_error", !keys_error_.empty()   ? json::Value(keys_error_)
                     : !revs_error_.empty() ? json::Value(revs_error_)
                                            : json::Value()}};
}

}  // namespace rcan::rcand

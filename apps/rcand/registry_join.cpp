#include "registry_join.h"

#include <chrono>

#include "base/clock.h"
#include "identity.h"
#include "node/admission/registry_feed.h"
#include "rcan/crypto/registry_proof.h"
#include "rcan/encoding.h"
#include "rcan/errors.h"
#include "rcan/registry.h"
#include "runtime/http_client.h"
#include "runtime/log.h"
#include "runtime/state_file.h"

namespace rcan::rcand {
namespace {

constexpr int kTimeoutMs = 5000;

// <data-dir>/registry/state.json (0600): {"registry_url", "rrn", "robot_key"}.
std::string state_path(const std::string& data_dir) { return data_dir + "/registry/state.json"; }

Error link_error(const std::string& msg) { return Error(ErrorCode::kInternal, msg); }

std::string read_key_file(const std::string& path, std::string& err) {
  auto secret = keys::read_secret_file(path);
  if (!secret.ok()) {
    err = "registry.key_file: " + secret.error().message;
    return {};
  }
  std::string k(secret->view());
  while (!k.empty() && (k.back() == '\n' || k.back() == '\r' || k.back() == ' ')) k.pop_back();
  return k;
}

struct Exchange {
  const config::NodeConfig& cfg;
  int timeout_ms;

  Result<HttpAnswer> operator()(
      const std::string& method, const std::string& path, const std::string& body,
      const std::string& key, std::vector<std::pair<std::string, std::string>> headers = {}) const {
    std::string base = cfg.registry_url;
    while (!base.empty() && base.back() == '/') base.pop_back();
    auto u = parse_web_url(base + path);
    if (!u.ok()) return u.error();
    HttpRequestOptions o;
    o.ca_file = cfg.registry.ca_file;
    o.headers = std::move(headers);
    if (!key.empty()) o.headers.emplace_back("Authorization", "Bearer " + key);
    return http_request(method, *u, body, timeout_ms, o);
  }
};

// The registry's refusal, in one line: its error body's message when it sent one.
std::string refusal(const HttpAnswer& a) { return node::registry_refusal(a.status, a.body); }

// The endpoints this robot advertises.
json::Array endpoints(const config::NodeConfig& cfg) {
  json::Array eps;
  if (!cfg.registry.endpoint.empty()) eps.emplace_back(cfg.registry.endpoint);
  return eps;
}

// Whether the registry's record `rrn` holds `keys` (both public keys, as registered).
Status same_keys(const Exchange& call, const std::string& rrn, const keys::RobotKeys& keys) {
  auto got = call("GET", "/api/v1/robots/" + rrn, "", "");
  if (!got.ok()) return link_error("registration: reading " + rrn + ": " + got.error().message);
  if (got->status != 200) return link_error("registration: reading " + rrn + ": " + refusal(*got));
  auto rec = json::parse(got->body);
  if (!rec.ok() || !rec->is_object())
    return link_error("registration: the registry's record " + rrn + " is not a JSON object");
  if (json::string_field(*rec, "ed25519_public_key") != base64url_encode(keys.pub.ed25519_pk) ||
      json::string_field(*rec, "mldsa65_public_key") != base64url_encode(keys.pub.mldsa65_pk))
    return link_error("registration: the registry already holds this robot's names as " + rrn +
                      " with other keys: not adopted (someone registered them first; the "
                      "registry's admin must remove that record)");
  return Status::Ok();
}

}  // namespace

std::string stored_registry_rrn(const std::string& data_dir) {
  auto v = read_state_file(state_path(data_dir));
  if (!v.ok()) return {};
  auto rrn = registry::normalize_rrn(json::string_field(*v, "rrn"));
  return rrn ? *rrn : std::string();
}

Result<std::string> register_with_registry(const config::NodeConfig& cfg,
                                           const keys::RobotKeys& keys, int timeout_ms) {
  std::string err;
  const std::string key = read_key_file(cfg.registry.key_file, err);
  if (!err.empty()) return link_error(err);
  Exchange call{cfg, timeout_ms};
  auto ch = call("GET", "/api/v1/challenge", "", key);
  if (!ch.ok()) return link_error("registry challenge: " + ch.error().message);
  if (ch->status != 200) return link_error("registry challenge: " + refusal(*ch));
  auto challenge = node::parse_registry_challenge(ch->body);
  if (!challenge.ok()) return link_error("registry challenge: " + challenge.error().message);
  const std::string id = challenge->id, nonce = challenge->nonce;

  // The robot's names as the registry keys them: its RURI's segments (version "v1", the
  // SDKs' 5-segment form).
  const Ruri& r = cfg.ruri_parts;
  const std::string mfr = registry::slugify(r.manufacturer), model = registry::slugify(r.model),
                    version = registry::slugify(r.version.empty() ? "v1" : r.version),
                    device = registry::slugify(r.device_id);
  auto proof = registry::sign_proof(
      keys, id, registry::proof_message(id, nonce, mfr, model, version, device));
  if (!proof.ok()) return link_error("registry proof: " + proof.error().message);
  json::Object body{{"manufacturer", mfr},
                    {"model", model},
                    {"version", version},
                    {"device_id", device},
                    {"description", cfg.robot.name},
                    {"source", "rcand"},
                    // The robot's own RURI: the audience of the tokens the registry issues for it.
                    {"metadata", json::Object{{"ruri", cfg.ruri}}},
                    {"ed25519_public_key", base64url_encode(keys.pub.ed25519_pk)},
                    {"mldsa65_public_key", base64url_encode(keys.pub.mldsa65_pk)},
                    {"proof", proof->to_json()}};
  body.set("endpoints", json::Value(endpoints(cfg)));
  auto posted = call("POST", "/api/v1/robots", json::dump(json::Value(std::move(body))), key);
  if (!posted.ok()) return link_error("registration: " + posted.error().message);
  if (posted->status != 200 && posted->status != 201)
    return link_error("registration: " + refusal(*posted));
  auto answer = node::parse_registration_answer(posted->body);
  if (!answer.ok()) return link_error("registration: " + answer.error().message);
  // A record that was there before is this robot's only if it holds this robot's keys
  // (docs/THREATS.md T3): names registered first by someone else are not adopted.
  if (answer->robot_key.empty())
    if (Status s = same_keys(call, answer->rrn, keys); !s.ok()) return s.error();
  // The robot's own key comes once, with a new registration; a robot registered before (its
  // state lost) keeps refreshing with the registrant key.
  json::Object state{
      {"registry_url", cfg.registry_url}, {"rrn", answer->rrn}, {"robot_key", answer->robot_key}};
  if (Status s = make_private_dir(cfg.data_dir + "/registry"); !s.ok()) return s.error();
  if (Status s = write_state_file(state_path(cfg.data_dir), json::Value(std::move(state))); !s.ok())
    return s.error();
  return answer->rrn;
}

RegistryLink::RegistryLink(const config::NodeConfig& cfg, const keys::RobotKeys& keys,
                           audit::AuditLog& audit, std::string ruri)
    : cfg_(cfg), keys_(keys), audit_(audit), ruri_(std::move(ruri)) {}

RegistryLink::~RegistryLink() { stop(); }

void RegistryLink::start() {
  thread_ = std::thread([this] { run(); });
}

void RegistryLink::stop() {
  {
    std::lock_guard<std::mutex> l(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

std::string RegistryLink::last_result() const {
  std::lock_guard<std::mutex> l(mu_);
  return last_;
}

void RegistryLink::record(const std::string& event, const std::string& outcome,
                          const std::string& detail) {
  {
    std::lock_guard<std::mutex> l(mu_);
    last_ = detail;
  }
  audit::AuditEntry e;
  e.principal = "node";
  e.message_id = new_uuid_v4();
  e.ruri = ruri_;
  e.event = event;
  e.outcome = outcome;
  e.sender_type = "system";
  e.detail.set("registry", cfg_.registry_url);
  e.detail.set("result", detail);
  (void)audit_.append(std::move(e));
}

bool RegistryLink::refresh(const std::string& rrn) {
  auto v = read_state_file(state_path(cfg_.data_dir));
  std::string key = v.ok() ? json::string_field(*v, "robot_key") : std::string();
  std::string err;
  if (key.empty()) key = read_key_file(cfg_.registry.key_file, err);
  if (!err.empty()) {
    log(LogLevel::kWarn, "registry_refresh_failed", json::Object{{"error", err}});
    return false;
  }
  json::Object fields;
  fields.set("endpoints", json::Value(endpoints(cfg_)));
  const std::string body = json::dump(json::Value(std::move(fields)));
  // Signed with the identity key the registration proved (the registry refuses a robot's
  // unsigned update once it holds its keys).
  const int64_t ts = unix_ms();
  auto sig = registry::sign_update(keys_, registry::update_message(rrn, ts, body));
  if (!sig.ok()) {
    log(LogLevel::kWarn, "registry_refresh_failed", json::Object{{"error", sig.error().message}});
    return false;
  }
  auto a = Exchange{cfg_, kTimeoutMs}(
      "PATCH", "/api/v1/robots/" + rrn, body, key,
      {{"X-RCAN-Timestamp", std::to_string(ts)}, {"X-RCAN-Signature", *sig}});
  const std::string why =
      !a.ok() ? a.error().message : (a->status == 200 ? std::string() : refusal(*a));
  std::lock_guard<std::mutex> l(mu_);
  last_ = why.empty() ? "refreshed" : why;
  if (!why.empty())
    log(LogLevel::kWarn, "registry_refresh_failed", json::Object{{"rrn", rrn}, {"error", why}});
  return why.empty();
}

void RegistryLink::run() {
  int64_t backoff_s = 5;
  while (true) {
    std::string rrn = stored_registry_rrn(cfg_.data_dir);
    int64_t wait_s = cfg_.registry.refresh_s;
    if (rrn.empty() && cfg_.registry.register_at_start) {
      auto r = register_with_registry(cfg_, keys_, kTimeoutMs);
      if (r.ok()) {
        record("REGISTRY_REGISTERED", "ok", *r);
        log(LogLevel::kInfo, "registry_registered",
            json::Object{{"rrn", *r}, {"note", "the node adopts this RRN at its next start"}});
        backoff_s = 5;
      } else {
        log(LogLevel::kWarn, "registry_registration_failed",
            json::Object{{"error", r.error().message}, {"retry_s", backoff_s}});
        {
          std::lock_guard<std::mutex> l(mu_);
          last_ = r.error().message;
        }
        wait_s = backoff_s;
        backoff_s = std::min<int64_t>(backoff_s * 2, cfg_.registry.refresh_s);
      }
    } else if (!rrn.empty()) {
      (void)refresh(rrn);
    }
    std::unique_lock<std::mutex> l(mu_);
    if (cv_.wait_for(l, std::chrono::seconds(wait_s), [this] { return stopping_; })) return;
  }
}

}  // namespace rcan::rcand

#include "rcan/audit/record.h"

#include <cmath>
#include <cstdio>

#include "rcan/encoding.h"
#include "rcan/hash.h"

namespace rcan::audit {
namespace {

Error field_error(const std::string& field, const std::string& why) {
  return Error(ErrorCode::kSchemaValidationFailed, "audit entry: " + field + " " + why, field);
}

}  // namespace

Status validate(const AuditEntry& e) {
  if (e.principal.empty()) return field_error("principal", "is required");
  if (e.ruri.empty()) return field_error("ruri", "is required");
  if (e.message_id.empty()) return field_error("message_id", "is required");
  if (e.event.empty()) return field_error("event", "is required");
  if (e.outcome.empty()) return field_error("outcome", "is required");
  if (e.timestamp_ms < 0) return field_error("timestamp_ms", "is negative");
  if (e.sender_type != "human" && e.sender_type != "robot" && e.sender_type != "cloud_function" &&
      e.sender_type != "system")
    return field_error("sender_type", "must be human, robot, cloud_function or system");
  if (e.sender_type == "cloud_function") {
    if (!e.cloud_provider || e.cloud_provider->empty())
      return field_error("cloud_provider", "is required for sender_type cloud_function");
    if (!e.function_name || e.function_name->empty())
      return field_error("function_name", "is required for sender_type cloud_function");
  }
  if (e.ai) {
    if (e.ai->provider.empty()) return field_error("ai.provider", "is required in an ai block");
    if (e.ai->model.empty()) return field_error("ai.model", "is required in an ai block");
    if (e.ai->confidence &&
        (!std::isfinite(*e.ai->confidence) || *e.ai->confidence < 0.0 || *e.ai->confidence > 1.0))
      return field_error("ai.confidence", "must be a number in [0, 1]");
    if (e.ai->inference_latency_ms && !std::isfinite(*e.ai->inference_latency_ms))
      return field_error("ai.inference_latency_ms", "must be finite");
  }
  for (const auto* k : {"seq", "prev_hash", "hmac"}) {
    if (e.detail.contains(k)) return field_error(std::string("detail.") + k, "is reserved");
  }
  return Status::Ok();
}

json::Object to_object(const AiBlock& a) {
  json::Object ai;
  ai.set("provider", a.provider);
  ai.set("model", a.model);
  if (a.model_version) ai.set("model_version", *a.model_version);
  if (a.layer) ai.set("layer", *a.layer);
  if (a.confidence) ai.set("confidence", *a.confidence);
  if (a.inference_latency_ms) ai.set("inference_latency_ms", *a.inference_latency_ms);
  if (a.thought_id) ai.set("thought_id", *a.thought_id);
  ai.set("escalated", a.escalated);
  return ai;
}

json::Object to_object(const AuditEntry& e) {
  json::Object o;
  o.set("principal", e.principal);
  o.set("ruri", e.ruri);
  o.set("timestamp_ms", e.timestamp_ms);
  o.set("message_id", e.message_id);
  o.set("event", e.event);
  o.set("outcome", e.outcome);
  o.set("sender_type", e.sender_type);
  if (e.sub) o.set("sub", *e.sub);
  if (e.cloud_provider) o.set("cloud_provider", *e.cloud_provider);
  if (e.function_name) o.set("function_name", *e.function_name);
  if (e.ai) o.set("ai", to_object(*e.ai));
  if (e.gate_bypassed) o.set("gate_bypassed", true);
  if (e.hitl_timeout_bypass) o.set("hitl_timeout_bypass", true);
  if (e.watermark_token) o.set("watermark_token", *e.watermark_token);
  if (e.action) o.set("action", *e.action);
  if (e.reason) o.set("reason", *e.reason);
  if (!e.detail.empty()) o.set("detail", e.detail);
  if (!e.kind.empty()) o.set("kind", e.kind);
  if (e.segment) o.set("segment", static_cast<int64_t>(*e.segment));
  return o;
}

namespace {

Error bad_member(const std::string& name, const char* what) {
  return Error(ErrorCode::kSchemaValidationFailed, name + " must be " + what, name);
}

// Reads member `k` of `o` into `out` when present; an error when it has the wrong type.
Status read_string(const json::Object& o, const char* k, std::string& out) {
  const json::Value* v = o.find(k);
  if (!v) return Status::Ok();
  if (!v->is_string()) return bad_member(k, "a string");
  out = v->as_string();
  return Status::Ok();
}

Status read_string(const json::Object& o, const char* k, std::optional<std::string>& out) {
  const json::Value* v = o.find(k);
  if (!v || v->is_null()) return Status::Ok();
  if (!v->is_string()) return bad_member(k, "a string");
  out = v->as_string();
  return Status::Ok();
}

Status read_number(const json::Object& o, const char* k, std::optional<double>& out) {
  const json::Value* v = o.find(k);
  if (!v || v->is_null()) return Status::Ok();
  if (!v->is_number() || !std::isfinite(v->to_double())) return bad_member(k, "a number");
  out = v->to_double();
  return Status::Ok();
}

Status read_bool(const json::Object& o, const char* k, bool& out) {
  const json::Value* v = o.find(k);
  if (!v) return Status::Ok();
  if (!v->is_bool()) return bad_member(k, "true or false");
  out = v->as_bool();
  return Status::Ok();
}

Result<AiBlock> ai_from_object(const json::Object& o) {
  AiBlock a;
  for (Status s :
       {read_string(o, "provider", a.provider), read_string(o, "model", a.model),
        read_string(o, "model_version", a.model_version), read_string(o, "layer", a.layer),
        read_number(o, "confidence", a.confidence),
        read_number(o, "inference_latency_ms", a.inference_latency_ms),
        read_string(o, "thought_id", a.thought_id), read_bool(o, "escalated", a.escalated)})
    if (!s.ok()) return Error(s.error().code, "ai." + s.error().message, "ai." + s.error().field);
  return a;
}

}  // namespace

Result<AuditEntry> entry_from_object(const json::Object& o) {
  AuditEntry e;
  for (Status s :
       {read_string(o, "principal", e.principal), read_string(o, "ruri", e.ruri),
        read_string(o, "message_id", e.message_id), read_string(o, "event", e.event),
        read_string(o, "outcome", e.outcome), read_string(o, "sender_type", e.sender_type),
        read_string(o, "sub", e.sub), read_string(o, "cloud_provider", e.cloud_provider),
        read_string(o, "function_name", e.function_name),
        read_bool(o, "gate_bypassed", e.gate_bypassed),
        read_bool(o, "hitl_timeout_bypass", e.hitl_timeout_bypass),
        read_string(o, "watermark_token", e.watermark_token), read_string(o, "action", e.action),
        read_string(o, "reason", e.reason), read_string(o, "kind", e.kind)})
    if (!s.ok()) return s.error();
  if (const json::Value* t = o.find("timestamp_ms")) {
    if (!t->is_int() || t->as_int() < 0)
      return bad_member("timestamp_ms", "a non-negative integer");
    e.timestamp_ms = t->as_int();
  }
  if (const json::Value* a = o.find("ai"); a && !a->is_null()) {
    if (!a->is_object()) return bad_member("ai", "an object");
    auto ai = ai_from_object(a->as_object());
    if (!ai.ok()) return ai.error();
    e.ai = std::move(*ai);
  }
  if (const json::Value* d = o.find("detail")) {
    if (!d->is_object()) return bad_member("detail", "an object");
    e.detail = d->as_object();
  }
  if (const json::Value* g = o.find("segment")) {
    if (!g->is_int() || g->as_int() < 0) return bad_member("segment", "a non-negative integer");
    e.segment = static_cast<uint64_t>(g->as_int());
  }
  if (Status s = validate(e); !s.ok()) return s.error();
  return e;
}

SealedRecord seal(json::Object obj, uint64_t seq, std::string_view prev_hash,
                  std::string_view secret) {
  SealedRecord r;
  r.seq = seq;
  obj.set("seq", static_cast<int64_t>(seq));
  if (prev_hash.empty()) {
    obj.set("prev_hash", nullptr);
  } else {
    obj.set("prev_hash", std::string(prev_hash));
  }
  r.preimage = json::canonical(json::Value(obj));
  r.record_hash = sha256_hex(r.preimage);
  r.hmac = hmac_sha256_hex(secret, r.preimage);
  obj.set("hmac", r.hmac);
  r.line = json::canonical(json::Value(std::move(obj)));
  return r;
}

RecordCheck check_record(const json::Object& rec, std::string_view secret) {
  RecordCheck c;
  c.preimage = json::canonical_without(rec, "hmac");
  c.record_hash = sha256_hex(c.preimage);
  const json::Value* h = rec.find("hmac");
  if (h && h->is_string()) {
    c.hmac_present = true;
    c.hmac_ok = constant_time_equal(hmac_sha256_hex(secret, c.preimage), h->as_string());
  }
  return c;
}

std::string new_uuid() {
  uint8_t b[16] = {};
  if (!random_bytes(b, sizeof b)) {
    // Extremely unlikely; fall back to a time-derived value rather than failing an audit.
    static uint64_t counter = 0;
    uint64_t v = ++counter;
    for (int i = 0; i < 8; ++i) b[i] = static_cast<uint8_t>(v >> (8 * i));
  }
  b[6] = static_cast<uint8_t>((b[6] & 0x0f) | 0x40);
  b[8] = static_cast<uint8_t>((b[8] & 0x3f) | 0x80);
  std::string h = to_hex(b, sizeof b);
  return h.substr(0, 8) + "-" + h.substr(8, 4) + "-" + h.substr(12, 4) + "-" + h.substr(16, 4) +
         "-" + h.substr(20);
}

}  // namespace rcan::audit

#include "node/ai/hitl.h"

#include <algorithm>
#include <cctype>
#include <cstdio>

#include "base/strings.h"
#include "rcan/errors.h"
#include "rcan/message.h"

namespace rcan::node {
namespace {

Error schema(const std::string& field, const std::string& msg, const std::string& reason = {}) {
  return Error(ErrorCode::kSchemaValidationFailed, msg, field, reason);
}

json::Array strings(const std::vector<std::string>& v) {
  json::Array a;
  for (const auto& s : v) a.emplace_back(s);
  return a;
}

std::vector<std::string> strings_of(const json::Value* v) {
  std::vector<std::string> out;
  if (v && v->is_array())
    for (const auto& e : v->as_array())
      if (e.is_string()) out.push_back(e.as_string());
  return out;
}

}  // namespace

json::Value PendingItem::to_json() const {
  json::Array roles;
  for (Role r : authorized_roles) roles.emplace_back(std::string(role_name(r)));
  json::Object s{{"sender_type", std::string(sender_type_name(sender.sender_type))},
                 {"sub", sender.sub},
                 {"cloud_provider", sender.cloud_provider},
                 {"function_name", sender.function_name},
                 {"function_region", sender.function_region}};
  json::Object o{{"message_id", message_id},
                 {"action_type", action_type},
                 {"description", description},
                 {"auth_timeout_ms", static_cast<int64_t>(auth_timeout_ms)},
                 {"created_ms", created_ms},
                 {"expires_at_ms", expires_at_ms},
                 {"on_timeout", allow_on_timeout ? "allow" : "block"},
                 {"authorized_roles", roles},
                 {"notify", strings(notify)},
                 {"message", message},
                 {"issuer", issuer},
                 {"sub", sub},
                 {"role", std::string(role_name(role))},
                 {"scopes", strings(scopes)},
                 {"sender", s},
                 {"transport", transport},
                 {"route", route},
                 {"audit_detail", audit_detail},
                 {"gate_bypassed", gate_bypassed},
                 {"thought_id", thought_id},
                 {"model", model}};
  if (confidence) o.set("confidence", *confidence);
  return o;
}

Result<PendingItem> PendingItem::from_json(const json::Value& v) {
  if (!v.is_object()) return schema("pending", "a pending item must be an object");
  PendingItem p;
  p.message_id = json::string_field(v, "message_id");
  if (p.message_id.empty()) return schema("message_id", "message_id is required");
  p.action_type = json::string_field(v, "action_type");
  p.description = json::string_field(v, "description");
  p.auth_timeout_ms = static_cast<uint32_t>(
      std::clamp<int64_t>(json::int_field(v, "auth_timeout_ms"), 1, 86'400'000));
  p.created_ms = json::int_field(v, "created_ms");
  p.expires_at_ms = json::int_field(v, "expires_at_ms");
  p.allow_on_timeout = json::string_field(v, "on_timeout") == "allow";
  p.authorized_roles.clear();
  for (const auto& r : strings_of(v.get("authorized_roles")))
    if (auto role = role_from_name(r); role && (*role == Role::kOwner || *role == Role::kCreator))
      p.authorized_roles.push_back(*role);
  if (p.authorized_roles.empty()) p.authorized_roles = {Role::kOwner, Role::kCreator};
  p.notify = strings_of(v.get("notify"));
  const json::Value* m = v.get("message");
  if (!m || !m->is_object()) return schema("message", "message is required");
  p.message = *m;
  p.issuer = json::string_field(v, "issuer");
  p.sub = json::string_field(v, "sub");
  auto role = role_from_name(json::string_field(v, "role"));
  if (!role) return schema("role", "role is required");
  p.role = *role;
  p.scopes = strings_of(v.get("scopes"));
  if (const json::Value* s = v.get("sender"); s && s->is_object()) {
    if (auto st = sender_type_from_name(json::string_field(*s, "sender_type")))
      p.sender.sender_type = *st;
    p.sender.sub = json::string_field(*s, "sub");
    p.sender.cloud_provider = json::string_field(*s, "cloud_provider");
    p.sender.function_name = json::string_field(*s, "function_name");
    p.sender.function_region = json::string_field(*s, "function_region");
  }
  p.transport = json::string_field(v, "transport");
  p.route = json::string_field(v, "route");
  if (const json::Value* d = v.get("audit_detail"); d && d->is_object())
    p.audit_detail = d->as_object();
  if (const json::Value* g = v.get("gate_bypassed"); g && g->is_bool())
    p.gate_bypassed = g->as_bool();
  p.thought_id = json::string_field(v, "thought_id");
  p.model = json::string_field(v, "model");
  if (const json::Value* c = v.get("confidence"); c && c->is_number())
    p.confidence = c->to_double();
  return p;
}

json::Object PendingItem::public_view(int64_t now_ms) const {
  json::Object o{{"message_id", message_id},
                 {"pending_id", message_id},
                 {"ref_message_id", message_id},
                 {"action_type", action_type},
                 {"description", description},
                 {"auth_timeout_ms", static_cast<int64_t>(auth_timeout_ms)},
                 {"timeout_remaining_ms", std::max<int64_t>(0, expires_at_ms - now_ms)},
                 {"expires_at_ms", expires_at_ms},
                 {"created_ms", created_ms},
                 {"on_timeout", allow_on_timeout ? "allow" : "block"},
                 {"requested_by", sub},
                 {"requested_by_iss", issuer},
                 {"requested_role", std::string(role_name(role))},
                 {"requires_auth_from_role", 4},
                 {"thought_id", thought_id.empty() ? message_id : thought_id},
                 {"model_id", model},
                 {"queue_status", "pending_authorization"}};
  o.set("confidence", confidence ? json::Value(*confidence) : json::Value());
  if (const json::Value* p = message.get("payload"); p) {
    json::Value cmd = *p;
    if (cmd.is_object()) cmd.as_object().erase("thought");
    o.set("original_command", cmd);
  }
  return o;
}

Status save_pending(const std::string& path, const std::vector<PendingItem>& items,
                    base::Env* env) {
  json::Array arr;
  for (const auto& i : items) arr.push_back(i.to_json());
  std::string text = json::dump(json::Value(json::Object{{"version", 1}, {"pending", arr}})) + "\n";
  if (!env) env = base::Env::posix();
  base::IoStatus s = env->write_file_atomic(path, text);
  if (!s.ok()) return Error(ErrorCode::kInternal, s.error().message);
  return Status::Ok();
}

Result<std::vector<PendingItem>> load_pending(const std::string& path, size_t* skipped) {
  std::vector<PendingItem> out;
  if (skipped) *skipped = 0;
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return out;
  std::string text;
  char buf[8192];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0 && text.size() < (64u << 20))
    text.append(buf, n);
  std::fclose(f);
  auto v = json::parse(text, {.max_depth = 64, .max_bytes = 64u << 20});
  if (!v.ok())
    return Error(ErrorCode::kInternal,
                 "the pending file " + path + " is not JSON: " + v.error().message);
  const json::Value* arr = v->get("pending");
  if (!arr || !arr->is_array())
    return Error(ErrorCode::kInternal, "the pending file " + path + " has no pending list");
  for (const auto& e : arr->as_array()) {
    auto p = PendingItem::from_json(e);
    if (p.ok())
      out.push_back(std::move(p).value());
    else if (skipped)
      ++*skipped;
  }
  return out;
}

Result<AuthorizeRequest> parse_authorize(const json::Value& body) {
  if (!body.is_object()) return schema("", "an AUTHORIZE must be a JSON object");
  AuthorizeRequest r;
  if (const json::Value* t = body.get("type"); t && !t->is_null()) {
    if (!t->is_string() || t->as_string() != "AUTHORIZE")
      return schema("type", "type must be AUTHORIZE");
  }
  if (const json::Value* id = body.get("message_id"); id && id->is_string())
    r.authorize_id = id->as_string();
  const json::Value* payload = body.get("payload");
  if (payload && !payload->is_object()) return schema("payload", "payload must be an object");
  const json::Value& p = payload ? *payload : body;
  for (const char* k : {"ref_message_id", "pending_id", "message_id", "thought_id"}) {
    if (!payload && std::string_view(k) == "message_id")
      continue;  // flat form: message_id is the target
    const json::Value* v = p.get(k);
    if (v && v->is_string() && !v->as_string().empty()) {
      r.target = v->as_string();
      break;
    }
  }
  if (!payload && r.target.empty()) {
    r.target = r.authorize_id;
    r.authorize_id.clear();
  }
  if (r.target.empty() || r.target.size() > 128)
    return schema("payload.message_id", "the held command's message_id is required",
                  "missing_field");
  const json::Value* d = p.get("decision");
  if (!d || !d->is_string())
    return schema("payload.decision", "decision is required (approve or deny)", "missing_field");
  std::string dec = ascii_lower(d->as_string());
  if (dec == "approve" || dec == "approved")
    r.approve = true;
  else if (dec == "deny" || dec == "denied" || dec == "reject" || dec == "rejected")
    r.approve = false;
  else
    return schema("payload.decision", "decision must be approve or deny");
  if (const json::Value* rs = p.get("reason"); rs && !rs->is_null()) {
    if (!rs->is_string()) return schema("payload.reason", "reason must be a string");
    r.reason = rs->as_string().substr(0, 512);
  }
  if (r.authorize_id.empty() || r.authorize_id.size() > 128) r.authorize_id = new_uuid_v4();
  return r;
}

}  // namespace rcan::node

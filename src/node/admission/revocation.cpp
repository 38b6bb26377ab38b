#include "node/admission/revocation.h"

#include <algorithm>

#include "base/state_file.h"
#include "rcan/errors.h"

namespace rcan::node {
namespace {

Error bad(const std::string& msg, const std::string& field) {
  return Error(ErrorCode::kSchemaValidationFailed, msg, field);
}

// A string field: absent → "", else a string of at most kMaxFieldBytes.
Result<std::string> text(const json::Value& v, const char* name) {
  const json::Value* f = v.get(name);
  if (!f || f->is_null()) return std::string();
  if (!f->is_string()) return bad(std::string(name) + " must be a string", name);
  if (f->as_string().size() > RevocationList::kMaxFieldBytes)
    return bad(std::string(name) + " is longer than 512 bytes", name);
  return f->as_string();
}

std::string index_key(Revocation::Kind k, std::string_view iss, std::string_view value) {
  std::string s(revocation_kind_name(k));
  s += '\x1f';
  s += iss;
  s += '\x1f';
  s += value;
  return s;
}

bool expired(const Revocation& r, int64_t now_s, int64_t leeway_s) {
  return r.kind == Revocation::Kind::kJti && r.exp && now_s >= *r.exp + leeway_s;
}

}  // namespace

std::string_view revocation_kind_name(Revocation::Kind k) {
  switch (k) {
    case Revocation::Kind::kJti:
      return "jti";
    case Revocation::Kind::kSubject:
      return "sub";
    case Revocation::Kind::kKid:
      return "kid";
  }
  return "jti";
}

json::Value Revocation::to_json() const {
  json::Object o{{"kind", std::string(revocation_kind_name(kind))}};
  o.set(std::string(revocation_kind_name(kind)), value);
  if (!iss.empty()) o.set("iss", iss);
  if (exp) o.set("exp", *exp);
  o.set("at_ms", at_ms);
  o.set("by", json::Object{{"iss", by.iss}, {"sub", by.sub}});
  if (!reason.empty()) o.set("reason", reason);
  return json::Value(std::move(o));
}

Result<Revocation> Revocation::from_json(const json::Value& v) {
  if (!v.is_object()) return bad("a revocation must be a JSON object", "revocations");
  Revocation r;
  auto kind = text(v, "kind");
  if (!kind.ok()) return kind.error();
  if (*kind == "jti") {
    r.kind = Kind::kJti;
  } else if (*kind == "sub") {
    r.kind = Kind::kSubject;
  } else if (*kind == "kid") {
    r.kind = Kind::kKid;
  } else {
    return bad("kind must be jti, sub or kid", "kind");
  }
  auto value = text(v, kind->c_str());
  if (!value.ok()) return value.error();
  if (value->empty()) return bad(*kind + " is missing", *kind);
  r.value = std::move(*value);
  auto iss = text(v, "iss");
  if (!iss.ok()) return iss.error();
  r.iss = std::move(*iss);
  if (const json::Value* e = v.get("exp"); e && !e->is_null()) {
    if (!e->is_int()) return bad("exp must be an integer (unix seconds)", "exp");
    r.exp = e->as_int();
  }
  if (const json::Value* a = v.get("at_ms"); a && !a->is_null()) {
    if (!a->is_int()) return bad("at_ms must be an integer", "at_ms");
    r.at_ms = a->as_int();
  }
  if (const json::Value* by = v.get("by"); by && !by->is_null()) {
    if (!by->is_object()) return bad("by must be an object {iss, sub}", "by");
    auto bi = text(*by, "iss");
    auto bs = text(*by, "sub");
    if (!bi.ok()) return bi.error();
    if (!bs.ok()) return bs.error();
    r.by = PrincipalId{std::move(*bi), std::move(*bs)};
  }
  auto reason = text(v, "reason");
  if (!reason.ok()) return reason.error();
  r.reason = std::move(*reason);
  return r;
}

RevocationList::RevocationList(std::string path, size_t capacity, int64_t leeway_s, audit::Env* env)
    : path_(std::move(path)),
      capacity_(capacity),
      leeway_s_(std::max<int64_t>(0, leeway_s)),
      env_(env) {}

Result<std::vector<Revocation>> RevocationList::parse(const json::Value& doc, size_t capacity) {
  if (!doc.is_object()) return bad("not a JSON object", "");
  const json::Value* ver = doc.get("version");
  if (!ver || !ver->is_int() || ver->as_int() != 1) return bad("version must be 1", "version");
  const json::Value* list = doc.get("revocations");
  if (!list || !list->is_array()) return bad("revocations must be an array", "revocations");
  if (list->as_array().size() > capacity)
    return bad("holds " + std::to_string(list->as_array().size()) + " entries, more than " +
                   std::to_string(capacity),
               "revocations");
  std::vector<Revocation> out;
  out.reserve(list->as_array().size());
  size_t i = 0;
  for (const json::Value& e : list->as_array()) {
    auto r = Revocation::from_json(e);
    if (!r.ok()) {
      Error err = r.error();
      err.message = "entry " + std::to_string(i) + ": " + err.message;
      return err;
    }
    out.push_back(std::move(r).value());
    ++i;
  }
  return out;
}

Status RevocationList::load(int64_t now_s) {
  if (path_.empty()) return Status::Ok();
  MutexLock w(write_mu_);
  auto doc = read_state_file(path_);
  if (!doc.ok()) {
    if (doc.error().code == ErrorCode::kNotFound) return Status::Ok();
    return bad("the revocation list " + path_ + " is not a JSON object; move it away only if " +
                   "you accept that the tokens it revoked are valid again",
               path_);
  }
  auto entries = parse(*doc, capacity_);
  if (!entries.ok())
    return bad("the revocation list " + path_ + " is unreadable: " + entries.error().message,
               path_);
  std::erase_if(*entries, [&](const Revocation& r) { return expired(r, now_s, leeway_s_); });
  install(std::move(*entries));
  return Status::Ok();
}

void RevocationList::install(std::vector<Revocation> entries) {
  std::unordered_map<std::string, int64_t> index;
  for (const Revocation& r : entries) {
    int64_t at_s = r.at_ms / 1000;
    auto [it, fresh] = index.emplace(index_key(r.kind, r.iss, r.value), at_s);
    if (!fresh) it->second = std::max(it->second, at_s);
  }
  MutexLock lock(mu_);
  entries_ = std::move(entries);
  index_ = std::move(index);
}

std::vector<Revocation> RevocationList::pruned(int64_t now_s) const {
  std::vector<Revocation> out = list();
  std::erase_if(out, [&](const Revocation& r) { return expired(r, now_s, leeway_s_); });
  return out;
}

Result<bool> RevocationList::add(Revocation r, int64_t now_s) {
  if (r.value.empty()) return bad("nothing to revoke", "");
  if (expired(r, now_s, leeway_s_)) return false;  // the token is refused as expired anyway
  Revocation copy = r;
  {
    MutexLock w(write_mu_);
    std::vector<Revocation> next = pruned(now_s);
    for (const Revocation& e : next) {
      if (e.kind != r.kind || e.iss != r.iss || e.value != r.value) continue;
      if (r.kind == Revocation::Kind::kJti || r.kind == Revocation::Kind::kKid) return false;
    }
    if (next.size() >= capacity_)
      return Error(ErrorCode::kCommandRejected,
                   "the revocation list is full (" + std::to_string(capacity_) +
                       " entries in force); revoke by sub or kid instead",
                   "", "revocation_list_full");
    next.push_back(std::move(r));
    if (!path_.empty()) {
      json::Array arr;
      for (const Revocation& e : next) arr.push_back(e.to_json());
      json::Value doc(json::Object{{"version", 1}, {"revocations", std::move(arr)}});
      if (Status s = write_state_file(path_, doc, env_); !s.ok())
        return Error(ErrorCode::kInternal,
                     "the revocation could not be recorded: " + s.error().message);
    }
    install(std::move(next));
  }
  std::vector<Listener> fns;
  {
    MutexLock lock(lmu_);
    for (auto& [id, fn] : listeners_) fns.push_back(fn);
  }
  for (auto& fn : fns) fn(copy);
  return true;
}

const int64_t* RevocationList::find_locked(Revocation::Kind k, std::string_view iss,
                                           std::string_view value) const {
  if (value.empty()) return nullptr;
  // The entry for this issuer first, then the one for any issuer.
  for (std::string_view i : {iss, std::string_view()}) {
    auto it = index_.find(index_key(k, i, value));
    if (it != index_.end()) return &it->second;
    if (iss.empty()) break;
  }
  return nullptr;
}

std::optional<std::string> RevocationList::revoked(const Principal& p) const {
  if (!p.authenticated) return std::nullopt;
  MutexLock lock(mu_);
  if (index_.empty()) return std::nullopt;
  if (find_locked(Revocation::Kind::kJti, p.issuer, p.jti)) return "jti";
  if (find_locked(Revocation::Kind::kKid, p.issuer, p.kid)) return "kid";
  // By subject: the tokens issued at or before the revocation's second (or without iat).
  for (std::string_view iss : {std::string_view(p.issuer), std::string_view()}) {
    const int64_t* at_s = find_locked(Revocation::Kind::kSubject, iss, p.sub);
    if (at_s && (!p.token_iat || *p.token_iat <= *at_s)) return "sub";
  }
  return std::nullopt;
}

std::vector<Revocation> RevocationList::list() const {
  MutexLock lock(mu_);
  return entries_;
}

size_t RevocationList::size() const {
  MutexLock lock(mu_);
  return entries_.size();
}

uint64_t RevocationList::subscribe(Listener fn) {
  MutexLock lock(lmu_);
  listeners_[++next_listener_] = std::move(fn);
  return next_listener_;
}

void RevocationList::unsubscribe(uint64_t id) {
  MutexLock lock(lmu_);
  listeners_.erase(id);
}

}  // namespace rcan::node

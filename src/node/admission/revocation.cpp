#include "node/admission/revocation.h"

#include <algorithm>

#include "rcan/errors.h"
#include "runtime/log.h"
#include "runtime/state_file.h"

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
  if (feed) o.set("source", "feed");
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
  auto source = text(v, "source");
  if (!source.ok()) return source.error();
  if (!source->empty() && *source != "feed") return bad("source must be feed or absent", "source");
  r.feed = *source == "feed";
  return r;
}

RevocationList::RevocationList(std::string path, size_t capacity, int64_t leeway_s, base::Env* env,
                               size_t feed_capacity)
    : path_(std::move(path)),
      capacity_(capacity),
      leeway_s_(std::max<int64_t>(0, leeway_s)),
      env_(env != nullptr ? env : base::Env::posix()),
      feed_capacity_(feed_capacity) {}

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

Result<std::vector<Revocation>> RevocationList::read_journal() const {
  std::vector<Revocation> out;
  const std::string jpath = journal_path();
  if (!env_->exists(jpath)) return out;
  auto text_r = env_->read_file(jpath);
  if (!text_r.ok())
    return bad("the revocation journal " + jpath + ": " + text_r.error().message, jpath);
  std::string_view rest(*text_r);
  size_t line_no = 0;
  while (!rest.empty()) {
    const size_t nl = rest.find('\n');
    if (nl == std::string_view::npos) break;  // a torn last line: its append never returned
    std::string_view line = rest.substr(0, nl);
    rest.remove_prefix(nl + 1);
    ++line_no;
    auto v = json::parse(line);
    auto r = v.ok() ? Revocation::from_json(*v) : Result<Revocation>(v.error());
    if (!r.ok())
      return bad("the revocation journal " + jpath + " is unreadable at line " +
                     std::to_string(line_no) + ": " + r.error().message +
                     "; move it away only if you accept that the tokens it revoked are valid "
                     "again",
                 jpath);
    out.push_back(std::move(r).value());
  }
  return out;
}

Status RevocationList::load(int64_t now_s) {
  if (path_.empty()) return Status::Ok();
  MutexLock w(write_mu_);
  std::vector<Revocation> entries;
  auto doc = read_state_file(path_);
  if (!doc.ok()) {
    if (doc.error().code != ErrorCode::kNotFound)
      return bad("the revocation list " + path_ + " is not a JSON object; move it away only if " +
                     "you accept that the tokens it revoked are valid again",
                 path_);
  } else {
    auto parsed = parse(*doc, capacity_ + feed_capacity_);
    if (!parsed.ok())
      return bad("the revocation list " + path_ + " is unreadable: " + parsed.error().message,
                 path_);
    entries = std::move(*parsed);
  }
  auto journal = read_journal();
  if (!journal.ok()) return journal.error();
  const bool had_journal = env_->exists(journal_path());
  for (Revocation& r : *journal) entries.push_back(std::move(r));
  std::erase_if(entries, [&](const Revocation& r) { return expired(r, now_s, leeway_s_); });
  // A crash between a fold's snapshot and its emptying of the journal leaves entries in both:
  // one entry each (a subject's revocation keeps its latest second).
  std::unordered_map<std::string, size_t> seen;
  std::vector<Revocation> unique;
  unique.reserve(entries.size());
  for (Revocation& r : entries) {
    // Lists written before the feed had a table of its own: the registry link's entries.
    if (!r.feed && r.by.sub == "registry" && r.reason.rfind("registry revocation ", 0) == 0)
      r.feed = true;
    auto [it, fresh] = seen.emplace(index_key(r.kind, r.iss, r.value), unique.size());
    if (fresh) {
      unique.push_back(std::move(r));
    } else if (r.at_ms > unique[it->second].at_ms) {
      unique[it->second] = std::move(r);
    }
  }
  entries = std::move(unique);
  const auto feed = static_cast<size_t>(
      std::count_if(entries.begin(), entries.end(), [](const Revocation& r) { return r.feed; }));
  if (entries.size() - feed > capacity_ || feed > feed_capacity_)
    return bad("the revocation list " + path_ + " holds " + std::to_string(entries.size() - feed) +
                   " entries of the node's own and " + std::to_string(feed) +
                   " of the registry's, more than " + std::to_string(capacity_) + " and " +
                   std::to_string(feed_capacity_),
               path_);
  install(std::move(entries));
  if (!had_journal) return Status::Ok();
  // Folded in at every start: the journal starts empty, with no torn line to append after.
  // Where that cannot be written, the node runs on the journal (every entry in it is in force),
  // and the next entry goes in by a fold (the journal may end in a torn line).
  if (Status s = compact(); !s.ok()) {
    journal_torn_ = true;
    log(LogLevel::kWarn, "revocations_not_folded",
        json::Object{{"file", path_}, {"error", s.error().message}});
  }
  return Status::Ok();
}

void RevocationList::install(std::vector<Revocation> entries) {
  std::unordered_map<std::string, int64_t> index;
  size_t own = 0, feed = 0;
  for (const Revocation& r : entries) {
    int64_t at_s = r.at_ms / 1000;
    auto [it, fresh] = index.emplace(index_key(r.kind, r.iss, r.value), at_s);
    if (!fresh) it->second = std::max(it->second, at_s);
    ++(r.feed ? feed : own);
  }
  MutexLock lock(mu_);
  entries_ = std::move(entries);
  index_ = std::move(index);
  own_count_ = own;
  feed_count_ = feed;
}

void RevocationList::insert(const Revocation& r) {
  MutexLock lock(mu_);
  auto [it, fresh] = index_.emplace(index_key(r.kind, r.iss, r.value), r.at_ms / 1000);
  if (!fresh) it->second = std::max(it->second, r.at_ms / 1000);
  ++(r.feed ? feed_count_ : own_count_);
  entries_.push_back(r);
}

void RevocationList::prune(int64_t now_s) {
  std::vector<Revocation> kept = list();
  std::erase_if(kept, [&](const Revocation& r) { return expired(r, now_s, leeway_s_); });
  install(std::move(kept));
}

Status RevocationList::compact() {
  json::Array arr;
  for (const Revocation& e : list()) arr.push_back(e.to_json());
  json::Value doc(json::Object{{"version", 1}, {"revocations", std::move(arr)}});
  if (Status s = write_state_file(path_, doc, env_); !s.ok()) return s;
  if (journal_) {
    (void)journal_->close();
    journal_.reset();
  }
  if (env_->exists(journal_path()))
    if (base::IoStatus s = env_->truncate_file(journal_path(), 0); !s.ok())
      return Error(ErrorCode::kInternal, s.error().message);
  journal_lines_ = 0;
  journal_torn_ = false;
  return Status::Ok();
}

Status RevocationList::append(const Revocation& r) {
  if (!journal_) {
    auto f = env_->open_appendable(journal_path());
    if (!f.ok()) return Error(ErrorCode::kInternal, f.error().message);
    journal_ = std::move(*f);
  }
  base::IoStatus s = journal_->append(json::dump(r.to_json()) + "\n");
  if (s.ok()) s = journal_->sync();
  if (!s.ok()) {
    (void)journal_->close();
    journal_.reset();
    journal_torn_ = true;
    return Error(ErrorCode::kInternal, s.error().message);
  }
  ++journal_lines_;
  return Status::Ok();
}

Result<bool> RevocationList::add(Revocation r, int64_t now_s) {
  if (r.value.empty()) return bad("nothing to revoke", "");
  if (expired(r, now_s, leeway_s_)) return false;  // the token is refused as expired anyway
  {
    MutexLock w(write_mu_);
    const std::string key = index_key(r.kind, r.iss, r.value);
    auto table_full = [&] {
      MutexLock lock(mu_);
      return (r.feed ? feed_count_ : own_count_) >= (r.feed ? feed_capacity_ : capacity_);
    };
    {
      MutexLock lock(mu_);
      if (r.kind != Revocation::Kind::kSubject && index_.count(key) != 0) return false;
    }
    if (table_full()) prune(now_s);
    if (table_full()) {
      if (r.feed)
        return Error(ErrorCode::kCommandRejected,
                     "the table of the registry's revocations is full (" +
                         std::to_string(feed_capacity_) + " entries in force)",
                     "", "revocation_feed_full");
      return Error(ErrorCode::kCommandRejected,
                   "the revocation list is full (" + std::to_string(capacity_) +
                       " entries in force); revoke by sub or kid instead",
                   "", "revocation_list_full");
    }
    if (!path_.empty() && journal_torn_) {
      // The journal may end in part of a line: this entry goes in with a fresh snapshot.
      std::vector<Revocation> before = list();
      insert(r);
      if (Status s = compact(); !s.ok()) {
        install(std::move(before));
        return Error(ErrorCode::kInternal,
                     "the revocation could not be recorded: " + s.error().message);
      }
    } else {
      if (!path_.empty())
        if (Status s = append(r); !s.ok())
          return Error(ErrorCode::kInternal,
                       "the revocation could not be recorded: " + s.error().message);
      insert(r);
      if (!path_.empty() && journal_lines_ >= kCompactEvery) {
        prune(now_s);
        (void)compact();  // the entries are in the journal already; a failure retries later
      }
    }
  }
  std::vector<Listener> fns;
  {
    MutexLock lock(lmu_);
    for (auto& [id, fn] : listeners_) fns.push_back(fn);
  }
  for (auto& fn : fns) fn(r);
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

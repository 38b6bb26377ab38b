#include "node/ai/thoughts.h"

#include <algorithm>
#include <tuple>

#include "rcan/errors.h"
#include "runtime/log.h"

namespace rcan::node {
namespace {

constexpr size_t kMaxText = 8192;

std::string str_of(const json::Value* o, const char* key, size_t cap = 512) {
  if (!o || !o->is_object()) return {};
  const json::Value* v = o->get(key);
  return v && v->is_string() ? v->as_string().substr(0, cap) : std::string();
}

}  // namespace

json::Value Thought::to_json(bool with_reasoning) const {
  json::Object o;
  o.set("id", id);
  o.set("timestamp_ms", timestamp_ms);
  o.set("provider", provider);
  o.set("model", model);
  o.set("layer", layer.empty() ? json::Value() : json::Value(layer));
  o.set("instruction", instruction);
  o.set("context_snapshot",
        context_snapshot.is_object() ? context_snapshot : json::Value(json::Object{}));
  o.set("action", action);
  o.set("confidence", confidence ? json::Value(*confidence) : json::Value());
  if (with_reasoning) o.set("reasoning", reasoning);
  o.set("escalated_from", escalated_from ? json::Value(*escalated_from) : json::Value());
  if (!message_id.empty()) o.set("message_id", message_id);
  return o;
}

Thought thought_from_command(const Message& m, const json::Value* thought, int64_t now_ms) {
  Thought t;
  t.timestamp_ms = now_ms;
  t.message_id = m.message_id;
  if (m.ai) {
    t.provider = m.ai->provider;
    t.model = m.ai->model;
    t.layer = m.ai->layer.value_or("");
    t.confidence = m.ai->confidence;
    if (m.ai->thought_id) t.id = *m.ai->thought_id;
  }
  if (!t.confidence) t.confidence = m.confidence;
  std::string own_id = str_of(thought, "id", 128);
  if (t.id.empty()) t.id = own_id;
  t.reasoning = str_of(thought, "reasoning", kMaxText);
  t.instruction = str_of(thought, "instruction", kMaxText);
  if (t.instruction.empty())
    if (const json::Value* i = m.payload.find("instruction"); i && i->is_string())
      t.instruction = i->as_string().substr(0, kMaxText);
  if (thought && thought->is_object()) {
    if (const json::Value* c = thought->get("context_snapshot"); c && c->is_object())
      t.context_snapshot = *c;
    std::string from = str_of(thought, "escalated_from", 128);
    if (!from.empty()) t.escalated_from = from;
  }
  json::Object action{{"type", m.action()}};
  for (const auto& [k, v] : m.payload) {
    if (k == "action" || k == "action_type" || k == "command" || k == "thought" || k == "ai" ||
        k == "watermark_token")
      continue;
    action.set(k, v);
  }
  t.action = action;
  return t;
}

json::Object thought_record(const Thought& t) {
  json::Object o = t.to_json(true).as_object();
  o.set("principal", t.principal);
  return o;
}

Result<Thought> parse_thought_line(std::string_view line) {
  auto v = json::parse(line);
  if (!v.ok()) return v.error();
  if (!v->is_object())
    return Error(ErrorCode::kSchemaValidationFailed, "a thought line is an object", "");
  const json::Value& o = *v;
  auto bad = [](const char* k, const char* what) {
    return Error(ErrorCode::kSchemaValidationFailed, std::string(k) + " must be " + what, k);
  };
  Thought t;
  const json::Value* id = o.get("id");
  if (!id || !id->is_string() || id->as_string().empty() || id->as_string().size() > 128)
    return bad("id", "a string of 1 to 128 characters");
  t.id = id->as_string();
  const json::Value* ts = o.get("timestamp_ms");
  if (!ts || !ts->is_int()) return bad("timestamp_ms", "an integer");
  t.timestamp_ms = ts->as_int();
  for (auto [k, out, cap] :
       {std::tuple<const char*, std::string*, size_t>{"provider", &t.provider, 512},
        {"model", &t.model, 512},
        {"instruction", &t.instruction, kMaxText},
        {"reasoning", &t.reasoning, kMaxText},
        {"message_id", &t.message_id, 512},
        {"principal", &t.principal, 1024}}) {
    const json::Value* f = o.get(k);
    if (!f || f->is_null()) continue;
    if (!f->is_string()) return bad(k, "a string");
    *out = f->as_string().substr(0, cap);
  }
  if (const json::Value* l = o.get("layer"); l && !l->is_null()) {
    if (!l->is_string()) return bad("layer", "a string or null");
    t.layer = l->as_string().substr(0, 512);
  }
  if (const json::Value* c = o.get("confidence"); c && !c->is_null()) {
    if (!c->is_number() || !(c->to_double() >= 0.0 && c->to_double() <= 1.0))
      return bad("confidence", "a number in [0, 1] or null");
    t.confidence = c->to_double();
  }
  if (const json::Value* e = o.get("escalated_from"); e && !e->is_null()) {
    if (!e->is_string()) return bad("escalated_from", "a string or null");
    t.escalated_from = e->as_string().substr(0, 128);
  }
  if (const json::Value* c = o.get("context_snapshot"); c && c->is_object())
    t.context_snapshot = *c;
  if (const json::Value* a = o.get("action")) t.action = *a;
  return t;
}

Result<size_t> ThoughtLog::open() {
  if (file_.empty()) return size_t{0};
  MutexLock lock(mu_);
  size_t skipped = 0;
  if (env_->exists(file_)) {
    auto text = env_->read_file(file_);
    if (!text.ok())
      return Error(ErrorCode::kInternal, "thought log " + file_ + ": " + text.error().message);
    std::string_view rest = *text;
    while (!rest.empty()) {
      size_t nl = rest.find('\n');
      std::string_view line = rest.substr(0, nl);
      rest = nl == std::string_view::npos ? std::string_view() : rest.substr(nl + 1);
      ++lines_;
      auto t = nl == std::string_view::npos
                   ? Result<Thought>(Error(ErrorCode::kMalformedJson, "torn"))
                   : parse_thought_line(line);
      if (!t.ok()) {
        ++skipped;
        continue;
      }
      std::string id = t->id;
      if (by_id_.count(id) == 0) order_.push_back(id);
      by_id_[id] = std::move(*t);
      while (order_.size() > capacity_) {
        by_id_.erase(order_.front());
        order_.pop_front();
      }
    }
  }
  // Start from a file that holds exactly what is kept (no torn tail to append after).
  if (skipped > 0 || lines_ > order_.size()) {
    if (Status st = rewrite_locked(); !st.ok()) return st.error();
  }
  // Opened now, not at the first thought: the node's open files do not change under load.
  if (auto f = env_->open_appendable(file_); f.ok()) out_ = std::move(*f);
  return skipped;
}

Status ThoughtLog::rewrite_locked() {
  if (out_) {
    (void)out_->close();
    out_.reset();
  }
  std::string body;
  for (const auto& id : order_) {
    body += json::canonical(json::Value(thought_record(by_id_.at(id))));
    body += '\n';
  }
  base::IoStatus st = env_->write_file_atomic(file_, body);
  if (!st.ok())
    return Error(ErrorCode::kInternal, "thought log " + file_ + ": " + st.error().message);
  lines_ = order_.size();
  return Status::Ok();
}

void ThoughtLog::append_locked(const Thought& t) {
  if (file_.empty()) return;
  if (lines_ >= 2 * capacity_ && rewrite_locked().ok()) {
    // compacted: the thought below is appended to the rewritten file
  }
  base::IoStatus st = base::IoStatus::Ok();
  if (!out_) {
    auto f = env_->open_appendable(file_);
    if (f.ok()) {
      out_ = std::move(*f);
    } else {
      st = f.error();
    }
  }
  if (st.ok()) {
    std::string line = json::canonical(json::Value(thought_record(t)));
    line += '\n';
    st = out_->append(line);
    if (st.ok()) st = out_->sync();
    if (!st.ok()) {
      (void)out_->close();
      out_.reset();
    }
  }
  if (st.ok()) {
    ++lines_;
    return;
  }
  if (unpersisted_++ == 0)
    log(LogLevel::kError, "thought_log_write_failed",
        json::Object{{"file", file_}, {"error", st.error().message}});
}

bool ThoughtLog::put(Thought t) {
  MutexLock lock(mu_);
  std::string id = t.id;
  auto it = by_id_.find(id);
  if (it != by_id_.end()) {
    if (it->second.principal != t.principal) return false;
    append_locked(t);
    it->second = std::move(t);
    return true;
  }
  append_locked(t);
  by_id_.emplace(id, std::move(t));
  order_.push_back(id);
  while (order_.size() > capacity_) {
    by_id_.erase(order_.front());
    order_.pop_front();
  }
  return true;
}

std::optional<Thought> ThoughtLog::get(const std::string& id) const {
  MutexLock lock(mu_);
  auto it = by_id_.find(id);
  if (it == by_id_.end()) return std::nullopt;
  return it->second;
}

void ThoughtLog::clear() {
  MutexLock lock(mu_);
  by_id_.clear();
  order_.clear();
  if (!file_.empty()) {
    if (Status st = rewrite_locked(); !st.ok())
      log(LogLevel::kError, "thought_log_write_failed",
          json::Object{{"file", file_}, {"error", st.error().message}});
  }
}

uint64_t ThoughtLog::unpersisted() const {
  MutexLock lock(mu_);
  return unpersisted_;
}

size_t ThoughtLog::size() const {
  MutexLock lock(mu_);
  return by_id_.size();
}

}  // namespace rcan::node

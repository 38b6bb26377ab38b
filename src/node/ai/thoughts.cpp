#include "node/ai/thoughts.h"

#include <algorithm>

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

void ThoughtLog::put(Thought t) {
  MutexLock lock(mu_);
  std::string id = t.id;
  auto it = by_id_.find(id);
  if (it != by_id_.end()) {
    it->second = std::move(t);
    return;
  }
  by_id_.emplace(id, std::move(t));
  order_.push_back(id);
  while (order_.size() > capacity_) {
    by_id_.erase(order_.front());
    order_.pop_front();
  }
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
}

size_t ThoughtLog::size() const {
  MutexLock lock(mu_);
  return by_id_.size();
}

}  // namespace rcan::node

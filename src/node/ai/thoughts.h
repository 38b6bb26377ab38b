// ThoughtLog — the §16.5 thought log: the reasoning behind AI-produced commands, kept in
// memory with bounded retention (the newest `capacity` thoughts; older ones are dropped).
//
// Thoughts arrive attached to COMMANDs (the `thought` member, docs/AI.md) or from brain
// layers on escalation. GET /api/thoughts/<id> reads them; `reasoning` is shown only to
// callers holding the `config` scope. clear() empties the log (ownership transfer).
#pragma once

#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <unordered_map>

#include "base/thread_annotations.h"
#include "rcan/json.h"
#include "rcan/message.h"

namespace rcan::node {

struct Thought {
  std::string id;
  int64_t timestamp_ms = 0;
  std::string provider, model, layer;
  std::string instruction;
  json::Value context_snapshot;  // object or null
  json::Value action;            // {type, …params} or null
  std::optional<double> confidence;
  std::string reasoning;
  std::optional<std::string> escalated_from;  // the thought (or message) it escalated from
  std::string message_id;                     // the command it produced

  // The §16.5 response body; reasoning only when `with_reasoning`.
  json::Value to_json(bool with_reasoning) const;
};

// Builds a thought from a COMMAND's ai block and its optional `thought` object
// ({id?, reasoning?, instruction?, context_snapshot?, escalated_from?}). Strings are capped.
Thought thought_from_command(const Message& m, const json::Value* thought, int64_t now_ms);

class ThoughtLog {
 public:
  explicit ThoughtLog(size_t capacity = 1000) : capacity_(capacity ? capacity : 1) {}
  // Stores (or replaces) a thought by id.
  void put(Thought t) EXCLUDES(mu_);
  std::optional<Thought> get(const std::string& id) const EXCLUDES(mu_);
  void clear() EXCLUDES(mu_);
  size_t size() const EXCLUDES(mu_);

 private:
  mutable Mutex mu_;
  size_t capacity_;
  std::deque<std::string> order_ GUARDED_BY(mu_);
  std::unordered_map<std::string, Thought> by_id_ GUARDED_BY(mu_);
};

}  // namespace rcan::node

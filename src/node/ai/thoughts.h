// ThoughtLog — the §16.5 thought log: the reasoning behind AI-produced commands, with bounded
// retention (the newest `capacity` thoughts; older ones are dropped). With a file, every thought
// is appended and synced before it is referenced by an audit record, and the log is read back at
// start, so a record's `thought_id` still points at its thought after a restart; the file is
// compacted to the retained thoughts when it holds twice as many lines.
//
// Thoughts arrive attached to COMMANDs (the `thought` member, docs/AI.md) or from brain
// layers on escalation. GET /api/thoughts/<id> reads them; `reasoning` is shown only to
// callers holding the `config` scope. clear() empties the log (ownership transfer).
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>

#include "base/thread_annotations.h"
#include "rcan/base/env.h"
#include "rcan/json.h"
#include "rcan/message.h"
#include "rcan/result.h"

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
  std::string principal;  // Principal::key() of whoever sent it: only they may replace it

  // The §16.5 response body; reasoning only when `with_reasoning`.
  json::Value to_json(bool with_reasoning) const;
};

// The persisted form: to_json(true) plus `principal`. One line of the thought file.
json::Object thought_record(const Thought& t);
// Reads a persisted line back. Errors: MALFORMED_JSON, SCHEMA_VALIDATION_FAILED naming the member.
Result<Thought> parse_thought_line(std::string_view line);

// Builds a thought from a COMMAND's ai block and its optional `thought` object
// ({id?, reasoning?, instruction?, context_snapshot?, escalated_from?}). Strings are capped.
Thought thought_from_command(const Message& m, const json::Value* thought, int64_t now_ms);

class ThoughtLog {
 public:
  // `file` "" keeps the log in memory only; `env` nullptr → base::Env::posix().
  explicit ThoughtLog(size_t capacity = 1000, std::string file = {}, base::Env* env = nullptr)
      : capacity_(capacity ? capacity : 1),
        file_(std::move(file)),
        env_(env ? env : base::Env::posix()) {}
  // Reads the file (when there is one): the newest `capacity` thoughts. A line that cannot be
  // read (torn by a crash) is skipped and counted in the result. Errors: INTERNAL when the file
  // exists and cannot be read.
  Result<size_t> open() EXCLUDES(mu_);
  // Stores a thought by id (replacing one with the same id from the same principal). False,
  // storing nothing, when the id already holds another principal's thought: evidence is not
  // overwritten by someone else. A thought the file could not take is kept in memory, logged
  // and counted (unpersisted()).
  bool put(Thought t) EXCLUDES(mu_);
  std::optional<Thought> get(const std::string& id) const EXCLUDES(mu_);
  void clear() EXCLUDES(mu_);
  size_t size() const EXCLUDES(mu_);
  uint64_t unpersisted() const EXCLUDES(mu_);

 private:
  void append_locked(const Thought& t) REQUIRES(mu_);
  Status rewrite_locked() REQUIRES(mu_);
  mutable Mutex mu_;
  size_t capacity_;
  std::string file_;
  base::Env* env_;
  std::unique_ptr<base::WritableFile> out_ GUARDED_BY(mu_);
  size_t lines_ GUARDED_BY(mu_) = 0;  // in the file
  uint64_t unpersisted_ GUARDED_BY(mu_) = 0;
  std::deque<std::string> order_ GUARDED_BY(mu_);
  std::unordered_map<std::string, Thought> by_id_ GUARDED_BY(mu_);
};

}  // namespace rcan::node

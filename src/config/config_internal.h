// The config module's internal interface: what the files of src/config/ share. Not for use
// outside src/config/ (the public interface is config.h).
//
// Two passes:
//   1. validate(): walks the YAML tree against a declarative schema (every key of every
//      block enumerated) and produces a typed json::Value tree. Unknown and duplicate keys,
//      wrong types, enum and range violations fail here, with the key path and the
//      YAML line/column. Node and depth budgets bound the walk (alias bombs, cycles).
//   2. build(): maps the typed tree onto NodeConfig: aliases between the two published
//      styles, cross-field checks (min < max, RURI, RRN), defaults and path resolution.
// Both passes come from one set of tables: every key is one row (table.h) that holds its
// schema and the code that reads it, and each block's rows live in its own file under
// blocks/. config_schema() is the schema the rows describe; build() walks the same rows in
// order. yaml-cpp exceptions and the module's own ConfigError never leave the module.
//
// Files: table.h/table.cpp (rows, schema builders, path resolution), blocks/*.cpp (one
// table per block; blocks/document.cpp puts them in order), validator.cpp (pass 1 and the
// mapping of failures to Error values) and config.cpp (the public API of config.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "config/config.h"

namespace rcan::config::internal {

// ---------------------------------------------------------------------------------------
// Errors (validator.cpp)

// Thrown by fail() and caught by parse_document(), which turns it into an Error value.
struct ConfigError {
  std::string path;
  std::string message;
  std::string reason;
};

[[noreturn]] void fail(std::string path, std::string message, std::string reason);

// `s` for an error message: quotes and control bytes escaped, cut after `max` bytes.
std::string printable(std::string_view s, size_t max = 48);

// Key paths: `parent.key` (or `parent["odd key"]`) and `parent[i]`.
std::string key_segment(const std::string& parent, std::string_view key);
std::string index_segment(const std::string& parent, size_t i);

bool is_one_of(std::string_view s, std::initializer_list<std::string_view> list);

Error make_error(const std::string& path, const std::string& msg, const std::string& reason,
                 const std::string& loc);

// Parses and validates a document whose size and bytes parse_config_text() has checked:
// pass 1, then build(); every failure becomes an Error with the path and the YAML position.
Result<NodeConfig> parse_document(std::string_view yaml, const ConfigOptions& opts);

// ---------------------------------------------------------------------------------------
// Schema (built from the block tables; the builders are in table.h)

struct Schema;
using SP = std::shared_ptr<const Schema>;

struct Schema {
  enum class K { kString, kInt, kNumber, kBool, kObject, kArray, kEither, kFree };
  K k = K::kString;
  // kString
  std::vector<std::string> enums;
  size_t max_len = 4096;
  // kInt / kNumber
  std::optional<double> min, max;
  bool min_exclusive = false;
  // kObject
  std::vector<std::pair<std::string, SP>> props;
  std::vector<std::string> required;
  // kArray
  SP items;
  size_t max_items = 1024;
  // kEither: alternatives tried by the YAML node's kind (and, for scalars, resolved type)
  std::vector<SP> alts;
};

// The whole document's schema (built once from the block tables, blocks/document.cpp).
SP config_schema();

std::string expected_name(const Schema& s);
std::string join_enum(const std::vector<std::string>& v);
std::string fmt_num(double d);

// ---------------------------------------------------------------------------------------
// Pass 2: typed JSON → NodeConfig (the rows' readers, walked by blocks/document.cpp)

// A position in the typed tree: the value (nullptr when absent) and its path.
struct At {
  const json::Value* v = nullptr;
  std::string path;

  At operator[](std::string_view key) const {
    const json::Value* child = (v != nullptr && v->is_object()) ? v->get(key) : nullptr;
    return At{child, key_segment(path, key)};
  }
  At operator[](size_t i) const {
    const json::Value* child =
        (v != nullptr && v->is_array() && i < v->as_array().size()) ? &v->as_array()[i] : nullptr;
    return At{child, index_segment(path, i)};
  }
  explicit operator bool() const { return v != nullptr; }
  size_t size() const { return v != nullptr && v->is_array() ? v->as_array().size() : 0; }
  bool is_array() const { return v != nullptr && v->is_array(); }
  bool is_object() const { return v != nullptr && v->is_object(); }
  bool is_string() const { return v != nullptr && v->is_string(); }
  bool is_int() const { return v != nullptr && v->is_int(); }

  std::string str(std::string def = {}) const { return v ? v->as_string() : def; }
  double num(double def = 0) const { return v ? v->to_double() : def; }
  std::optional<double> opt_num() const {
    return v ? std::optional<double>(v->to_double()) : std::nullopt;
  }
  bool flag(bool def) const { return v ? v->as_bool() : def; }
  // Integers are range-checked by the schema; these narrow within those ranges.
  uint32_t u32(uint32_t def) const { return v ? static_cast<uint32_t>(v->as_int()) : def; }
  std::optional<uint32_t> opt_u32() const {
    return v ? std::optional<uint32_t>(static_cast<uint32_t>(v->as_int())) : std::nullopt;
  }
  uint64_t u64(uint64_t def) const { return v ? static_cast<uint64_t>(v->as_int()) : def; }
  std::vector<std::string> strs() const {
    std::vector<std::string> out;
    if (v != nullptr && v->is_array())
      for (const auto& e : v->as_array()) out.push_back(e.as_string());
    return out;
  }
};

// Two spellings of one setting: both present and different → error.
template <typename T>
void same_or_fail(const At& a, const T& va, const At& b, const T& vb) {
  if (a && b && !(va == vb))
    fail(b.path, "conflicts with " + a.path + " (give one of them)", "invalid_value");
}

NodeConfig build(const json::Value& root_value, const ConfigOptions& opts);

// `p` resolved against `base_dir` (the config file's directory; empty: left relative) and
// `~/…` against $HOME; an empty `p` stays empty.
std::string resolve_path(const std::string& p, const std::string& base_dir);
// key_dir, audit.dir and audit.chain_secret_file under data_dir, unless the file set them
// (blocks/security.cpp; apply_overrides() calls it again for a new data dir).
void derive_paths(NodeConfig& c);

}  // namespace rcan::config::internal

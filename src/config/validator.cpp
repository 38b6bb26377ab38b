// Pass 1 of config loading (YAML → typed JSON against the schema), the module's error
// helpers, and parse_document(), which maps every failure to an Error value.
#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <limits>
#include <new>
#include <set>
#include <sstream>
#include <unordered_map>

#include "config/config_internal.h"

namespace rcan::config::internal {

// ---------------------------------------------------------------------------------------
// Errors

[[noreturn]] void fail(std::string path, std::string message, std::string reason) {
  throw ConfigError{std::move(path), std::move(message), std::move(reason)};
}

std::string printable(std::string_view s, size_t max) {
  std::string out;
  for (unsigned char c : s) {
    if (out.size() >= max) {
      out += "…";
      break;
    }
    if (c == '"' || c == '\\') {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  return out;
}

std::string key_segment(const std::string& parent, std::string_view key) {
  bool plain = !key.empty() && key.size() <= 64;
  for (char c : key) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) plain = false;
  }
  if (plain) return parent.empty() ? std::string(key) : parent + "." + std::string(key);
  return parent + "[\"" + printable(key, 64) + "\"]";
}

std::string index_segment(const std::string& parent, size_t i) {
  return parent + "[" + std::to_string(i) + "]";
}

bool is_one_of(std::string_view s, std::initializer_list<std::string_view> list) {
  return std::find(list.begin(), list.end(), s) != list.end();
}

namespace {

// ---------------------------------------------------------------------------------------
// Scalars: YAML 1.2 core schema resolution of plain scalars, plus the YAML 1.1 booleans
// (yes/no/on/off) that Python tools read as booleans.

enum class ScalarKind { kNull, kBool, kInt, kFloat, kString };

struct Scalar {
  ScalarKind kind = ScalarKind::kString;
  std::string text;
  bool b = false;
  int64_t i = 0;
  double d = 0;
  bool int_overflow = false;
};

bool all_digits(std::string_view s, int base) {
  if (s.empty()) return false;
  for (char c : s) {
    if (base == 10 && !(c >= '0' && c <= '9')) return false;
    if (base == 8 && !(c >= '0' && c <= '7')) return false;
    if (base == 16 && !std::isxdigit(static_cast<unsigned char>(c))) return false;
  }
  return true;
}

bool parse_int(std::string_view s, Scalar& out) {
  std::string_view body = s;
  bool neg = false;
  if (!body.empty() && (body[0] == '+' || body[0] == '-')) {
    neg = body[0] == '-';
    body.remove_prefix(1);
  }
  int base = 10;
  if (body.size() > 2 && body[0] == '0' && (body[1] == 'x' || body[1] == 'o')) {
    if (s.size() != body.size()) return false;  // no sign on 0x / 0o
    base = body[1] == 'x' ? 16 : 8;
    body.remove_prefix(2);
  }
  if (!all_digits(body, base)) return false;
  out.kind = ScalarKind::kInt;
  // Magnitude limit: INT64_MAX, or INT64_MAX + 1 for a negative number.
  const uint64_t limit =
      static_cast<uint64_t>(std::numeric_limits<int64_t>::max()) + (neg ? 1u : 0u);
  uint64_t v = 0;
  for (char c : body) {
    unsigned digit =
        std::isdigit(static_cast<unsigned char>(c))
            ? static_cast<unsigned>(c - '0')
            : static_cast<unsigned>(std::tolower(static_cast<unsigned char>(c)) - 'a' + 10);
    if (v > (limit - digit) / static_cast<unsigned>(base)) {
      out.int_overflow = true;
      return true;
    }
    v = v * static_cast<unsigned>(base) + digit;
  }
  if (neg) {
    out.i = v == static_cast<uint64_t>(std::numeric_limits<int64_t>::max()) + 1u
                ? std::numeric_limits<int64_t>::min()
                : -static_cast<int64_t>(v);
  } else {
    out.i = static_cast<int64_t>(v);
  }
  return true;
}

bool parse_float(std::string_view s, Scalar& out) {
  std::string_view body = s;
  bool neg = false;
  if (!body.empty() && (body[0] == '+' || body[0] == '-')) {
    neg = body[0] == '-';
    body.remove_prefix(1);
  }
  if (is_one_of(body, {".inf", ".Inf", ".INF"})) {
    out.kind = ScalarKind::kFloat;
    out.d =
        neg ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
    return true;
  }
  if (s.size() == body.size() && is_one_of(body, {".nan", ".NaN", ".NAN"})) {
    out.kind = ScalarKind::kFloat;
    out.d = std::numeric_limits<double>::quiet_NaN();
    return true;
  }
  // [0-9]+(\.[0-9]*)?([eE][-+]?[0-9]+)?  |  \.[0-9]+([eE][-+]?[0-9]+)?
  size_t p = 0;
  size_t int_digits = 0, frac_digits = 0;
  while (p < body.size() && std::isdigit(static_cast<unsigned char>(body[p]))) ++p, ++int_digits;
  if (p < body.size() && body[p] == '.') {
    ++p;
    while (p < body.size() && std::isdigit(static_cast<unsigned char>(body[p]))) ++p, ++frac_digits;
  }
  if (int_digits == 0 && frac_digits == 0) return false;
  if (p < body.size() && (body[p] == 'e' || body[p] == 'E')) {
    ++p;
    if (p < body.size() && (body[p] == '+' || body[p] == '-')) ++p;
    size_t exp_digits = 0;
    while (p < body.size() && std::isdigit(static_cast<unsigned char>(body[p]))) ++p, ++exp_digits;
    if (exp_digits == 0) return false;
  }
  if (p != body.size()) return false;
  std::string copy(s);
  errno = 0;
  char* end = nullptr;
  double d = std::strtod(copy.c_str(), &end);
  if (end != copy.c_str() + copy.size()) return false;
  out.kind = ScalarKind::kFloat;
  out.d = d;  // ±HUGE_VAL on overflow → reported as not finite
  return true;
}

Scalar resolve(const YAML::Node& n) {
  Scalar s;
  s.text = n.Scalar();
  const std::string& tag = n.Tag();
  if (tag == "!" || tag == "tag:yaml.org,2002:str") return s;  // quoted / block / !!str
  if (tag != "?" && !tag.empty()) return s;                    // rejected by the caller
  const std::string& t = s.text;
  if (is_one_of(t, {"", "~", "null", "Null", "NULL"})) {
    s.kind = ScalarKind::kNull;
  } else if (is_one_of(t, {"true", "True", "TRUE", "yes", "Yes", "YES", "on", "On", "ON"})) {
    s.kind = ScalarKind::kBool;
    s.b = true;
  } else if (is_one_of(t, {"false", "False", "FALSE", "no", "No", "NO", "off", "Off", "OFF"})) {
    s.kind = ScalarKind::kBool;
    s.b = false;
  } else if (parse_int(t, s) || parse_float(t, s)) {
    // kind set
  }
  return s;
}

std::string describe(const YAML::Node& n) {
  switch (n.Type()) {
    case YAML::NodeType::Map:
      return "a mapping";
    case YAML::NodeType::Sequence:
      return "a list";
    case YAML::NodeType::Null:
    case YAML::NodeType::Undefined:
      return "null";
    case YAML::NodeType::Scalar:
      break;
  }
  Scalar s = resolve(n);
  switch (s.kind) {
    case ScalarKind::kNull:
      return "null";
    case ScalarKind::kBool:
      return "boolean " + s.text;
    case ScalarKind::kInt:
      return "integer " + printable(s.text);
    case ScalarKind::kFloat:
      return "number " + printable(s.text);
    case ScalarKind::kString:
      break;
  }
  return "string \"" + printable(s.text) + "\"";
}

// ---------------------------------------------------------------------------------------
// Document count. yaml-cpp 0.7's LoadAll() loops forever on a stray flow token at document
// level (e.g. a file starting with ","): each HandleNextDocument() yields a null document
// without consuming the token. So documents are counted with a bounded loop of our own.

class DiscardEvents : public YAML::EventHandler {
 public:
  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t,
                const std::string&) override {}
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {}
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {}
  void OnMapEnd() override {}
};

// 0, 1 or 2 (= more than one). Throws YAML::Exception on syntax errors.
int count_documents(const std::string& text) {
  std::istringstream in(text);
  YAML::Parser parser(in);
  DiscardEvents discard;
  int n = 0;
  while (n < 2 && parser.HandleNextDocument(discard)) ++n;
  return n;
}

// ---------------------------------------------------------------------------------------
// Pass 1: YAML → typed JSON

class Validator {
 public:
  json::Value run(const YAML::Node& root) { return walk(root, *config_schema(), "", 0); }

  // Where a path was in the text (for pass-2 errors).
  const YAML::Mark* mark_of(const std::string& path) const {
    auto it = marks_.find(path);
    return it == marks_.end() ? nullptr : &it->second;
  }

  // Mark of the node being reported (pass-1 errors).
  std::optional<YAML::Mark> last_mark;

 private:
  [[noreturn]] void error(const YAML::Node& n, const std::string& path, std::string msg,
                          std::string reason) {
    last_mark = n.Mark();
    fail(path, std::move(msg), std::move(reason));
  }

  void count(const YAML::Node& n, const std::string& path, size_t depth) {
    if (++nodes_ > kMaxConfigNodes)
      error(n, path,
            "document too large: more than " + std::to_string(kMaxConfigNodes) +
                " nodes (alias expansion counts every use)",
            "too_large");
    if (depth > 64) error(n, path, "nesting too deep", "too_large");
  }

  void remember(const YAML::Node& n, const std::string& path) {
    if (marks_.size() < kMaxConfigNodes) marks_.emplace(path, n.Mark());
  }

  void check_tag(const YAML::Node& n, const std::string& path) {
    const std::string& tag = n.Tag();
    if (n.IsScalar()) {
      if (tag == "?" || tag == "!" || tag == "tag:yaml.org,2002:str") return;
    } else if (n.IsMap() || n.IsSequence()) {
      if (tag == "?" || tag.empty() || tag == "tag:yaml.org,2002:map" ||
          tag == "tag:yaml.org,2002:seq")
        return;
    } else {
      return;
    }
    error(n, path, "unsupported YAML tag \"" + printable(tag) + "\"", "wrong_type");
  }

  [[noreturn]] void wrong_type(const YAML::Node& n, const Schema& s, const std::string& path) {
    error(n, path, "expected " + expected_name(s) + ", got " + describe(n), "wrong_type");
  }

  json::Value walk(const YAML::Node& n, const Schema& s, const std::string& path, size_t depth) {
    count(n, path, depth);
    check_tag(n, path);
    remember(n, path);
    switch (s.k) {
      case Schema::K::kString:
        return walk_string(n, s, path);
      case Schema::K::kInt:
        return walk_int(n, s, path);
      case Schema::K::kNumber:
        return walk_number(n, s, path);
      case Schema::K::kBool: {
        if (!n.IsScalar()) wrong_type(n, s, path);
        Scalar sc = resolve(n);
        if (sc.kind != ScalarKind::kBool) wrong_type(n, s, path);
        return json::Value(sc.b);
      }
      case Schema::K::kObject:
        return walk_object(n, s, path, depth);
      case Schema::K::kArray: {
        if (!n.IsSequence()) wrong_type(n, s, path);
        if (n.size() > s.max_items)
          error(n, path,
                "too many items: " + std::to_string(n.size()) + " (at most " +
                    std::to_string(s.max_items) + ")",
                "out_of_range");
        json::Array out;
        size_t i = 0;
        for (const auto& item : n) {
          out.push_back(walk(item, *s.items, index_segment(path, i), depth + 1));
          ++i;
        }
        return json::Value(std::move(out));
      }
      case Schema::K::kEither: {
        for (const SP& alt : s.alts) {
          if (accepts_kind(n, *alt)) return walk(n, *alt, path, depth);
        }
        // Report against the alternative of the same YAML kind when there is one, so that
        // e.g. an out-of-range integer is reported as such.
        wrong_type(n, s, path);
      }
      case Schema::K::kFree:
        return walk_free(n, path, depth);
    }
    wrong_type(n, s, path);
  }

  static bool accepts_kind(const YAML::Node& n, const Schema& s) {
    switch (s.k) {
      case Schema::K::kObject:
        return n.IsMap();
      case Schema::K::kArray:
        return n.IsSequence();
      case Schema::K::kFree:
        return n.IsMap() || n.IsSequence() || n.IsScalar();
      case Schema::K::kEither:
        return false;
      case Schema::K::kString:
      case Schema::K::kInt:
      case Schema::K::kNumber:
      case Schema::K::kBool:
        break;
    }
    if (!n.IsScalar()) return false;
    Scalar sc = resolve(n);
    switch (s.k) {
      case Schema::K::kString:
        return sc.kind == ScalarKind::kString;
      case Schema::K::kInt:
        return sc.kind == ScalarKind::kInt;
      case Schema::K::kNumber:
        return sc.kind == ScalarKind::kInt || sc.kind == ScalarKind::kFloat;
      case Schema::K::kBool:
        return sc.kind == ScalarKind::kBool;
      default:
        return false;
    }
  }

  json::Value walk_string(const YAML::Node& n, const Schema& s, const std::string& path) {
    if (!n.IsScalar()) wrong_type(n, s, path);
    Scalar sc = resolve(n);
    if (sc.kind != ScalarKind::kString) {
      std::string msg = "expected " + expected_name(s) + ", got " + describe(n);
      if (sc.kind != ScalarKind::kNull) msg += " (quote it to make it a string)";
      error(n, path, msg, "wrong_type");
    }
    if (!json::valid_utf8(sc.text)) error(n, path, "string is not valid UTF-8", "invalid_value");
    if (sc.text.size() > s.max_len)
      error(n, path,
            "string too long: " + std::to_string(sc.text.size()) + " bytes (at most " +
                std::to_string(s.max_len) + ")",
            "out_of_range");
    if (!s.enums.empty() && std::find(s.enums.begin(), s.enums.end(), sc.text) == s.enums.end())
      error(n, path,
            "expected one of " + join_enum(s.enums) + ", got \"" + printable(sc.text) + "\"",
            "invalid_value");
    return json::Value(std::move(sc.text));
  }

  void check_range(const YAML::Node& n, const Schema& s, const std::string& path, double v,
                   const std::string& shown) {
    bool low = s.min && (s.min_exclusive ? !(v > *s.min) : v < *s.min);
    bool high = s.max && v > *s.max;
    if (!low && !high) return;
    std::string range;
    if (s.min && s.max) {
      range = "between " + fmt_num(*s.min) + " and " + fmt_num(*s.max);
    } else if (s.min) {
      range = (s.min_exclusive ? "greater than " : "at least ") + fmt_num(*s.min);
    } else {
      range = "at most " + fmt_num(*s.max);
    }
    error(n, path, "out of range: " + shown + " (must be " + range + ")", "out_of_range");
  }

  json::Value walk_int(const YAML::Node& n, const Schema& s, const std::string& path) {
    if (!n.IsScalar()) wrong_type(n, s, path);
    Scalar sc = resolve(n);
    if (sc.kind != ScalarKind::kInt) wrong_type(n, s, path);
    if (sc.int_overflow) error(n, path, "out of range: " + printable(sc.text), "out_of_range");
    check_range(n, s, path, static_cast<double>(sc.i), printable(sc.text));
    return json::Value(sc.i);
  }

  json::Value walk_number(const YAML::Node& n, const Schema& s, const std::string& path) {
    if (!n.IsScalar()) wrong_type(n, s, path);
    Scalar sc = resolve(n);
    double v = 0;
    if (sc.kind == ScalarKind::kInt) {
      if (sc.int_overflow) error(n, path, "out of range: " + printable(sc.text), "out_of_range");
      v = static_cast<double>(sc.i);
    } else if (sc.kind == ScalarKind::kFloat) {
      v = sc.d;
    } else {
      wrong_type(n, s, path);
    }
    if (!std::isfinite(v))
      error(n, path, "expected a finite number, got " + printable(sc.text), "out_of_range");
    check_range(n, s, path, v, printable(sc.text));
    return json::Value(v);
  }

  // Keys: scalars only, unique, `<<` merge keys refused.
  std::string key_of(const YAML::Node& key, const std::string& path) {
    if (!key.IsScalar())
      error(key, path, "mapping keys must be strings, got " + describe(key), "wrong_type");
    const std::string& k = key.Scalar();
    if (k == "<<" && key.Tag() == "?")
      error(key, key_segment(path, k), "YAML merge keys (<<) are not supported", "unknown_key");
    if (!json::valid_utf8(k)) error(key, path, "key is not valid UTF-8", "invalid_value");
    return k;
  }

  json::Value walk_object(const YAML::Node& n, const Schema& s, const std::string& path,
                          size_t depth) {
    if (!n.IsMap()) wrong_type(n, s, path);
    json::Object out;
    std::set<std::string> seen;
    for (auto it = n.begin(); it != n.end(); ++it) {
      std::string k = key_of(it->first, path);
      std::string child = key_segment(path, k);
      if (!seen.insert(k).second) error(it->first, child, "duplicate key", "duplicate_key");
      const Schema* prop = nullptr;
      for (const auto& p : s.props) {
        if (p.first == k) {
          prop = p.second.get();
          break;
        }
      }
      if (prop == nullptr) error(it->first, child, "unknown key", "unknown_key");
      out.append_unchecked(k, walk(it->second, *prop, child, depth + 1));
    }
    for (const auto& r : s.required) {
      if (!seen.count(r)) error(n, key_segment(path, r), "required key is missing", "missing_key");
    }
    return json::Value(std::move(out));
  }

  // Free-form blocks (no published key list): any keys, scalars typed, bounded depth.
  json::Value walk_free(const YAML::Node& n, const std::string& path, size_t depth) {
    if (depth > kMaxFreeDepth + 8) error(n, path, "nesting too deep", "too_large");
    if (n.IsMap()) {
      json::Object out;
      std::set<std::string> seen;
      for (auto it = n.begin(); it != n.end(); ++it) {
        std::string k = key_of(it->first, path);
        std::string child = key_segment(path, k);
        if (!seen.insert(k).second) error(it->first, child, "duplicate key", "duplicate_key");
        count(it->second, child, depth + 1);
        check_tag(it->second, child);
        out.append_unchecked(k, walk_free(it->second, child, depth + 1));
      }
      return json::Value(std::move(out));
    }
    if (n.IsSequence()) {
      json::Array out;
      size_t i = 0;
      for (const auto& item : n) {
        std::string child = index_segment(path, i++);
        count(item, child, depth + 1);
        check_tag(item, child);
        out.push_back(walk_free(item, child, depth + 1));
      }
      return json::Value(std::move(out));
    }
    if (!n.IsScalar()) return json::Value();
    Scalar sc = resolve(n);
    switch (sc.kind) {
      case ScalarKind::kNull:
        return json::Value();
      case ScalarKind::kBool:
        return json::Value(sc.b);
      case ScalarKind::kInt:
        if (sc.int_overflow) return json::Value(sc.text);
        return json::Value(sc.i);
      case ScalarKind::kFloat:
        if (!std::isfinite(sc.d)) return json::Value(sc.text);
        return json::Value(sc.d);
      case ScalarKind::kString:
        break;
    }
    if (!json::valid_utf8(sc.text)) error(n, path, "string is not valid UTF-8", "invalid_value");
    return json::Value(std::move(sc.text));
  }

  size_t nodes_ = 0;
  std::unordered_map<std::string, YAML::Mark> marks_;
};

std::string location(const YAML::Mark& m) {
  if (m.is_null() || m.line < 0) return {};
  return " (line " + std::to_string(m.line + 1) + ", column " + std::to_string(m.column + 1) + ")";
}

}  // namespace

Error make_error(const std::string& path, const std::string& msg, const std::string& reason,
                 const std::string& loc) {
  std::string text = path.empty() ? msg : path + ": " + msg;
  return Error(ErrorCode::kSchemaValidationFailed, text + loc, path, reason);
}

Result<NodeConfig> parse_document(std::string_view yaml, const ConfigOptions& opts) {
  Validator v;
  try {
    const std::string text(yaml);
    int ndocs = count_documents(text);
    if (ndocs > 1)
      return make_error("", "unexpected content after the first YAML document (one document only)",
                        "malformed_yaml", "");
    YAML::Node doc = ndocs == 0 ? YAML::Node() : YAML::Load(text);
    if (!doc.IsDefined() || doc.IsNull())
      return make_error("", "the config file is empty", "missing_key", "");
    if (!doc.IsMap())
      return make_error("", "the config file must be a YAML mapping, got " + describe(doc),
                        "wrong_type", location(doc.Mark()));
    json::Value typed = v.run(doc);
    NodeConfig cfg = build(typed, opts);
    cfg.source = opts.source_name;
    return cfg;
  } catch (const ConfigError& e) {
    std::string loc = v.last_mark ? location(*v.last_mark) : std::string();
    if (loc.empty()) {
      // Pass-2 errors: the mark of the path, or of its nearest recorded parent.
      std::string p = e.path;
      while (!p.empty()) {
        if (const YAML::Mark* m = v.mark_of(p)) {
          loc = location(*m);
          break;
        }
        size_t cut = p.find_last_of(".[");
        if (cut == std::string::npos) break;
        p.resize(cut);
      }
    }
    return make_error(e.path, e.message, e.reason, loc);
  } catch (const YAML::DeepRecursion& e) {
    return make_error("", "YAML nesting too deep", "too_large", location(e.mark));
  } catch (const YAML::Exception& e) {
    return make_error("", "malformed YAML: " + printable(e.msg, 200), "malformed_yaml",
                      location(e.mark));
  } catch (const std::bad_alloc&) {
    return make_error("", "config too large (out of memory)", "too_large", "");
  } catch (const std::exception& e) {
    return make_error("", std::string("cannot parse config: ") + e.what(), "malformed_yaml", "");
  }
}

}  // namespace rcan::config::internal

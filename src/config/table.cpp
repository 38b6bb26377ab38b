// The schema builders the block tables use, the names the validator's messages give them,
// and path resolution.
#include "config/table.h"

#include <cstdio>
#include <cstdlib>
#include <filesystem>

namespace rcan::config::internal {
namespace {

SP make(Schema s) { return std::make_shared<const Schema>(std::move(s)); }

}  // namespace

SP Str(size_t max_len) {
  Schema s;
  s.k = Schema::K::kString;
  s.max_len = max_len;
  return make(std::move(s));
}
SP Enum(std::initializer_list<const char*> values) {
  Schema s;
  s.k = Schema::K::kString;
  for (const char* v : values) s.enums.emplace_back(v);
  return make(std::move(s));
}
SP Int(std::optional<double> lo, std::optional<double> hi) {
  Schema s;
  s.k = Schema::K::kInt;
  s.min = lo;
  s.max = hi;
  return make(std::move(s));
}
SP Num(std::optional<double> lo, std::optional<double> hi, bool lo_exclusive) {
  Schema s;
  s.k = Schema::K::kNumber;
  s.min = lo;
  s.max = hi;
  s.min_exclusive = lo_exclusive;
  return make(std::move(s));
}
SP Pos() { return Num(0.0, std::nullopt, true); }
SP NonNeg() { return Num(0.0); }
SP Bool() {
  Schema s;
  s.k = Schema::K::kBool;
  return make(std::move(s));
}
SP Obj(std::vector<std::pair<std::string, SP>> props, std::vector<std::string> required) {
  Schema s;
  s.k = Schema::K::kObject;
  s.props = std::move(props);
  s.required = std::move(required);
  return make(std::move(s));
}
SP Arr(SP items, size_t max_items) {
  Schema s;
  s.k = Schema::K::kArray;
  s.items = std::move(items);
  s.max_items = max_items;
  return make(std::move(s));
}
SP Either(std::vector<SP> alts) {
  Schema s;
  s.k = Schema::K::kEither;
  s.alts = std::move(alts);
  return make(std::move(s));
}
SP Free() {
  Schema s;
  s.k = Schema::K::kFree;
  return make(std::move(s));
}
SP StrList() { return Arr(Str()); }

std::string expected_name(const Schema& s) {
  switch (s.k) {
    case Schema::K::kString:
      return s.enums.empty() ? "a string" : "one of the listed strings";
    case Schema::K::kInt:
      return "an integer";
    case Schema::K::kNumber:
      return "a number";
    case Schema::K::kBool:
      return "a boolean";
    case Schema::K::kObject:
      return "a mapping";
    case Schema::K::kArray:
      return "a list";
    case Schema::K::kFree:
      return "a value";
    case Schema::K::kEither:
      break;
  }
  std::string out;
  for (size_t i = 0; i < s.alts.size(); ++i) {
    if (i) out += i + 1 == s.alts.size() ? " or " : ", ";
    out += expected_name(*s.alts[i]);
  }
  return out;
}

std::string join_enum(const std::vector<std::string>& v) {
  std::string out;
  for (size_t i = 0; i < v.size(); ++i) {
    if (i) out += ", ";
    out += v[i];
  }
  return out;
}

std::string fmt_num(double d) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", d);
  return buf;
}

template <>
const NodeConfig& defaults<NodeConfig>() {
  static const NodeConfig* d = new NodeConfig();
  return *d;
}

std::string resolve_path(const std::string& p, const std::string& base_dir) {
  namespace fs = std::filesystem;
  if (p.empty()) return p;
  if (p == "~" || p.rfind("~/", 0) == 0) {
    const char* home = std::getenv("HOME");
    if (home != nullptr && *home == '/')
      return (fs::path(home) / p.substr(p.size() > 1 ? 2 : 1)).lexically_normal().string();
  }
  fs::path path(p);
  if (path.is_absolute() || base_dir.empty()) return path.lexically_normal().string();
  return (fs::path(base_dir) / path).lexically_normal().string();
}

}  // namespace rcan::config::internal

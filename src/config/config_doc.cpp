// The key tables of docs/CONFIG.md from the block tables (config_doc.h).
#include "config/config_doc.h"

#include <cstdint>
#include <sstream>
#include <vector>

#include "config/table.h"

namespace rcan::config {
namespace {

using internal::KeyDoc;
using internal::Schema;

// A table cell: a `|` of the text must not end the cell.
std::string cell(const std::string& text) {
  std::string out;
  for (size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '|' && (i == 0 || text[i - 1] != '\\')) out += '\\';
    out += text[i];
  }
  return out;
}

// A bound as written in a file: 3600000, not 3.6e+06.
std::string fmt_num(double d) {
  if (d == static_cast<double>(static_cast<int64_t>(d)) && d > -1e15 && d < 1e15)
    return std::to_string(static_cast<int64_t>(d));
  return internal::fmt_num(d);
}

std::string range_text(const Schema& s) {
  if (s.min && s.max) return " " + fmt_num(*s.min) + "–" + fmt_num(*s.max);
  if (s.min) return (s.min_exclusive ? " > " : " ≥ ") + fmt_num(*s.min);
  if (s.max) return " ≤ " + fmt_num(*s.max);
  return "";
}

std::string type_text(const Schema& s) {
  switch (s.k) {
    case Schema::K::kString: {
      if (s.enums.empty()) return "string";
      std::string out;
      for (const std::string& e : s.enums) out += (out.empty() ? "`" : " | `") + e + "`";
      return out;
    }
    case Schema::K::kInt:
      return "integer" + range_text(s);
    case Schema::K::kNumber:
      return "number" + range_text(s);
    case Schema::K::kBool:
      return "bool";
    case Schema::K::kObject:
      return "mapping";
    case Schema::K::kArray: {
      if (!s.items) return "list";
      if (s.items->k == Schema::K::kObject) return "list of mappings";
      if (s.items->k == Schema::K::kString && s.items->enums.empty()) return "list of strings";
      return "list of " + type_text(*s.items);
    }
    case Schema::K::kFree:
      return "any";
    case Schema::K::kEither:
      break;
  }
  std::string out;
  for (size_t i = 0; i < s.alts.size(); ++i) out += (i ? " or " : "") + type_text(*s.alts[i]);
  return out;
}

// The rows of a mapping a key holds: its table's, else its schema's keys (a kept block).
std::vector<KeyDoc> keys_of(const KeyDoc& k) {
  if (!k.keys.empty()) return k.keys;
  const Schema* s = k.schema.get();
  if (s != nullptr && s->k == Schema::K::kArray && s->items) s = s->items.get();
  std::vector<KeyDoc> out;
  if (s == nullptr || s->k != Schema::K::kObject) return out;
  for (const auto& [key, schema] : s->props) {
    KeyDoc d;
    d.key = key;
    d.schema = schema;
    for (const std::string& r : s->required) d.is_required |= r == key;
    out.push_back(std::move(d));
  }
  return out;
}

// One line per key, its mapping's keys after it (a list's elements as `key[].sub`). A mapping
// without text of its own is not a line: its keys are.
void lines(const KeyDoc& k, const std::string& prefix, std::ostringstream& out) {
  if (k.key.empty()) return;  // a check between keys
  const std::string path = prefix + k.key;
  std::vector<KeyDoc> sub = keys_of(k);
  if (sub.empty() || !k.about.empty()) {
    std::string def = k.is_required ? "**required**" : k.shown_default;
    out << "| `" << path << "` | " << cell(type_text(*k.schema)) << " | " << cell(def) << " | "
        << cell(k.about) << " |\n";
  }
  const bool list = k.schema->k == Schema::K::kArray;
  for (const KeyDoc& s : sub) lines(s, path + (list ? "[]." : "."), out);
}

}  // namespace

Result<std::string> config_doc_table(std::string_view keys) {
  std::ostringstream out;
  out << "| key | type | default | meaning |\n|---|---|---|---|\n";
  std::istringstream names{std::string(keys)};
  for (std::string name; names >> name;) {
    const KeyDoc* found = nullptr;
    for (const KeyDoc& k : internal::document_rows())
      if (k.key == name) found = &k;
    if (found == nullptr) return Error(ErrorCode::kInternal, "not a top-level key: " + name);
    lines(*found, "", out);
  }
  return out.str();
}

Result<std::string> regenerate_config_doc(std::string_view markdown) {
  static constexpr std::string_view kOpen = "<!-- generated: ";
  static constexpr std::string_view kClose = "<!-- end generated -->";
  std::string out;
  size_t at = 0;
  for (size_t open; (open = markdown.find(kOpen, at)) != std::string_view::npos;) {
    const size_t name_end = markdown.find(" -->\n", open);
    const size_t close = markdown.find(kClose, open);
    if (name_end == std::string_view::npos || close == std::string_view::npos || close < name_end)
      return Error(ErrorCode::kInternal, "a generated region without its end");
    const size_t body = name_end + 5;
    auto table =
        config_doc_table(markdown.substr(open + kOpen.size(), name_end - open - kOpen.size()));
    if (!table.ok()) return table.error();
    out.append(markdown.substr(at, body - at));
    out += *table;
    at = close;
  }
  out.append(markdown.substr(at));
  return out;
}

}  // namespace rcan::config

// Key tables: each key of `.rcan.yaml` is one row that holds its schema (type, range, enum,
// required) and the code that reads it into the config struct; a block is a table of rows
// (blocks/*.cpp). The schema of a mapping is built from its table (object_of) and pass 2
// walks the same table in order (walk), so a key is written down once.
//
//   using R = Rows<MqttConfig>;
//   Table<MqttConfig> rows = {
//       R::field("enabled", Bool(), &MqttConfig::enabled),  // default: the member initializer
//       R::field("keepalive_s", Int(5, 3600), &MqttConfig::keepalive_s),
//       R::path("password_file", Str(), &MqttConfig::password_file),
//       R::check([](const At& mqtt, MqttConfig& m, Ctx&) { ... }),  // a rule between keys
//   };
//
// A row also carries the key's documentation: .doc("what it does") and, when the default is
// not a member's initializer, .default_text("how it is computed"). The default of a field row
// is read from a default-constructed struct (default_text_of), so it is written only in the
// member's initializer; docs/CONFIG.md's key tables are generated from the rows (config_doc.h).
//
// Rows are walked in table order, and a reader may fail(): the order of the rows is the
// order in which a file with several faults reports them, and a reader may use what the rows
// before it (in this table or an earlier block) have set. The order of the keys in the
// schema does not matter to the validator.
#pragma once

#include <cstddef>
#include <functional>
#include <initializer_list>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "config/config_internal.h"

namespace rcan::config::internal {

// ---------------------------------------------------------------------------------------
// Schema builders (table.cpp)

SP Str(size_t max_len = 4096);
SP Enum(std::initializer_list<const char*> values);
SP Int(std::optional<double> lo = std::nullopt, std::optional<double> hi = std::nullopt);
SP Num(std::optional<double> lo = std::nullopt, std::optional<double> hi = std::nullopt,
       bool lo_exclusive = false);
SP Pos();     // a number > 0
SP NonNeg();  // a number ≥ 0
SP Bool();
SP Obj(std::vector<std::pair<std::string, SP>> props, std::vector<std::string> required = {});
SP Arr(SP items, size_t max_items = 1024);
SP Either(std::vector<SP> alts);
SP Free();
SP StrList();

// ---------------------------------------------------------------------------------------
// Rows

// What a reader sees besides its own value and the struct it fills.
struct Ctx {
  At root;                    // the whole document (for aliases kept in other blocks)
  const ConfigOptions& opts;  // base_dir, device_id, default_data_dir
  NodeConfig& c;              // everything the rows before this one have set
};

// A default as the docs show it: numbers and booleans as written in YAML, a string in
// backticks, "unset"/"empty"/"none" for an absent optional, string or list, and nothing for
// a type the docs describe in words (an enum, a mapping).
template <typename M>
std::string default_text_of(const M& v);

// A default-constructed T: its members' initializers are the keys' defaults.
template <typename T>
const T& defaults() {
  static const T d{};
  return d;
}
// Out of line (table.cpp): inlined, the whole NodeConfig's constructor trips GCC's
// maybe-uninitialized analysis.
template <>
const NodeConfig& defaults<NodeConfig>();

// A key's documentation: what the generator of docs/CONFIG.md reads (config_doc.cpp).
struct KeyDoc {
  std::string key;  // empty: a check between keys, not a key of its own
  SP schema;        // type, range, enum (null for a check)
  bool is_required = false;
  std::string about;          // what the key does (markdown)
  std::string shown_default;  // the default as the docs show it; empty: none to show
  std::vector<KeyDoc> keys;   // a mapping's (or a list element's) own rows
};

template <typename T>
struct Row : KeyDoc {
  // `at` is the key's value (absent when the file does not give it); for a check, the
  // mapping the check belongs to.
  using Read = std::function<void(const At& at, T& out, Ctx& x)>;

  Read read;  // null: validated only (a kept block, or an alias another row reads)

  Row() = default;
  Row(std::string k, SP s, Read fn) : read(std::move(fn)) {
    key = std::move(k);
    schema = std::move(s);
  }

  Row required() && {
    is_required = true;
    return std::move(*this);
  }
  Row doc(std::string text) && {
    about = std::move(text);
    return std::move(*this);
  }
  // A default the member's initializer does not show (computed, or from another block).
  Row default_text(std::string text) && {
    shown_default = std::move(text);
    return std::move(*this);
  }
  // The default of a row with its own reader: `member`'s initializer.
  template <typename M>
  Row default_of(M T::*member) && {
    shown_default = default_text_of(defaults<T>().*member);
    return std::move(*this);
  }
  // The rows of the mapping this key holds (a list's elements, a mapping read by hand).
  template <typename U>
  Row with_keys(const std::vector<Row<U>>& rows) && {
    keys.assign(rows.begin(), rows.end());
    return std::move(*this);
  }
};

template <typename T>
using Table = std::vector<Row<T>>;

// Reads each row of `rows` at `at` (its key's value) into `out`, in order.
template <typename T>
void walk(const Table<T>& rows, const At& at, T& out, Ctx& x) {
  for (const Row<T>& r : rows) {
    if (r.read) r.read(r.key.empty() ? at : at[r.key], out, x);
  }
}

// The schema of a mapping whose keys are the table's rows.
template <typename T>
SP object_of(const Table<T>& rows) {
  std::vector<std::pair<std::string, SP>> props;
  std::vector<std::string> required;
  for (const Row<T>& r : rows) {
    if (r.key.empty()) continue;
    props.emplace_back(r.key, r.schema);
    if (r.is_required) required.push_back(r.key);
  }
  return Obj(std::move(props), std::move(required));
}

// One element of a list of mappings, read with the element's table.
template <typename E>
E element(const Table<E>& rows, const At& at, Ctx& x) {
  E e;
  walk(rows, at, e, x);
  return e;
}

template <typename M>
inline constexpr bool kIsOptional = false;
template <typename M>
inline constexpr bool kIsOptional<std::optional<M>> = true;

// A present value, as the member's type (the schema has checked its type and range).
template <typename M>
void assign(const At& a, M& out) {
  if constexpr (kIsOptional<M>) {
    typename M::value_type v{};
    assign(a, v);
    out = std::move(v);
  } else if constexpr (std::is_same_v<M, bool>) {
    out = a.v->as_bool();
  } else if constexpr (std::is_integral_v<M>) {
    out = static_cast<M>(a.v->as_int());
  } else if constexpr (std::is_same_v<M, double>) {
    out = a.v->to_double();
  } else if constexpr (std::is_same_v<M, std::string>) {
    out = a.v->as_string();
  } else if constexpr (std::is_same_v<M, std::vector<std::string>>) {
    out = a.strs();
  } else if constexpr (std::is_same_v<M, std::vector<double>>) {
    out.clear();
    for (size_t i = 0; i < a.size(); ++i) out.push_back(a[i].num());
  } else {
    static_assert(sizeof(M) == 0, "no reader for this member type");
  }
}

template <typename M>
std::string default_text_of(const M& v) {
  if constexpr (kIsOptional<M>) {
    return v ? default_text_of(*v) : "unset";
  } else if constexpr (std::is_same_v<M, bool>) {
    return v ? "true" : "false";
  } else if constexpr (std::is_integral_v<M>) {
    return std::to_string(v);
  } else if constexpr (std::is_same_v<M, double>) {
    return fmt_num(v);
  } else if constexpr (std::is_same_v<M, std::string>) {
    return v.empty() ? "empty" : "`" + v + "`";
  } else if constexpr (std::is_same_v<M, std::vector<std::string>> ||
                       std::is_same_v<M, std::vector<double>>) {
    if (v.empty()) return "none";
    std::string out;
    for (const auto& e : v) out += (out.empty() ? "" : ", ") + default_text_of(e);
    return out;
  } else {
    return {};
  }
}

// The row makers for a table that fills a T.
template <typename T>
struct Rows {
  using Read = typename Row<T>::Read;

  // A key read into a member; absent, the member keeps its initializer (the default).
  template <typename M>
  static Row<T> field(std::string key, SP schema, M T::*member) {
    Row<T> r(std::move(key), std::move(schema), [member](const At& a, T& out, Ctx&) {
      if (a) assign(a, out.*member);
    });
    return std::move(r).default_of(member);
  }
  // A file path, resolved against the config file's directory (resolve_path).
  static Row<T> path(std::string key, SP schema, std::string T::*member) {
    Row<T> r(std::move(key), std::move(schema), [member](const At& a, T& out, Ctx& x) {
      if (a) out.*member = resolve_path(a.str(), x.opts.base_dir);
    });
    return std::move(r).default_of(member);
  }
  // A key with its own reader (checks, aliases, conversions, defaults that are computed).
  static Row<T> read(std::string key, SP schema, Read fn) {
    return Row<T>(std::move(key), std::move(schema), std::move(fn));
  }
  // A rule between the keys of the mapping, run at this point of the table.
  static Row<T> check(Read fn) { return Row<T>(std::string(), nullptr, std::move(fn)); }
  // Validated, not read here: a kept block, or an alias that another row reads.
  static Row<T> schema_only(std::string key, SP schema) {
    return Row<T>(std::move(key), std::move(schema), nullptr);
  }
  // A mapping whose keys fill `project(out)`: a member pointer (&T::sub), or a function
  // returning a reference into T. Walked when absent too, so its rows see absent values.
  template <typename U, typename P>
  static Row<T> block(std::string key, Table<U> rows, P project) {
    SP schema = object_of(rows);
    std::vector<KeyDoc> keys(rows.begin(), rows.end());
    Row<T> r(std::move(key), std::move(schema),
             [rows = std::move(rows), project](const At& a, T& out, Ctx& x) {
               walk(rows, a, std::invoke(project, out), x);
             });
    r.keys = std::move(keys);
    return r;
  }
  // A mapping whose keys fill T itself.
  static Row<T> block(std::string key, Table<T> rows) {
    return block(std::move(key), std::move(rows), [](T& out) -> T& { return out; });
  }
};

// The rows of a U, as rows of the T that holds it in `member` (same keys, same schema).
template <typename T, typename U>
Table<T> lift(const Table<U>& rows, U T::*member) {
  Table<T> out;
  for (const Row<U>& r : rows) {
    typename Row<T>::Read fn;
    if (r.read) fn = [read = r.read, member](const At& a, T& t, Ctx& x) { read(a, t.*member, x); };
    Row<T> lifted(r.key, r.schema, std::move(fn));
    static_cast<KeyDoc&>(lifted) = r;
    out.push_back(std::move(lifted));
  }
  return out;
}

// Every top-level row of the document, in the order build() walks them (blocks/document.cpp).
const Table<NodeConfig>& document_rows();

}  // namespace rcan::config::internal

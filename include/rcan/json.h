// rcan::json — a small JSON document model built for a protocol that signs bytes.
//
// Why not a general-purpose library: RCAN pre-images depend on details that
// common libraries lose. This model keeps
//   * int vs float exactly as on the wire (`1` stays an integer, `1.0` a float),
//   * integers of any size exactly (beyond 64 bits they are kept as decimal digits),
//   * object members in wire order (serializers sort when the format asks for it),
// and its parser is strict: invalid UTF-8, duplicate keys, lone surrogates,
// trailing garbage, excessive depth or size are errors with a byte offset.
//
// Three writers:
//   canonical()    — rcan-canonical-json-v1 (sorted keys, raw UTF-8, whole floats as ints)
//   python_dumps() — byte-identical to Python's json.dumps(sort_keys=True,
//                    separators=(",", ":")) with ensure_ascii, used by rcan-py pre-images
//   dump()         — compact, wire order, raw UTF-8 (for replies and logs)
#pragma once

#include <cstdint>
#include <initializer_list>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "rcan/result.h"

namespace rcan::json {

class Value;
class Object;
using Array = std::vector<Value>;

class Value {
 public:
  enum class Kind : uint8_t { kNull, kBool, kInt, kBigInt, kDouble, kString, kArray, kObject };

  Value() = default;                                                // null
  Value(std::nullptr_t) {}                                          // NOLINT
  Value(bool b) : kind_(Kind::kBool), b_(b) {}                      // NOLINT
  Value(int i) : kind_(Kind::kInt), i_(i) {}                        // NOLINT
  Value(int64_t i) : kind_(Kind::kInt), i_(i) {}                    // NOLINT
  Value(uint64_t u);                                                // NOLINT big when > INT64_MAX
  Value(double d) : kind_(Kind::kDouble), d_(d) {}                  // NOLINT
  Value(const char* s) : kind_(Kind::kString), s_(s) {}             // NOLINT
  Value(std::string s) : kind_(Kind::kString), s_(std::move(s)) {}  // NOLINT
  Value(std::string_view s) : kind_(Kind::kString), s_(s) {}        // NOLINT
  Value(Array a);                                                   // NOLINT
  Value(Object o);                                                  // NOLINT

  // An integer written as decimal digits (optional leading '-'), kept exactly.
  static Value big_int(std::string digits);

  Value(const Value& other);
  Value(Value&& other) noexcept;
  Value& operator=(const Value& other);
  Value& operator=(Value&& other) noexcept;
  ~Value();

  Kind kind() const { return kind_; }
  bool is_null() const { return kind_ == Kind::kNull; }
  bool is_bool() const { return kind_ == Kind::kBool; }
  bool is_int() const { return kind_ == Kind::kInt; }  // fits int64
  bool is_integer() const { return kind_ == Kind::kInt || kind_ == Kind::kBigInt; }
  bool is_double() const { return kind_ == Kind::kDouble; }
  bool is_number() const { return is_integer() || is_double(); }
  bool is_string() const { return kind_ == Kind::kString; }
  bool is_array() const { return kind_ == Kind::kArray; }
  bool is_object() const { return kind_ == Kind::kObject; }

  bool as_bool() const { return b_; }
  int64_t as_int() const { return i_; }
  double as_double() const { return d_; }
  // Any number as double (big integers are converted, possibly inexactly).
  double to_double() const;
  const std::string& as_string() const { return s_; }  // string, or big-int digits
  const std::string& big_digits() const { return s_; }
  const Array& as_array() const { return *a_; }
  Array& as_array() { return *a_; }
  const Object& as_object() const { return *o_; }
  Object& as_object() { return *o_; }

  // Object member lookup; nullptr when not an object or absent.
  const Value* get(std::string_view key) const;
  Value* get(std::string_view key);

  bool operator==(const Value& other) const;
  bool operator!=(const Value& other) const { return !(*this == other); }

 private:
  void destroy();
  void copy_from(const Value& other);
  void move_from(Value&& other) noexcept;

  Kind kind_ = Kind::kNull;
  bool b_ = false;
  int64_t i_ = 0;
  double d_ = 0.0;
  std::string s_;
  std::unique_ptr<Array> a_;
  std::unique_ptr<Object> o_;
};

using Member = std::pair<std::string, Value>;

// An object keeps members in insertion order. Keys are unique (set() replaces).
class Object {
 public:
  Object() = default;
  Object(std::initializer_list<Member> init);

  const Value* find(std::string_view key) const;
  Value* find(std::string_view key);
  bool contains(std::string_view key) const { return find(key) != nullptr; }
  // Inserts or replaces.
  Value& set(std::string key, Value v);
  bool erase(std::string_view key);
  // Appends without checking for an existing key (parser use; callers guarantee uniqueness).
  void append_unchecked(std::string key, Value v);

  size_t size() const { return members_.size(); }
  bool empty() const { return members_.empty(); }
  auto begin() const { return members_.begin(); }
  auto end() const { return members_.end(); }
  auto begin() { return members_.begin(); }
  auto end() { return members_.end(); }
  const std::vector<Member>& members() const { return members_; }

  bool operator==(const Object& other) const;

 private:
  std::vector<Member> members_;
};

struct ParseOptions {
  size_t max_depth = 64;              // nesting of arrays/objects
  size_t max_bytes = 1 << 20;         // input size
  size_t max_string_bytes = 1 << 20;  // one decoded string
  size_t max_number_chars = 400;      // one number lexeme
  bool allow_duplicate_keys = false;
};

// Parses one JSON text (RFC 8259) with surrounding whitespace. Errors carry
// ErrorCode::kMalformedJson and a message naming the byte offset.
Result<Value> parse(std::string_view text, const ParseOptions& opts = {});

// rcan-canonical-json-v1: keys sorted by code point at every depth, no whitespace,
// raw UTF-8, controls escaped, whole floats written as integers (-0.0 → 0),
// other floats in Python repr form.
std::string canonical(const Value& v);
std::string canonical(const Object& obj);  // the same as canonical(Value(obj)), without the copy
// Canonical JSON of `obj` without one top-level key (e.g. "sig" or "hmac").
std::string canonical_without(const Object& obj, std::string_view excluded_key);

// Python json.dumps(v, sort_keys=sort_keys, separators=(",",":") if compact else (", ",": "),
// ensure_ascii=True). Floats use Python repr (1.0, 1e-05, 1e+16).
std::string python_dumps(const Value& v, bool sort_keys = true, bool compact = true);

// Compact, members in stored order, raw UTF-8; floats in Python repr form.
std::string dump(const Value& v);

// Lenient readers of one member, for stored state and request bodies: the member `key` of `v`
// when `v` is an object holding it with that kind, otherwise `def`.
//   int64_t end = json::int_field(lease, "end_ms");   // 0 when absent or not an integer
std::string string_field(const Value& v, std::string_view key, std::string_view def = {});
int64_t int_field(const Value& v, std::string_view key, int64_t def = 0);
bool bool_field(const Value& v, std::string_view key, bool def = false);
// Appends `s` as a JSON string literal, as dump() and canonical() write a string. `s` must not
// point into `out` (appending may move `out`'s bytes).
void append_string(std::string& out, std::string_view s);

// Python repr() of a float: shortest round-trip digits, "1.0", "1e-05", "1e+16", "inf", "nan".
std::string python_float_repr(double d);

// Exact decimal expansion of an integral double (e.g. 1e300 → "1000…0").
std::string integral_double_to_string(double d);

// True when `s` is valid UTF-8 (no overlongs, no surrogates, ≤ U+10FFFF).
bool valid_utf8(std::string_view s);

}  // namespace rcan::json

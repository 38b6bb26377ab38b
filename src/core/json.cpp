// rcan::json — parser and the three writers. See include/rcan/json.h for the contract.
#include "rcan/json.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <unordered_set>

namespace rcan::json {

// ---------------------------------------------------------------------------------------------
// Object

Object::Object(std::initializer_list<Member> init) {
  for (const auto& m : init) set(m.first, m.second);
}

const Value* Object::find(std::string_view key) const {
  for (const auto& m : members_)
    if (m.first == key) return &m.second;
  return nullptr;
}

Value* Object::find(std::string_view key) {
  for (auto& m : members_)
    if (m.first == key) return &m.second;
  return nullptr;
}

Value& Object::set(std::string key, Value v) {
  if (Value* existing = find(key)) {
    *existing = std::move(v);
    return *existing;
  }
  members_.emplace_back(std::move(key), std::move(v));
  return members_.back().second;
}

bool Object::erase(std::string_view key) {
  for (auto it = members_.begin(); it != members_.end(); ++it) {
    if (it->first == key) {
      members_.erase(it);
      return true;
    }
  }
  return false;
}

void Object::append_unchecked(std::string key, Value v) {
  members_.emplace_back(std::move(key), std::move(v));
}

bool Object::operator==(const Object& other) const {
  if (members_.size() != other.members_.size()) return false;
  for (const auto& m : members_) {
    const Value* o = other.find(m.first);
    if (!o || !(*o == m.second)) return false;
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// Value

Value::Value(uint64_t u) {
  if (u <= static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) {
    kind_ = Kind::kInt;
    i_ = static_cast<int64_t>(u);
  } else {
    kind_ = Kind::kBigInt;
    s_ = std::to_string(u);
  }
}

Value::Value(Array a) : kind_(Kind::kArray), a_(std::make_unique<Array>(std::move(a))) {}
Value::Value(Object o) : kind_(Kind::kObject), o_(std::make_unique<Object>(std::move(o))) {}

Value Value::big_int(std::string digits) {
  // Normalise: an integer that fits int64 is stored as kInt.
  int64_t v = 0;
  auto [p, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), v);
  if (ec == std::errc() && p == digits.data() + digits.size()) return Value(v);
  Value out;
  out.kind_ = Kind::kBigInt;
  out.s_ = std::move(digits);
  return out;
}

Value::Value(const Value& other) { copy_from(other); }
Value::Value(Value&& other) noexcept { move_from(std::move(other)); }
Value& Value::operator=(const Value& other) {
  if (this != &other) {
    Value tmp(other);
    destroy();
    move_from(std::move(tmp));
  }
  return *this;
}
Value& Value::operator=(Value&& other) noexcept {
  if (this != &other) {
    destroy();
    move_from(std::move(other));
  }
  return *this;
}
Value::~Value() = default;

void Value::destroy() {
  a_.reset();
  o_.reset();
  s_.clear();
  kind_ = Kind::kNull;
}

void Value::copy_from(const Value& other) {
  kind_ = other.kind_;
  b_ = other.b_;
  i_ = other.i_;
  d_ = other.d_;
  s_ = other.s_;
  if (other.a_) a_ = std::make_unique<Array>(*other.a_);
  if (other.o_) o_ = std::make_unique<Object>(*other.o_);
}

void Value::move_from(Value&& other) noexcept {
  kind_ = other.kind_;
  b_ = other.b_;
  i_ = other.i_;
  d_ = other.d_;
  s_ = std::move(other.s_);
  a_ = std::move(other.a_);
  o_ = std::move(other.o_);
  other.kind_ = Kind::kNull;
}

double Value::to_double() const {
  switch (kind_) {
    case Kind::kInt:
      return static_cast<double>(i_);
    case Kind::kDouble:
      return d_;
    case Kind::kBigInt:
      return std::strtod(s_.c_str(), nullptr);
    default:
      return 0.0;
  }
}

const Value* Value::get(std::string_view key) const {
  return kind_ == Kind::kObject ? o_->find(key) : nullptr;
}
Value* Value::get(std::string_view key) { return kind_ == Kind::kObject ? o_->find(key) : nullptr; }

std::string string_field(const Value& v, std::string_view key, std::string_view def) {
  const Value* f = v.get(key);
  return f != nullptr && f->is_string() ? f->as_string() : std::string(def);
}

int64_t int_field(const Value& v, std::string_view key, int64_t def) {
  const Value* f = v.get(key);
  return f != nullptr && f->is_int() ? f->as_int() : def;
}

bool bool_field(const Value& v, std::string_view key, bool def) {
  const Value* f = v.get(key);
  return f != nullptr && f->is_bool() ? f->as_bool() : def;
}

bool Value::operator==(const Value& other) const {
  if (kind_ != other.kind_) return false;
  switch (kind_) {
    case Kind::kNull:
      return true;
    case Kind::kBool:
      return b_ == other.b_;
    case Kind::kInt:
      return i_ == other.i_;
    case Kind::kDouble:
      return d_ == other.d_;
    case Kind::kBigInt:
    case Kind::kString:
      return s_ == other.s_;
    case Kind::kArray:
      return *a_ == *other.a_;
    case Kind::kObject:
      return *o_ == *other.o_;
  }
  return false;
}

// ---------------------------------------------------------------------------------------------
// UTF-8

namespace {

// Decodes one UTF-8 sequence at s[i]; returns its length (0 when invalid) and the code point.
size_t decode_utf8(std::string_view s, size_t i, uint32_t& cp) {
  const auto* p = reinterpret_cast<const unsigned char*>(s.data());
  size_t n = s.size();
  unsigned char c = p[i];
  if (c < 0x80) {
    cp = c;
    return 1;
  }
  size_t len;
  uint32_t min;
  if ((c & 0xE0) == 0xC0) {
    len = 2;
    cp = c & 0x1F;
    min = 0x80;
  } else if ((c & 0xF0) == 0xE0) {
    len = 3;
    cp = c & 0x0F;
    min = 0x800;
  } else if ((c & 0xF8) == 0xF0) {
    len = 4;
    cp = c & 0x07;
    min = 0x10000;
  } else {
    return 0;
  }
  if (i + len > n) return 0;
  for (size_t k = 1; k < len; ++k) {
    unsigned char cc = p[i + k];
    if ((cc & 0xC0) != 0x80) return 0;
    cp = (cp << 6) | (cc & 0x3F);
  }
  if (cp < min || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
  return len;
}

// The index (i <= stop) of the first byte in s[i, stop) that a JSON string does not carry as it is:
// a quote, a backslash, a control character, or a byte of a multi-byte UTF-8 sequence (which the
// callers check one sequence at a time); `stop` when there is none. Eight bytes at a time: a
// fleet message's token and signature are some KiB of base64 with nothing to escape. Each test
// below is exact about whether such a byte is in the word (the borrow of a subtraction only
// reaches bytes above one that matched); the byte loop then finds it.
size_t plain_end(const char* s, size_t i, size_t stop) {
  constexpr uint64_t kOnes = 0x0101010101010101ULL;
  constexpr uint64_t kHigh = 0x8080808080808080ULL;
  while (stop - i >= 8) {
    uint64_t x;
    std::memcpy(&x, s + i, 8);
    const uint64_t quote = x ^ (kOnes * '"');
    const uint64_t backslash = x ^ (kOnes * '\\');
    const uint64_t control = (x - kOnes * 0x20) & ~x;  // a byte < 0x20 (bytes >= 0x80 aside)
    const uint64_t has_quote = (quote - kOnes) & ~quote;
    const uint64_t has_backslash = (backslash - kOnes) & ~backslash;
    if ((x | control | has_quote | has_backslash) & kHigh) break;
    i += 8;
  }
  for (; i < stop; ++i) {
    const auto d = static_cast<unsigned char>(s[i]);
    if (d == '"' || d == '\\' || d < 0x20 || d >= 0x80) break;
  }
  return i;
}

void append_utf8(std::string& out, uint32_t cp) {
  if (cp < 0x80) {
    out.push_back(static_cast<char>(cp));
  } else if (cp < 0x800) {
    out.push_back(static_cast<char>(0xC0 | (cp >> 6)));
    out.push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else if (cp < 0x10000) {
    out.push_back(static_cast<char>(0xE0 | (cp >> 12)));
    out.push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out.push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else {
    out.push_back(static_cast<char>(0xF0 | (cp >> 18)));
    out.push_back(static_cast<char>(0x80 | ((cp >> 12) & 0x3F)));
    out.push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out.push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  }
}

}  // namespace

bool valid_utf8(std::string_view s) {
  size_t i = 0;
  uint32_t cp;
  while (i < s.size()) {
    size_t len = decode_utf8(s, i, cp);
    if (len == 0) return false;
    i += len;
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// Parser

namespace {

class Parser {
 public:
  Parser(std::string_view text, const ParseOptions& opts) : s_(text), opts_(opts) {}

  Result<Value> run() {
    if (s_.size() > opts_.max_bytes) {
      return Error(ErrorCode::kBodyTooLarge, "JSON text of " + std::to_string(s_.size()) +
                                                 " bytes exceeds the limit of " +
                                                 std::to_string(opts_.max_bytes));
    }
    skip_ws();
    Value v;
    if (!parse_value(v, 0)) return fail_result();
    skip_ws();
    if (pos_ != s_.size()) {
      set_error("unexpected data after the JSON value");
      return fail_result();
    }
    return v;
  }

 private:
  Result<Value> fail_result() {
    return Error(ErrorCode::kMalformedJson,
                 "malformed JSON at byte " + std::to_string(err_pos_) + ": " + err_);
  }

  bool set_error(std::string msg) {
    if (err_.empty()) {
      err_ = std::move(msg);
      err_pos_ = pos_;
    }
    return false;
  }

  void skip_ws() {
    while (pos_ < s_.size()) {
      char c = s_[pos_];
      if (c == ' ' || c == '\t' || c == '\n' || c == '\r')
        ++pos_;
      else
        break;
    }
  }

  bool literal(std::string_view word) {
    if (s_.substr(pos_, word.size()) != word) return set_error("invalid literal");
    pos_ += word.size();
    return true;
  }

  bool parse_value(Value& out, size_t depth) {
    if (pos_ >= s_.size()) return set_error("unexpected end of input");
    char c = s_[pos_];
    switch (c) {
      case '{':
        return parse_object(out, depth + 1);
      case '[':
        return parse_array(out, depth + 1);
      case '"': {
        std::string str;
        if (!parse_string(str)) return false;
        out = Value(std::move(str));
        return true;
      }
      case 't':
        if (!literal("true")) return false;
        out = Value(true);
        return true;
      case 'f':
        if (!literal("false")) return false;
        out = Value(false);
        return true;
      case 'n':
        if (!literal("null")) return false;
        out = Value();
        return true;
      default:
        if (c == '-' || (c >= '0' && c <= '9')) return parse_number(out);
        return set_error(
            std::string("unexpected character '") +
            (static_cast<unsigned char>(c) >= 0x20 && static_cast<unsigned char>(c) < 0x7f
                 ? std::string(1, c)
                 : "\\x" + to_hex2(static_cast<unsigned char>(c))) +
            "'");
    }
  }

  static std::string to_hex2(unsigned char c) {
    static const char* h = "0123456789abcdef";
    return std::string{h[c >> 4], h[c & 15]};
  }

  bool parse_object(Value& out, size_t depth) {
    if (depth > opts_.max_depth)
      return set_error("nesting deeper than " + std::to_string(opts_.max_depth));
    ++pos_;  // '{'
    Object obj;
    std::unordered_set<std::string> seen;
    skip_ws();
    if (pos_ < s_.size() && s_[pos_] == '}') {
      ++pos_;
      out = Value(std::move(obj));
      return true;
    }
    while (true) {
      skip_ws();
      if (pos_ >= s_.size()) return set_error("unexpected end of input in object");
      if (s_[pos_] != '"') return set_error("expected a string key");
      std::string key;
      size_t key_pos = pos_;
      if (!parse_string(key)) return false;
      if (!opts_.allow_duplicate_keys) {
        bool dup;
        if (obj.size() < 8) {
          dup = obj.find(key) != nullptr;
        } else {
          if (seen.empty())
            for (const auto& m : obj) seen.insert(m.first);
          dup = !seen.insert(key).second;
        }
        if (dup) {
          pos_ = key_pos;
          return set_error("duplicate key \"" + printable(key) + "\"");
        }
      }
      skip_ws();
      if (pos_ >= s_.size() || s_[pos_] != ':') return set_error("expected ':' after key");
      ++pos_;
      skip_ws();
      Value v;
      if (!parse_value(v, depth)) return false;
      if (opts_.allow_duplicate_keys)
        obj.set(std::move(key), std::move(v));
      else
        obj.append_unchecked(std::move(key), std::move(v));
      skip_ws();
      if (pos_ >= s_.size()) return set_error("unexpected end of input in object");
      if (s_[pos_] == ',') {
        ++pos_;
        continue;
      }
      if (s_[pos_] == '}') {
        ++pos_;
        break;
      }
      return set_error("expected ',' or '}' in object");
    }
    out = Value(std::move(obj));
    return true;
  }

  static std::string printable(const std::string& s) {
    std::string out;
    for (char c : s.substr(0, 64)) out.push_back(static_cast<unsigned char>(c) < 0x20 ? '?' : c);
    return out;
  }

  bool parse_array(Value& out, size_t depth) {
    if (depth > opts_.max_depth)
      return set_error("nesting deeper than " + std::to_string(opts_.max_depth));
    ++pos_;  // '['
    Array arr;
    skip_ws();
    if (pos_ < s_.size() && s_[pos_] == ']') {
      ++pos_;
      out = Value(std::move(arr));
      return true;
    }
    while (true) {
      skip_ws();
      if (!parse_value(arr.emplace_back(), depth)) return false;
      skip_ws();
      if (pos_ >= s_.size()) return set_error("unexpected end of input in array");
      if (s_[pos_] == ',') {
        ++pos_;
        continue;
      }
      if (s_[pos_] == ']') {
        ++pos_;
        break;
      }
      return set_error("expected ',' or ']' in array");
    }
    out = Value(std::move(arr));
    return true;
  }

  bool hex4(uint32_t& v) {
    if (pos_ + 4 > s_.size()) return set_error("truncated \\u escape");
    v = 0;
    for (int k = 0; k < 4; ++k) {
      char c = s_[pos_ + k];
      int d;
      if (c >= '0' && c <= '9')
        d = c - '0';
      else if (c >= 'a' && c <= 'f')
        d = c - 'a' + 10;
      else if (c >= 'A' && c <= 'F')
        d = c - 'A' + 10;
      else
        return set_error("invalid \\u escape");
      v = (v << 4) | static_cast<uint32_t>(d);
    }
    pos_ += 4;
    return true;
  }

  bool parse_string(std::string& out) {
    ++pos_;  // opening quote
    while (true) {
      if (pos_ >= s_.size()) return set_error("unterminated string");
      if (out.size() > opts_.max_string_bytes) return set_error("string longer than the limit");
      unsigned char c = static_cast<unsigned char>(s_[pos_]);
      if (c == '"') {
        ++pos_;
        return true;
      }
      if (c < 0x20) return set_error("unescaped control character in string");
      if (c == '\\') {
        ++pos_;
        if (pos_ >= s_.size()) return set_error("unterminated escape");
        char e = s_[pos_++];
        switch (e) {
          case '"':
            out.push_back('"');
            break;
          case '\\':
            out.push_back('\\');
            break;
          case '/':
            out.push_back('/');
            break;
          case 'b':
            out.push_back('\b');
            break;
          case 'f':
            out.push_back('\f');
            break;
          case 'n':
            out.push_back('\n');
            break;
          case 'r':
            out.push_back('\r');
            break;
          case 't':
            out.push_back('\t');
            break;
          case 'u': {
            uint32_t cp;
            if (!hex4(cp)) return false;
            if (cp >= 0xD800 && cp <= 0xDBFF) {
              if (s_.substr(pos_, 2) != "\\u") return set_error("lone high surrogate");
              pos_ += 2;
              uint32_t lo;
              if (!hex4(lo)) return false;
              if (lo < 0xDC00 || lo > 0xDFFF) return set_error("invalid low surrogate");
              cp = 0x10000 + ((cp - 0xD800) << 10) + (lo - 0xDC00);
            } else if (cp >= 0xDC00 && cp <= 0xDFFF) {
              return set_error("lone low surrogate");
            }
            append_utf8(out, cp);
            break;
          }
          default:
            --pos_;
            return set_error("invalid escape character");
        }
        continue;
      }
      if (c < 0x80) {
        // A run of plain characters goes in at once. It stops one character past the size
        // limit at the latest, so the check at the loop's top refuses exactly where it would
        // one character at a time.
        const size_t room = opts_.max_string_bytes - out.size();  // out.size() <= the limit here
        const size_t stop = room >= s_.size() - pos_ ? s_.size() : pos_ + room + 1;
        const size_t end = plain_end(s_.data(), pos_ + 1, stop);
        out.append(s_.data() + pos_, end - pos_);
        pos_ = end;
        continue;
      }
      uint32_t cp;
      size_t len = decode_utf8(s_, pos_, cp);
      if (len == 0) return set_error("invalid UTF-8 in string");
      out.append(s_.substr(pos_, len));
      pos_ += len;
    }
  }

  bool parse_number(Value& out) {
    size_t start = pos_;
    bool is_float = false;
    if (s_[pos_] == '-') ++pos_;
    if (pos_ >= s_.size()) return set_error("truncated number");
    if (s_[pos_] == '0') {
      ++pos_;
      if (pos_ < s_.size() && s_[pos_] >= '0' && s_[pos_] <= '9')
        return set_error("leading zero in number");
    } else if (s_[pos_] >= '1' && s_[pos_] <= '9') {
      while (pos_ < s_.size() && s_[pos_] >= '0' && s_[pos_] <= '9') ++pos_;
    } else {
      return set_error("invalid number");
    }
    if (pos_ < s_.size() && s_[pos_] == '.') {
      is_float = true;
      ++pos_;
      size_t d = pos_;
      while (pos_ < s_.size() && s_[pos_] >= '0' && s_[pos_] <= '9') ++pos_;
      if (pos_ == d) return set_error("missing digits after decimal point");
    }
    if (pos_ < s_.size() && (s_[pos_] == 'e' || s_[pos_] == 'E')) {
      is_float = true;
      ++pos_;
      if (pos_ < s_.size() && (s_[pos_] == '+' || s_[pos_] == '-')) ++pos_;
      size_t d = pos_;
      while (pos_ < s_.size() && s_[pos_] >= '0' && s_[pos_] <= '9') ++pos_;
      if (pos_ == d) return set_error("missing exponent digits");
    }
    std::string_view lex = s_.substr(start, pos_ - start);
    if (lex.size() > opts_.max_number_chars) {
      pos_ = start;
      return set_error("number longer than " + std::to_string(opts_.max_number_chars) +
                       " characters");
    }
    if (!is_float) {
      int64_t v = 0;
      auto [p, ec] = std::from_chars(lex.data(), lex.data() + lex.size(), v);
      if (ec == std::errc() && p == lex.data() + lex.size()) {
        out = Value(v);
      } else {
        out = Value::big_int(std::string(lex));
      }
      return true;
    }
    std::string buf(lex);
    char* end = nullptr;
    errno = 0;
    double d = std::strtod(buf.c_str(), &end);
    if (end != buf.c_str() + buf.size()) {
      pos_ = start;
      return set_error("invalid number");
    }
    if (!std::isfinite(d)) {
      pos_ = start;
      return set_error("number out of range");
    }
    out = Value(d);
    return true;
  }

  std::string_view s_;
  const ParseOptions& opts_;
  size_t pos_ = 0;
  std::string err_;
  size_t err_pos_ = 0;
};

}  // namespace

Result<Value> parse(std::string_view text, const ParseOptions& opts) {
  Parser p(text, opts);
  return p.run();
}

// ---------------------------------------------------------------------------------------------
// Number formatting

std::string python_float_repr(double d) {
  if (std::isnan(d)) return "nan";
  if (std::isinf(d)) return d < 0 ? "-inf" : "inf";
  if (d == 0.0) return std::signbit(d) ? "-0.0" : "0.0";
  char buf[64];
  auto res = std::to_chars(buf, buf + sizeof buf, d, std::chars_format::scientific);
  std::string sci(buf, res.ptr);
  // sci: [-]D[.DDD]e[+-]XX
  bool neg = false;
  size_t i = 0;
  if (sci[0] == '-') {
    neg = true;
    i = 1;
  }
  size_t epos = sci.find('e');
  std::string digits;
  for (size_t k = i; k < epos; ++k)
    if (sci[k] != '.') digits.push_back(sci[k]);
  int exp10 = std::atoi(sci.c_str() + epos + 1);
  // Drop trailing zeros the shortest form may not have (defensive).
  while (digits.size() > 1 && digits.back() == '0') digits.pop_back();
  int decpt = exp10 + 1;
  std::string out = neg ? "-" : "";
  int nd = static_cast<int>(digits.size());
  if (decpt <= -4 || decpt > 16) {
    out += digits[0];
    if (nd > 1) {
      out += '.';
      out.append(digits, 1);
    }
    char eb[16];
    std::snprintf(eb, sizeof eb, "e%c%02d", exp10 < 0 ? '-' : '+', exp10 < 0 ? -exp10 : exp10);
    out += eb;
  } else if (decpt <= 0) {
    out += "0.";
    out.append(static_cast<size_t>(-decpt), '0');
    out += digits;
  } else if (decpt < nd) {
    out.append(digits, 0, static_cast<size_t>(decpt));
    out += '.';
    out.append(digits, static_cast<size_t>(decpt));
  } else {
    out += digits;
    out.append(static_cast<size_t>(decpt - nd), '0');
    out += ".0";
  }
  return out;
}

std::string integral_double_to_string(double d) {
  if (d == 0.0) return "0";
  if (std::fabs(d) < 9.2e18) return std::to_string(static_cast<int64_t>(d));
  bool neg = d < 0;
  int exp2 = 0;
  double m = std::frexp(std::fabs(d), &exp2);  // |d| = m * 2^exp2, m in [0.5, 1)
  uint64_t mant = static_cast<uint64_t>(std::ldexp(m, 53));
  int shift = exp2 - 53;  // > 0 here
  // Little-endian base-1e9 bignum.
  std::vector<uint32_t> limbs;
  while (mant) {
    limbs.push_back(static_cast<uint32_t>(mant % 1000000000u));
    mant /= 1000000000u;
  }
  while (shift > 0) {
    int step = std::min(shift, 30);
    uint64_t carry = 0;
    for (auto& l : limbs) {
      uint64_t v = (static_cast<uint64_t>(l) << step) + carry;
      l = static_cast<uint32_t>(v % 1000000000u);
      carry = v / 1000000000u;
    }
    while (carry) {
      limbs.push_back(static_cast<uint32_t>(carry % 1000000000u));
      carry /= 1000000000u;
    }
    shift -= step;
  }
  std::string out = neg ? "-" : "";
  out += std::to_string(limbs.back());
  for (size_t k = limbs.size() - 1; k-- > 0;) {
    char b[16];
    std::snprintf(b, sizeof b, "%09u", limbs[k]);
    out += b;
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Writers

namespace {

enum class Style { kCanonical, kPython, kDump };

// Raw UTF-8. A string that is not valid UTF-8 (never one that was parsed; it can come from a
// request path or header) has each invalid byte written as the code point of its value, as
// write_string_ascii() does, so that the output is always valid JSON.
void write_string_raw(std::string& out, std::string_view s) {
  static const char* hex = "0123456789abcdef";
  out.push_back('"');
  for (size_t i = 0; i < s.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x80) {
      uint32_t cp;
      const size_t len = decode_utf8(s, i, cp);
      if (len == 0) {
        append_utf8(out, c);
      } else {
        out.append(s.substr(i, len));
        i += len - 1;
      }
      continue;
    }
    switch (c) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\b':
        out += "\\b";
        break;
      case '\f':
        out += "\\f";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\r':
        out += "\\r";
        break;
      case '\t':
        out += "\\t";
        break;
      default:
        if (c < 0x20) {
          out += "\\u00";
          out.push_back(hex[c >> 4]);
          out.push_back(hex[c & 15]);
        } else {
          // A run of characters that need no escape goes in at once.
          const size_t end = plain_end(s.data(), i + 1, s.size());
          out.append(s.substr(i, end - i));
          i = end - 1;
        }
    }
  }
  out.push_back('"');
}

void append_u_escape(std::string& out, uint32_t unit) {
  static const char* hex = "0123456789abcdef";
  out += "\\u";
  out.push_back(hex[(unit >> 12) & 15]);
  out.push_back(hex[(unit >> 8) & 15]);
  out.push_back(hex[(unit >> 4) & 15]);
  out.push_back(hex[unit & 15]);
}

// Python json.dumps with ensure_ascii=True: everything outside ' '..'~' is escaped.
void write_string_ascii(std::string& out, const std::string& s) {
  out.push_back('"');
  size_t i = 0;
  while (i < s.size()) {
    unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7f) {
      if (c == '"')
        out += "\\\"";
      else if (c == '\\')
        out += "\\\\";
      else
        out.push_back(static_cast<char>(c));
      ++i;
      continue;
    }
    switch (c) {
      case '\b':
        out += "\\b";
        ++i;
        continue;
      case '\f':
        out += "\\f";
        ++i;
        continue;
      case '\n':
        out += "\\n";
        ++i;
        continue;
      case '\r':
        out += "\\r";
        ++i;
        continue;
      case '\t':
        out += "\\t";
        ++i;
        continue;
      default:
        break;
    }
    uint32_t cp;
    size_t len = decode_utf8(s, i, cp);
    if (len == 0) {  // not reachable for parsed input; escape the raw byte as a code point
      cp = c;
      len = 1;
    }
    if (cp >= 0x10000) {
      uint32_t v = cp - 0x10000;
      append_u_escape(out, 0xD800 + (v >> 10));
      append_u_escape(out, 0xDC00 + (v & 0x3FF));
    } else {
      append_u_escape(out, cp);
    }
    i += len;
  }
  out.push_back('"');
}

void write_value(std::string& out, const Value& v, Style style, bool sort_keys, bool compact);

void write_number(std::string& out, const Value& v, Style style) {
  if (v.is_int()) {
    out += std::to_string(v.as_int());
  } else if (v.kind() == Value::Kind::kBigInt) {
    out += v.big_digits();
  } else {
    double d = v.as_double();
    if (!std::isfinite(d)) {
      if (style == Style::kPython)
        out += std::isnan(d) ? "NaN" : (d < 0 ? "-Infinity" : "Infinity");
      else
        out += "null";
      return;
    }
    if (style == Style::kCanonical && d == std::floor(d)) {
      out += integral_double_to_string(d);
    } else {
      out += python_float_repr(d);
    }
  }
}

void write_object(std::string& out, const Object& obj, Style style, bool sort_keys, bool compact);

void write_value(std::string& out, const Value& v, Style style, bool sort_keys, bool compact) {
  const char* item_sep = compact ? "," : ", ";
  switch (v.kind()) {
    case Value::Kind::kNull:
      out += "null";
      break;
    case Value::Kind::kBool:
      out += v.as_bool() ? "true" : "false";
      break;
    case Value::Kind::kInt:
    case Value::Kind::kBigInt:
    case Value::Kind::kDouble:
      write_number(out, v, style);
      break;
    case Value::Kind::kString:
      if (style == Style::kPython)
        write_string_ascii(out, v.as_string());
      else
        write_string_raw(out, v.as_string());
      break;
    case Value::Kind::kArray: {
      out.push_back('[');
      bool first = true;
      for (const auto& e : v.as_array()) {
        if (!first) out += item_sep;
        first = false;
        write_value(out, e, style, sort_keys, compact);
      }
      out.push_back(']');
      break;
    }
    case Value::Kind::kObject:
      write_object(out, v.as_object(), style, sort_keys, compact);
      break;
  }
}

void write_object(std::string& out, const Object& obj, Style style, bool sort_keys, bool compact) {
  const char* item_sep = compact ? "," : ", ";
  const char* key_sep = compact ? ":" : ": ";
  const auto& members = obj.members();
  std::vector<const Member*> order;
  order.reserve(members.size());
  for (const auto& m : members) order.push_back(&m);
  if (sort_keys) {
    // UTF-8 byte order equals code point order (char_traits<char> compares unsigned).
    std::sort(order.begin(), order.end(),
              [](const Member* a, const Member* b) { return a->first < b->first; });
  }
  out.push_back('{');
  bool first = true;
  for (const Member* m : order) {
    if (!first) out += item_sep;
    first = false;
    if (style == Style::kPython)
      write_string_ascii(out, m->first);
    else
      write_string_raw(out, m->first);
    out += key_sep;
    write_value(out, m->second, style, sort_keys, compact);
  }
  out.push_back('}');
}

}  // namespace

std::string canonical(const Value& v) {
  std::string out;
  write_value(out, v, Style::kCanonical, true, true);
  return out;
}

std::string canonical(const Object& obj) {
  std::string out;
  write_object(out, obj, Style::kCanonical, true, true);
  return out;
}

std::string canonical_without(const Object& obj, std::string_view excluded_key) {
  std::vector<const Member*> order;
  for (const auto& m : obj) {
    if (m.first != excluded_key) order.push_back(&m);
  }
  std::sort(order.begin(), order.end(),
            [](const Member* a, const Member* b) { return a->first < b->first; });
  std::string out = "{";
  bool first = true;
  for (const Member* m : order) {
    if (!first) out.push_back(',');
    first = false;
    write_string_raw(out, m->first);
    out.push_back(':');
    write_value(out, m->second, Style::kCanonical, true, true);
  }
  out.push_back('}');
  return out;
}

std::string python_dumps(const Value& v, bool sort_keys, bool compact) {
  std::string out;
  write_value(out, v, Style::kPython, sort_keys, compact);
  return out;
}

void append_string(std::string& out, std::string_view s) { write_string_raw(out, s); }

std::string dump(const Value& v) {
  std::string out;
  write_value(out, v, Style::kDump, false, true);
  return out;
}

}  // namespace rcan::json

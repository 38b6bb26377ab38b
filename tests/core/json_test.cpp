// rcan::json: the parser's strictness, the canonical writer (rcan-canonical-json-v1 vectors),
// the Python json.dumps writer (rcan-py pre-image vectors) and Python float repr.
#include "rcan/json.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <sstream>
#include <utility>
#include <vector>

#include "rcan/hash.h"
#include "test_support.h"

namespace rcan::json {
namespace {

std::string b64(const std::string& s) {
  auto b = base64_decode(s);
  EXPECT_TRUE(b.has_value());
  return b ? to_string(*b) : std::string();
}

TEST(CanonicalJson, EveryCaseOfTheSpecFixture) {
  Value v = test::load_vector("canonical-json-v1.json");
  const auto& cases = v.get("cases")->as_array();
  ASSERT_EQ(cases.size(), 12u);
  for (const auto& c : cases) {
    SCOPED_TRACE(c.get("name")->as_string());
    EXPECT_EQ(canonical(*c.get("input")), b64(c.get("expected_bytes_base64")->as_string()));
  }
}

TEST(CanonicalJson, EveryExtraCaseFromItsExactText) {
  Value v = test::load_vector("canonical-json-extra.json");
  const auto& cases = v.get("cases")->as_array();
  ASSERT_EQ(cases.size(), 23u);
  for (const auto& c : cases) {
    SCOPED_TRACE(c.get("name")->as_string());
    auto parsed = parse(c.get("input_json")->as_string());
    ASSERT_TRUE(parsed.ok()) << parsed.error().message;
    std::string expected = b64(c.get("expected_bytes_base64")->as_string());
    EXPECT_EQ(canonical(*parsed), expected);
    EXPECT_EQ(c.get("expected_utf8")->as_string(), expected);
  }
}

TEST(CanonicalJson, WithoutDropsOnlyTheNamedTopLevelKey) {
  auto v = parse(R"({"hmac":"x","b":{"hmac":1},"a":2})");
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(canonical_without(v->as_object(), "hmac"), R"({"a":2,"b":{"hmac":1}})");
}

TEST(PythonDumps, MatchesRcanPyPreimagesOfTheSignedFields) {
  Value v = test::load_vector("python-json-preimage.json");
  const auto& cases = v.get("cases")->as_array();
  ASSERT_EQ(cases.size(), 10u);
  int checked = 0;
  for (const auto& c : cases) {
    const std::string& name = c.get("name")->as_string();
    SCOPED_TRACE(name);
    // These two cases exercise rcan-py's target re-formatting and rcan/rcan_version
    // overwrite, which belong to the message-signature module (message_sig_test).
    if (name == "target_normalized" || name == "rcan_version_sync") continue;
    auto wire = parse(c.get("wire_json")->as_string());
    ASSERT_TRUE(wire.ok()) << wire.error().message;
    Object pre;
    for (const char* k : {"rcan", "msg_id", "timestamp", "cmd", "target", "params"}) {
      const Value* f = wire->get(k);
      pre.set(k, f ? *f : Value());
    }
    EXPECT_EQ(python_dumps(Value(pre)), c.get("preimage")->as_string());
    EXPECT_EQ(rcan::sha256_hex(python_dumps(Value(pre))), c.get("preimage_sha256")->as_string());
    ++checked;
  }
  EXPECT_EQ(checked, 8);
}

// A string built from raw bytes (a request path, found by http_handler_fuzz) that is not valid
// UTF-8 still gives valid JSON from every writer, each invalid byte as the code point of its value.
TEST(Writers, InvalidUtf8InAStringStillGivesValidJson) {
  const std::string raw = "no route for /\xf2/\xe2\x82/ok-\xc3\xa9-\xf0\x9f\x98\x80";
  Value v(Object{{"error", raw}, {std::string("k\xff"), int64_t{1}}});
  for (const std::string& text : {dump(v), canonical(v), python_dumps(v)}) {
    auto back = parse(text);
    ASSERT_TRUE(back.ok()) << text;
    const std::string& s = back->get("error")->as_string();
    EXPECT_EQ(s, "no route for /\u00f2/\u00e2\u0082/ok-\u00e9-\U0001F600") << text;
    EXPECT_NE(back->get("k\u00ff"), nullptr) << text;
  }
  // Valid UTF-8 is written unchanged.
  EXPECT_EQ(dump(Value(std::string("ok-\xc3\xa9-\xf0\x9f\x98\x80"))),
            "\"ok-\xc3\xa9-\xf0\x9f\x98\x80\"");
}

// The writer copies runs of characters that need no escape at once: escapes at a run's start,
// middle and end, control characters, DEL and UTF-8 between them come out as one at a time would.
TEST(Writers, EscapesBetweenRunsOfPlainCharacters) {
  const std::string s = std::string("\"lead plain \"quoted\" back\\slash\ttab\x01") + "ctl\x7f" +
                        "del caf\xc3\xa9 end\n";
  const std::string want = std::string(R"("\"lead plain \"quoted\" back\\slash\ttab\u0001ctl)") +
                           "\x7f" + "del caf\xc3\xa9 end\\n\"";
  EXPECT_EQ(dump(Value(s)), want);
  auto back = parse(dump(Value(s)));
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->as_string(), s);
  EXPECT_EQ(dump(Value(std::string("\\"))), R"("\\")");
  EXPECT_EQ(dump(Value(std::string("x"))), R"("x")");
}

// Plain runs are found eight bytes at a time. Every character that ends a run (and its
// neighbours in value, which do not), at every offset of a word and at both ends of strings
// around a word's length, is written and parsed back as one byte at a time would; a raw control
// character anywhere is refused by the parser.
TEST(Writers, EveryEndOfAPlainRunAtEveryOffsetOfAWord) {
  const std::vector<std::pair<std::string, std::string>> chars = {{"\"", R"(\")"},
                                                                  {"\\", R"(\\)"},
                                                                  {"\n", R"(\n)"},
                                                                  {"\x01", R"(\u0001)"},
                                                                  {"\x1f", R"(\u001f)"},
                                                                  {"\xc3\xa9", "\xc3\xa9"},
                                                                  {"\x7f", "\x7f"},
                                                                  {" ", " "},
                                                                  {"!", "!"},
                                                                  {"#", "#"},
                                                                  {"[", "["},
                                                                  {"]", "]"}};
  for (size_t len : {0, 1, 7, 8, 9, 15, 16, 17, 24, 33}) {
    for (size_t at = 0; at <= len; ++at) {
      for (const auto& [raw, escaped] : chars) {
        const std::string s = std::string(at, 'a') + raw + std::string(len - at, 'b');
        const std::string want =
            "\"" + std::string(at, 'a') + escaped + std::string(len - at, 'b') + "\"";
        EXPECT_EQ(dump(Value(s)), want) << "at " << at << " of " << len;
        auto back = parse(want);
        ASSERT_TRUE(back.ok()) << want;
        EXPECT_EQ(back->as_string(), s);
      }
      const std::string with_control =
          "\"" + std::string(at, 'a') + "\x01" + std::string(len - at, 'b') + "\"";
      EXPECT_FALSE(parse(with_control).ok()) << "at " << at << " of " << len;
      // A byte that is not UTF-8 is refused by the parser and written as the code point of its
      // value.
      EXPECT_FALSE(
          parse("\"" + std::string(at, 'a') + "\x80" + std::string(len - at, 'b') + "\"").ok())
          << "at " << at << " of " << len;
      EXPECT_EQ(dump(Value(std::string(at, 'a') + "\x80" + std::string(len - at, 'b'))),
                "\"" + std::string(at, 'a') + "\xc2\x80" + std::string(len - at, 'b') + "\"");
    }
  }
}

// The string size limit bounds the word-at-a-time scan: a string of exactly the limit is
// accepted and one byte more refused, at every alignment of the string in the document.
TEST(JsonParse, StringLimitHoldsAtEveryAlignment) {
  for (size_t limit : {7, 8, 9, 16, 17}) {
    ParseOptions o;
    o.max_string_bytes = limit;
    for (size_t pad = 0; pad < 8; ++pad) {
      const std::string at_limit =
          "[" + std::string(pad, ' ') + "\"" + std::string(limit, 'a') + "\"]";
      auto ok = parse(at_limit, o);
      ASSERT_TRUE(ok.ok()) << "limit " << limit << " pad " << pad;
      EXPECT_EQ(ok->as_array()[0].as_string(), std::string(limit, 'a'));
      const std::string over =
          "[" + std::string(pad, ' ') + "\"" + std::string(limit + 1, 'a') + "\"]";
      EXPECT_FALSE(parse(over, o).ok()) << "limit " << limit << " pad " << pad;
    }
  }
}

TEST(PythonDumps, DefaultSeparatorsAndEnsureAscii) {
  auto v = parse(R"({"b":[1,2.0,"é😀\u007f"],"a":{"z":true,"y":null}})");
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(python_dumps(*v, true, false),
            R"({"a": {"y": null, "z": true}, "b": [1, 2.0, "\u00e9\ud83d\ude00\u007f"]})");
  EXPECT_EQ(python_dumps(*v, false, true),
            R"({"b":[1,2.0,"\u00e9\ud83d\ude00\u007f"],"a":{"z":true,"y":null}})");
}

// Reads tests/data/<file>: lines "<hex bits of a double> <expected text>" ('#' comments).
std::vector<std::pair<double, std::string>> double_table(const std::string& file) {
  std::ifstream in(std::string(RCAN_TESTDATA_DIR) + "/" + file);
  EXPECT_TRUE(in.good()) << file;
  std::vector<std::pair<double, std::string>> rows;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    std::string bits_hex, expected;
    ss >> bits_hex >> expected;
    uint64_t bits = std::stoull(bits_hex, nullptr, 16);
    double d;
    std::memcpy(&d, &bits, sizeof d);
    rows.emplace_back(d, expected);
  }
  return rows;
}

TEST(PythonFloatRepr, MatchesPythonOnThreeThousandDoubles) {
  auto rows = double_table("python_float_repr.txt");
  EXPECT_GT(rows.size(), 3000u);
  for (const auto& [d, expected] : rows) ASSERT_EQ(python_float_repr(d), expected);
}

TEST(IntegralDouble, ExactDecimalExpansionLikePythonInt) {
  auto rows = double_table("integral_double.txt");
  EXPECT_GT(rows.size(), 400u);
  for (const auto& [d, expected] : rows) ASSERT_EQ(integral_double_to_string(d), expected);
}

TEST(JsonParse, KeepsIntVersusFloatAndBigIntegersExactly) {
  auto v = parse(
      R"({"i":1,"f":1.0,"big":123456789012345678901234567890,"neg":-9223372036854775808,"e":1e2})");
  ASSERT_TRUE(v.ok());
  EXPECT_TRUE(v->get("i")->is_int());
  EXPECT_TRUE(v->get("f")->is_double());
  EXPECT_EQ(v->get("big")->kind(), Value::Kind::kBigInt);
  EXPECT_EQ(v->get("big")->big_digits(), "123456789012345678901234567890");
  EXPECT_EQ(v->get("neg")->as_int(), INT64_MIN);
  EXPECT_TRUE(v->get("e")->is_double());
  EXPECT_EQ(
      dump(*v),
      R"({"i":1,"f":1.0,"big":123456789012345678901234567890,"neg":-9223372036854775808,"e":100.0})");
}

TEST(JsonParse, DecodesEscapesAndSurrogatePairs) {
  auto v = parse(R"(["\u0041\u00e9\ud83d\ude00\/\b\f\n\r\t\"\\"])");
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(v->as_array()[0].as_string(), "Aé😀/\b\f\n\r\t\"\\");
}

struct Hostile {
  const char* name;
  std::string text;
};

class JsonHostile : public ::testing::TestWithParam<Hostile> {};

TEST_P(JsonHostile, IsAnErrorNamingAnOffsetNeverACrash) {
  auto v = parse(GetParam().text);
  ASSERT_FALSE(v.ok());
  EXPECT_TRUE(v.error().code == ErrorCode::kMalformedJson ||
              v.error().code == ErrorCode::kBodyTooLarge);
  EXPECT_FALSE(v.error().message.empty());
}

std::vector<Hostile> hostile_inputs() {
  std::vector<Hostile> h{
      {"empty", ""},
      {"whitespace_only", "   \n"},
      {"truncated_object", R"({"a":1)"},
      {"truncated_string", R"({"a":"abc)"},
      {"truncated_escape", R"(["\u12)"},
      {"truncated_literal", "tru"},
      {"trailing_garbage", R"({"a":1} x)"},
      {"two_values", "1 2"},
      {"trailing_comma_object", R"({"a":1,})"},
      {"trailing_comma_array", "[1,]"},
      {"single_quotes", "{'a':1}"},
      {"unquoted_key", "{a:1}"},
      {"duplicate_key", R"({"a":1,"a":2})"},
      {"duplicate_key_many",
       R"({"k0":0,"k1":1,"k2":2,"k3":3,"k4":4,"k5":5,"k6":6,"k7":7,"k8":8,"k3":9})"},
      {"duplicate_key_escaped", R"({"a":1,"\u0061":2})"},
      {"leading_zero", "[01]"},
      {"plus_sign", "[+1]"},
      {"bare_dot", "[1.]"},
      {"dot_first", "[.5]"},
      {"exp_no_digits", "[1e]"},
      {"nan_literal", "[NaN]"},
      {"infinity_literal", "[Infinity]"},
      {"overflowing_float", "[1e400]"},
      {"huge_number_lexeme", "[" + std::string(500, '9') + "]"},
      {"lone_high_surrogate", R"(["\ud83d"])"},
      {"lone_low_surrogate", R"(["\ude00"])"},
      {"bad_low_surrogate", R"(["\ud83d\u0041"])"},
      {"invalid_escape", R"(["\x41"])"},
      {"raw_control_char", "[\"a\x01b\"]"},
      {"raw_newline_in_string", "[\"a\nb\"]"},
      {"invalid_utf8_continuation", "[\"\x80\"]"},
      {"invalid_utf8_overlong", "[\"\xc0\xaf\"]"},
      {"invalid_utf8_surrogate", "[\"\xed\xa0\x80\"]"},
      {"invalid_utf8_too_big", "[\"\xf4\x90\x80\x80\"]"},
      {"invalid_utf8_truncated", "[\"\xe2\x82\"]"},
      {"utf8_bom", "\xef\xbb\xbf{}"},
      {"nul_byte", std::string("{\"a\":1}\0", 8)},
      {"deep_arrays", std::string(100000, '[')},
      {"deep_objects",
       [] {
         std::string s;
         for (int i = 0; i < 5000; ++i) s += "{\"a\":";
         return s;
       }()},
      {"comment", "{/*x*/}"},
  };
  return h;
}

INSTANTIATE_TEST_SUITE_P(Inputs, JsonHostile, ::testing::ValuesIn(hostile_inputs()),
                         [](const auto& param_info) { return std::string(param_info.param.name); });

TEST(JsonParse, SizeLimitIsEnforced) {
  ParseOptions o;
  o.max_bytes = 10;
  auto v = parse(R"({"a":"0123456789"})", o);
  ASSERT_FALSE(v.ok());
  EXPECT_EQ(v.error().code, ErrorCode::kBodyTooLarge);
}

TEST(JsonParse, DepthLimitIsExactlyTheOption) {
  ParseOptions o;
  o.max_depth = 3;
  EXPECT_TRUE(parse("[[[1]]]", o).ok());
  EXPECT_FALSE(parse("[[[[1]]]]", o).ok());
}

TEST(JsonParse, ErrorNamesTheByteOffset) {
  auto v = parse(R"({"a":1,"a":2})");
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.error().message.find("byte 7"), std::string::npos) << v.error().message;
  EXPECT_NE(v.error().message.find("duplicate key"), std::string::npos);
}

TEST(Utf8, Validation) {
  EXPECT_TRUE(valid_utf8("Café ☕ 😀"));
  EXPECT_FALSE(valid_utf8("\xff"));
  EXPECT_FALSE(valid_utf8("\xed\xbf\xbf"));
}

TEST(ValueModel, ObjectSetReplacesAndKeepsOrder) {
  Object o{{"b", 1}, {"a", 2}};
  o.set("b", 3);
  EXPECT_EQ(dump(Value(o)), R"({"b":3,"a":2})");
  EXPECT_TRUE(o.erase("b"));
  EXPECT_FALSE(o.erase("b"));
  EXPECT_EQ(dump(Value(o)), R"({"a":2})");
  Value copy = Value(o);
  Value moved = std::move(copy);
  EXPECT_EQ(moved, Value(o));
}

TEST(JsonFieldReaders, TakeAMemberOfItsKindOrTheDefault) {
  auto v = parse(R"({"s":"x","i":7,"b":true,"f":false,"n":null})");
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(string_field(*v, "s"), "x");
  EXPECT_EQ(string_field(*v, "i", "d"), "d");
  EXPECT_EQ(int_field(*v, "i"), 7);
  EXPECT_EQ(int_field(*v, "s", -1), -1);
  EXPECT_TRUE(bool_field(*v, "b"));
  EXPECT_FALSE(bool_field(*v, "f", true));
  EXPECT_FALSE(bool_field(*v, "i"));  // 7 is not a bool
  EXPECT_TRUE(bool_field(*v, "n", true));
  EXPECT_FALSE(bool_field(*v, "missing"));
  EXPECT_FALSE(bool_field(Value("not an object"), "b"));
}

}  // namespace
}  // namespace rcan::json

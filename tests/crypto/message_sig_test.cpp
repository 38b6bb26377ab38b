// Message signatures: rcan-py ML-DSA-65 pre-images and signatures (python-json-preimage.json),
// Ed25519 over seed-shape canonical JSON, and strict `sig` block parsing.
#include "rcan/crypto/message_sig.h"

#include <gtest/gtest.h>

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/hybrid.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/hash.h"
#include "test_support.h"

namespace rcan::msgsig {
namespace {

json::Object parse_obj(const std::string& text) {
  auto v = json::parse(text);
  EXPECT_TRUE(v.ok()) << (v.ok() ? "" : v.error().message);
  if (!v.ok() || !v->is_object()) return {};
  return v->as_object();
}

struct Fixture {
  Bytes pk, sk;
};
const Fixture& key0() {
  static Fixture f = [] {
    auto kg = test::load_vector("mldsa65-keygen.json");
    const auto& c = kg.get("cases")->as_array()[0];
    return Fixture{test::hex(c.get("pk_hex")->as_string()),
                   test::hex(c.get("sk_hex")->as_string())};
  }();
  return f;
}

TrustedKeys trusted0() {
  TrustedKeys t;
  t.mldsa65.push_back(key0().pk);
  return t;
}

TEST(MessageSig, RcanPyPreimagesMatchTheVectors) {
  auto v = test::load_vector("python-json-preimage.json");
  const auto& cases = v.get("cases")->as_array();
  ASSERT_EQ(cases.size(), 10u);
  for (const auto& c : cases) {
    SCOPED_TRACE(c.get("name")->as_string());
    json::Object msg = parse_obj(c.get("wire_json")->as_string());
    EXPECT_EQ(preimage_kind(msg), Preimage::kRcanPy);
    auto pre = rcanpy_preimage(msg);
    ASSERT_TRUE(pre.ok()) << pre.error().message;
    EXPECT_EQ(*pre, c.get("preimage")->as_string());
    EXPECT_EQ(sha256_hex(*pre), c.get("preimage_sha256")->as_string());
  }
}

TEST(MessageSig, RcanPySignedMessagesVerifyAndTamperingFails) {
  auto v = test::load_vector("python-json-preimage.json");
  for (const auto& c : v.get("cases")->as_array()) {
    SCOPED_TRACE(c.get("name")->as_string());
    json::Object msg = parse_obj(c.get("signed_wire_json")->as_string());
    auto r = verify(msg, trusted0());
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->alg, Alg::kMlDsa65);
    EXPECT_EQ(r->kid, "d666806e");
    // Unsigned envelope fields may change (rcan-py does not cover them) …
    json::Object extra = msg;
    extra.set("scope", "admin");
    EXPECT_TRUE(verify(extra, trusted0()).ok());
    // … signed ones may not.
    json::Object tampered = msg;
    tampered.set("cmd", "self_destruct");
    auto bad = verify(tampered, trusted0());
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().code, ErrorCode::kSignatureInvalid);
    tampered = msg;
    json::Object params = tampered.find("params")->as_object();
    params.set("injected", 1);
    tampered.set("params", json::Value(params));
    EXPECT_FALSE(verify(tampered, trusted0()).ok());
    tampered = msg;
    tampered.set("timestamp", tampered.find("timestamp")->to_double() + 1.0);
    EXPECT_FALSE(verify(tampered, trusted0()).ok());
  }
}

TEST(MessageSig, DeterministicSigningReproducesTheVectorSignatures) {
  auto v = test::load_vector("python-json-preimage.json");
  for (const auto& c : v.get("cases")->as_array()) {
    SCOPED_TRACE(c.get("name")->as_string());
    json::Object msg = parse_obj(c.get("wire_json")->as_string());
    SignOptions o;
    o.deterministic = true;
    ASSERT_TRUE(sign_mldsa65(msg, key0().sk, key0().pk, o).ok());
    json::Object want = parse_obj(c.get("signed_wire_json")->as_string());
    EXPECT_EQ(*msg.find("sig"), *want.find("sig"));
    EXPECT_TRUE(verify(msg, trusted0()).ok());
  }
  // Hedged signatures differ but verify.
  json::Object a = parse_obj(v.get("cases")->as_array()[0].get("wire_json")->as_string());
  json::Object b = a;
  ASSERT_TRUE(sign_mldsa65(a, key0().sk, key0().pk).ok());
  ASSERT_TRUE(sign_mldsa65(b, key0().sk, key0().pk).ok());
  EXPECT_NE(*a.find("sig"), *b.find("sig"));
  EXPECT_TRUE(verify(a, trusted0()).ok());
  EXPECT_TRUE(verify(b, trusted0()).ok());
}

TEST(MessageSig, UnknownKidAndWrongKeyAreRejected) {
  auto v = test::load_vector("python-json-preimage.json");
  json::Object msg = parse_obj(v.get("cases")->as_array()[0].get("signed_wire_json")->as_string());
  auto r = verify(msg, TrustedKeys{});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "sig.kid");
  auto kg = test::load_vector("mldsa65-keygen.json");
  TrustedKeys other;
  other.mldsa65.push_back(test::hex(kg.get("cases")->as_array()[1].get("pk_hex")->as_string()));
  EXPECT_FALSE(verify(msg, other).ok());
  json::Object unsigned_msg = msg;
  unsigned_msg.erase("sig");
  auto u = verify(unsigned_msg, trusted0());
  ASSERT_FALSE(u.ok());
  EXPECT_EQ(u.error().code, ErrorCode::kAuthRequired);
}

TEST(MessageSig, MalformedSigBlocksAreRejectedWithAField) {
  std::string good_value = base64url_encode(Bytes(3309, 1), true);
  std::vector<std::pair<std::string, std::string>> bad = {
      {"\"x\"", "sig"},
      {"[]", "sig"},
      {"{}", "sig.alg"},
      {R"({"alg":"rsa","kid":"d666806e","value":"AA"})", "sig.alg"},
      {R"({"alg":"ML-DSA-65","kid":"d666806e","value":"AA"})", "sig.alg"},
      {R"({"alg":"ml-dsa-65","value":"AA"})", "sig.kid"},
      {R"({"alg":"ml-dsa-65","kid":"D666806E","value":"AA"})", "sig.kid"},
      {R"({"alg":"ml-dsa-65","kid":"d666806","value":"AA"})", "sig.kid"},
      {R"({"alg":"ml-dsa-65","kid":7,"value":"AA"})", "sig.kid"},
      {R"({"alg":"ml-dsa-65","kid":"d666806e"})", "sig.value"},
      {R"({"alg":"ml-dsa-65","kid":"d666806e","value":"pending"})", "sig.value"},
      {R"({"alg":"ml-dsa-65","kid":"d666806e","value":"@@@@"})", "sig.value"},
      {R"({"alg":"ml-dsa-65","kid":"d666806e","value":"AAAA"})", "sig.value"},
      {R"({"alg":"ed25519","kid":"d666806e","value":")" + good_value + "\"}", "sig.value"},
      {R"({"alg":"ml-dsa-65","kid":"d666806e","value":")" + std::string(9000, 'A') + "\"}",
       "sig.value"},
  };
  for (const auto& [text, field] : bad) {
    SCOPED_TRACE(text.substr(0, 80));
    auto v = json::parse(text);
    ASSERT_TRUE(v.ok());
    auto r = parse_sig_block(*v);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kSignatureInvalid);
    EXPECT_EQ(r.error().field, field);
  }
  auto ok = json::parse(R"({"alg":"ml-dsa-65","kid":"d666806e","value":")" + good_value + "\"}");
  EXPECT_TRUE(parse_sig_block(*ok).ok());
  // base64url without padding is accepted too.
  std::string nopad = base64url_encode(Bytes(64, 2), false);
  auto ed = json::parse(R"({"alg":"ed25519","kid":"5cc558a6","value":")" + nopad + "\"}");
  EXPECT_TRUE(parse_sig_block(*ed).ok());
}

TEST(MessageSig, RcanPyShapeRequiresItsFields) {
  const std::string base =
      R"({"rcan":"3.2","msg_id":"m","timestamp":1.5,"cmd":"go","target":"rcan://r.example/acme/arm/v1/unit-1","params":{}})";
  json::Object ok = parse_obj(base);
  EXPECT_TRUE(rcanpy_preimage(ok).ok());
  struct Case {
    const char* key;
    json::Value v;
    ErrorCode code;
  };
  std::vector<Case> cases = {
      {"rcan", json::Value(3.2), ErrorCode::kSchemaValidationFailed},
      {"msg_id", json::Value(5), ErrorCode::kSchemaValidationFailed},
      {"timestamp", json::Value("1.5"), ErrorCode::kSchemaValidationFailed},
      {"cmd", json::Value(""), ErrorCode::kSchemaValidationFailed},
      {"params", json::Value(json::Array{}), ErrorCode::kSchemaValidationFailed},
      {"target", json::Value("rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6"),
       ErrorCode::kInvalidRuri},
      {"target", json::Value("http://r/a/b/c/d"), ErrorCode::kInvalidRuri},
      {"target", json::Value("rcan://r/a b/c/d/e"), ErrorCode::kInvalidRuri},
      {"target", json::Value("rcan://r//c/d/e"), ErrorCode::kInvalidRuri},
      {"target", json::Value(1), ErrorCode::kSchemaValidationFailed},
  };
  for (const auto& c : cases) {
    json::Object m = ok;
    m.set(c.key, c.v);
    auto r = rcanpy_preimage(m);
    ASSERT_FALSE(r.ok()) << c.key << " " << json::dump(c.v);
    EXPECT_EQ(r.error().code, c.code) << c.key;
  }
  json::Object no_params = ok;
  no_params.erase("params");
  auto np = rcanpy_preimage(no_params);
  ASSERT_TRUE(np.ok());
  EXPECT_NE(np->find("\"params\":{}"), std::string::npos);
  // rcan/rcan_version sync: only when rcan is the SDK's own 3.2.
  json::Object m = ok;
  m.set("rcan", "3.1");
  m.set("rcan_version", "3.0");
  EXPECT_NE(rcanpy_preimage(m)->find("\"rcan\":\"3.1\""), std::string::npos);
  // Python whitespace (incl. U+00A0) around the target is stripped like str.strip().
  m = ok;
  m.set("target", "\xc2\xa0\t rcan://r.example/acme/arm/v1/unit-1/ \n");
  EXPECT_NE(rcanpy_preimage(m)->find("\"target\":\"rcan://r.example/acme/arm/v1/unit-1\""),
            std::string::npos);
}

TEST(MessageSig, Ed25519OverSeedShapeCanonicalJson) {
  Bytes seed(32, 7);
  json::Object msg = parse_obj(
      R"({"version":"1.0.0","message_id":"3f2c1b1e-0000-4000-8000-000000000001","source_ruri":"rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6",
          "target_ruri":"rcan://continuon.cloud/continuon/companion-v1/0a0b0c0d","type":"COMMAND","sender_type":"robot",
          "payload":{"action":"move","linear":0.3,"angular":0.0},"timestamp_ms":1767225600000})");
  EXPECT_EQ(preimage_kind(msg), Preimage::kCanonical);
  ASSERT_TRUE(sign_ed25519(msg, seed).ok());
  const json::Value* sig = msg.find("sig");
  ASSERT_NE(sig, nullptr);
  EXPECT_EQ(sig->get("alg")->as_string(), "ed25519");
  EXPECT_EQ(sig->get("kid")->as_string(), "5cc558a6");
  // The signature covers canonical JSON of the message without sig (angular 0.0 → 0).
  std::string pre = json::canonical_without(msg, "sig");
  EXPECT_NE(pre.find("\"angular\":0,"), std::string::npos);
  auto raw = base64url_decode(sig->get("value")->as_string());
  ASSERT_TRUE(raw);
  auto pk = ed25519::public_key_from_seed(seed);
  ASSERT_TRUE(pk.ok());
  EXPECT_TRUE(ed25519::verify(*pk, Bytes(pre.begin(), pre.end()), *raw));
  TrustedKeys t;
  t.ed25519.push_back(*pk);
  EXPECT_TRUE(verify(msg, t).ok());
  // Key order on the wire does not matter; content does.
  json::Object reordered;
  for (auto it = msg.members().rbegin(); it != msg.members().rend(); ++it)
    reordered.set(it->first, it->second);
  EXPECT_TRUE(verify(reordered, t).ok());
  json::Object tampered = msg;
  tampered.set("sender_type", "human");
  EXPECT_FALSE(verify(tampered, t).ok());
  // An ML-DSA key with the same kid space is not consulted for ed25519.
  EXPECT_FALSE(verify(msg, trusted0()).ok());
}

TEST(MessageSig, Ed25519OverRcanPyShapeUsesThePythonPreimage) {
  auto v = test::load_vector("python-json-preimage.json");
  const auto& c = v.get("cases")->as_array()[0];
  json::Object msg = parse_obj(c.get("wire_json")->as_string());
  Bytes seed(32, 7);
  ASSERT_TRUE(sign_ed25519(msg, seed).ok());
  auto raw = base64url_decode(msg.find("sig")->get("value")->as_string());
  auto pk = ed25519::public_key_from_seed(seed);
  std::string pre = c.get("preimage")->as_string();
  EXPECT_TRUE(ed25519::verify(*pk, Bytes(pre.begin(), pre.end()), *raw));
  TrustedKeys t;
  t.ed25519.push_back(*pk);
  EXPECT_TRUE(verify(msg, t).ok());
}

TEST(MessageSig, JsStringifyMatchesJavaScript) {
  auto js = [](const std::string& text) {
    auto v = json::parse(text);
    EXPECT_TRUE(v.ok()) << text;
    return v.ok() ? js_stringify(*v) : std::string();
  };
  // Numbers as JavaScript's Number#toString writes them (node: JSON.stringify).
  EXPECT_EQ(js("[0.00001,1e-7,1e21,1e20,123.456,-0.0,50.0,1.5e300,0.1,100,-2.5e-7,1."
               "2345678901234568e23]"),
            "[0.00001,1e-7,1e+21,100000000000000000000,123.456,0,50,1.5e+300,0.1,100,-2.5e-7,"
            "1.2345678901234569e+23]");  // node prints …69e+23 for this input
  // Members in wire order, raw UTF-8, JavaScript's escapes.
  EXPECT_EQ(js(R"({"b":1,"a":"caf\u00e9 \"q\" \\ \n\u0001\u007f"})"),
            "{\"b\":1,\"a\":\"caf\xc3\xa9 \\\"q\\\" \\\\ \\n\\u0001\x7f\"}");
}

TEST(MessageSig, RcanTsPreimageAndSignature) {
  json::Object msg = parse_obj(
      R"({"rcan":"3.2","rcanVersion":"3.2","cmd":"move","target":"rcan://local.rcan/acme/rover/v1/0a1b2c3d",)"
      R"("timestamp":"2025-02-28T05:44:42.934Z","params":{"linear":0.1,"duration_ms":100}})");
  auto pre = rcants_preimage(msg);
  ASSERT_TRUE(pre.ok()) << pre.error().message;
  // rcan-ts 3.4.2 canonicalMessageBytes: sorted top level, empty msg_id, params as sent.
  EXPECT_EQ(
      *pre,
      R"({"cmd":"move","msg_id":"","params":{"linear":0.1,"duration_ms":100},"rcan":"3.2",)"
      R"("target":"rcan://local.rcan/acme/rover/v1/0a1b2c3d","timestamp":"2025-02-28T05:44:42.934Z"})");
  auto s = mldsa65::sign(
      key0().sk,
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(pre->data()), pre->size()));
  ASSERT_TRUE(s.ok());
  msg.set("signature", json::Object{{"alg", "ml-dsa-65"},
                                    {"kid", mldsa65::kid(key0().pk)},
                                    {"sig", base64url_encode(s->data(), s->size(), false)}});
  auto ok = verify(msg, trusted0());
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_EQ(ok->alg, Alg::kMlDsa65);
  EXPECT_EQ(alg_name(ok->alg), "ml-dsa-65");
  ASSERT_NE(signature_member(msg), nullptr);
  json::Object tampered = msg;
  tampered.set("timestamp", "2025-02-28T05:44:43.934Z");
  EXPECT_EQ(verify(tampered, trusted0()).error().code, ErrorCode::kSignatureInvalid);
  EXPECT_EQ(verify(msg, TrustedKeys{}).error().code, ErrorCode::kSignatureInvalid);
  json::Object bad_alg = msg;
  bad_alg.find("signature")->as_object().set("alg", "ed25519");
  EXPECT_EQ(verify(bad_alg, trusted0()).error().code, ErrorCode::kSignatureInvalid);
  json::Object unsigned_msg = parse_obj(R"({"cmd":"move"})");
  EXPECT_EQ(signature_member(unsigned_msg), nullptr);
  EXPECT_EQ(verify(unsigned_msg, trusted0()).error().code, ErrorCode::kAuthRequired);
}

// Messages signed by rcan-ts 3.4.2 itself (tests/vectors/rcants-signed-messages.json): its
// signMessage pre-image (raw UTF-8, JavaScript number formatting such as 1e-7) is rebuilt
// byte for byte, and its signBody on a message verifies with both keys trusted.
TEST(MessageSig, MessagesSignedByRcanTsVerify) {
  auto v = test::load_vector("rcants-signed-messages.json");
  auto ed_pub = ed25519::public_key_from_seed(Bytes(32, 7));
  ASSERT_TRUE(ed_pub.ok());
  TrustedKeys both = trusted0();
  both.ed25519.push_back(*ed_pub);
  json::Object ts = parse_obj(v.get("rcants_signed_message")->as_string());
  auto ok = verify(ts, both);
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_EQ(ok->kid, "d666806e");
  json::Object ts_bad = ts;
  ts_bad.find("params")->as_object().set("tiny", 1e-6);
  EXPECT_EQ(verify(ts_bad, both).error().code, ErrorCode::kSignatureInvalid);
  json::Object body = parse_obj(v.get("signbody_message")->as_string());
  auto hy = verify(body, both);
  ASSERT_TRUE(hy.ok()) << hy.error().message;
  EXPECT_EQ(hy->alg, Alg::kHybrid);
  json::Object body_bad = body;
  body_bad.set("msg_id", "fuzz-2");
  EXPECT_EQ(verify(body_bad, both).error().code, ErrorCode::kSignatureInvalid);
}

TEST(MessageSig, HybridSignedMessageNeedsBothKeysTrusted) {
  Bytes ed_seed(32, 7);
  auto ed_pub = ed25519::public_key_from_seed(ed_seed);
  ASSERT_TRUE(ed_pub.ok());
  json::Object body =
      parse_obj(R"({"rcan":"3.2","msg_id":"m-1","timestamp":1740721482.934,"cmd":"move",)"
                R"("target":"rcan://local.rcan/acme/rover/v1/0a1b2c3d","params":{"linear":0.1}})");
  auto signed_body = hybrid::sign_body(body, key0().sk, key0().pk, ed_seed);
  ASSERT_TRUE(signed_body.ok());
  TrustedKeys both = trusted0();
  both.ed25519.push_back(*ed_pub);
  auto ok = verify(*signed_body, both);
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_EQ(ok->alg, Alg::kHybrid);
  EXPECT_EQ(ok->kid, mldsa65::kid(key0().pk));
  // The Ed25519 key must be trusted too, and the ML-DSA-65 key named by pq_kid.
  EXPECT_EQ(verify(*signed_body, trusted0()).error().code, ErrorCode::kSignatureInvalid);
  TrustedKeys ed_only;
  ed_only.ed25519.push_back(*ed_pub);
  EXPECT_EQ(verify(*signed_body, ed_only).error().code, ErrorCode::kSignatureInvalid);
  json::Object tampered = *signed_body;
  tampered.set("cmd", "rotate");
  EXPECT_EQ(verify(tampered, both).error().code, ErrorCode::kSignatureInvalid);
}

}  // namespace
}  // namespace rcan::msgsig

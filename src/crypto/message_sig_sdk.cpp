// The SDKs' other signature forms on messages (see include/rcan/crypto/message_sig.h): the
// hybrid signed body (rcan-py hybrid.sign_body, rcan-ts signBody) and rcan-ts's `signature`
// block with its signMessage pre-image.
#include <algorithm>
#include <charconv>
#include <cmath>

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/hybrid.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/crypto/mldsa65.h"

namespace rcan::msgsig {
namespace {

Error sig_error(std::string msg, std::string field = "sig") {
  return Error(ErrorCode::kSignatureInvalid, "message signature: " + std::move(msg),
               std::move(field));
}
Error schema(std::string msg, std::string field) {
  return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), std::move(field));
}

std::span<const uint8_t> as_bytes(std::string_view s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

bool is_hybrid_block(const json::Value& sig) { return sig.is_object() && sig.get("ml_dsa"); }

// JavaScript Number.prototype.toString for a finite double (ECMA-262 Number::toString).
std::string js_number(double d) {
  if (d == 0 || !std::isfinite(d)) return "0";
  char buf[64];
  auto r = std::to_chars(buf, buf + sizeof buf, std::fabs(d), std::chars_format::scientific);
  std::string sci(buf, r.ptr);  // d[.ddd]e±XX, shortest round-trip
  size_t e = sci.find('e');
  std::string digits = sci.substr(0, 1) + (e > 2 ? sci.substr(2, e - 2) : "");
  int k = static_cast<int>(digits.size());
  int n = std::stoi(sci.substr(e + 1)) + 1;  // value = 0.digits × 10^n
  std::string out = d < 0 ? "-" : "";
  if (k <= n && n <= 21) {
    out += digits + std::string(static_cast<size_t>(n - k), '0');
  } else if (0 < n && n <= 21) {
    out += digits.substr(0, static_cast<size_t>(n)) + "." + digits.substr(static_cast<size_t>(n));
  } else if (-6 < n && n <= 0) {
    out += "0." + std::string(static_cast<size_t>(-n), '0') + digits;
  } else {
    out += digits.substr(0, 1);
    if (k > 1) out += "." + digits.substr(1);
    out += (n - 1 >= 0 ? "e+" : "e-") + std::to_string(std::abs(n - 1));
  }
  return out;
}

void js_append(std::string& out, const json::Value& v) {
  if (v.is_null()) {
    out += "null";
  } else if (v.is_bool()) {
    out += v.as_bool() ? "true" : "false";
  } else if (v.is_number()) {
    out += js_number(v.to_double());
  } else if (v.is_string()) {
    json::append_string(out, v.as_string());  // as JSON.stringify: parsed strings are valid UTF-8
  } else if (v.is_array()) {
    out += '[';
    bool first = true;
    for (const auto& x : v.as_array()) {
      if (!first) out += ',';
      first = false;
      js_append(out, x);
    }
    out += ']';
  } else {
    out += '{';
    bool first = true;
    for (const auto& [k, x] : v.as_object()) {
      if (!first) out += ',';
      first = false;
      json::append_string(out, k);
      out += ':';
      js_append(out, x);
    }
    out += '}';
  }
}

// A hybrid signed body: the ML-DSA-65 key named by pq_kid and the embedded Ed25519 key must
// both be trusted, and both signatures must verify over the canonical body without `sig`.
Result<SigBlock> verify_hybrid(const json::Object& msg, const TrustedKeys& trusted) {
  const json::Value* kid = msg.find("pq_kid");
  if (!kid || !kid->is_string() || kid->as_string().size() != 8)
    return sig_error("a hybrid signature needs pq_kid (8 hex)", "pq_kid");
  const json::Value* edpub_v = msg.find("sig")->get("ed25519_pub");
  std::optional<Bytes> edpub;
  if (edpub_v && edpub_v->is_string()) edpub = base64_decode(edpub_v->as_string());
  if (!edpub) return sig_error("sig.ed25519_pub is missing or not base64", "sig.ed25519_pub");
  if (std::find(trusted.ed25519.begin(), trusted.ed25519.end(), *edpub) == trusted.ed25519.end())
    return sig_error("sig.ed25519_pub is not a trusted Ed25519 key", "sig.ed25519_pub");
  bool known = false;
  Error last = sig_error("signature does not verify", "sig");
  for (const auto& pk : trusted.mldsa65) {
    if (pk.size() != mldsa65::kPublicKeyBytes || mldsa65::kid(pk) != kid->as_string()) continue;
    known = true;
    hybrid::VerifyOptions vo;
    vo.strict = true;
    vo.expected_ed25519_pub = *edpub;
    Status st = hybrid::verify_body(msg, pk, vo);
    if (st.ok()) return SigBlock{Alg::kHybrid, kid->as_string(), {}};
    last = sig_error(st.error().message, st.error().field);
  }
  if (!known) return sig_error("no trusted key with kid " + kid->as_string(), "pq_kid");
  return last;
}

// rcan-ts `signature` {alg: "ml-dsa-65", kid, sig (base64url)} over rcants_preimage().
Result<SigBlock> verify_rcants(const json::Object& msg, const TrustedKeys& trusted) {
  auto pre = rcants_preimage(msg);  // first: a malformed message is a schema error
  if (!pre.ok()) return pre.error();
  const json::Value* s = msg.find("signature");
  if (!s->is_object()) return sig_error("signature must be an object {alg, kid, sig}", "signature");
  std::string alg = json::string_field(*s, "alg");
  std::string kid = json::string_field(*s, "kid");
  std::string value = json::string_field(*s, "sig");
  if (alg != kAlgMlDsa65) return sig_error("signature.alg must be ml-dsa-65", "signature.alg");
  if (kid.size() != 8) return sig_error("signature.kid must be 8 hex digits", "signature.kid");
  if (value.empty() || value.size() > kMaxSigValueChars || value == "pending")
    return sig_error("signature.sig is not a signature", "signature.sig");
  auto raw = base64url_decode(value);
  if (!raw || raw->size() != mldsa65::kSignatureBytes)
    return sig_error("signature.sig is not a 3309-byte base64url signature", "signature.sig");
  bool known = false;
  for (const auto& pk : trusted.mldsa65) {
    if (pk.size() != mldsa65::kPublicKeyBytes || mldsa65::kid(pk) != kid) continue;
    known = true;
    if (mldsa65::verify(pk, as_bytes(*pre), *raw)) return SigBlock{Alg::kMlDsa65, kid, *raw};
  }
  if (!known) return sig_error("no trusted key with kid " + kid, "signature.kid");
  return sig_error("signature does not verify", "signature.sig");
}

}  // namespace

std::string_view alg_name(Alg alg) {
  switch (alg) {
    case Alg::kMlDsa65:
      return kAlgMlDsa65;
    case Alg::kEd25519:
      return kAlgEd25519;
    case Alg::kHybrid:
      return kAlgHybrid;
  }
  return kAlgMlDsa65;
}

const json::Value* signature_member(const json::Object& msg) {
  if (const json::Value* s = msg.find("sig"); s && !s->is_null()) return s;
  if (const json::Value* s = msg.find("signature"); s && !s->is_null()) return s;
  return nullptr;
}

std::string js_stringify(const json::Value& v) {
  std::string out;
  js_append(out, v);
  return out;
}

Result<std::string> rcants_preimage(const json::Object& msg) {
  json::Object pre;  // sorted top-level keys, as rcan-ts sorts Object.entries
  for (const char* key : {"cmd", "rcan", "target", "timestamp"}) {
    const json::Value* v = msg.find(key);
    if (!v || !v->is_string())
      return schema(std::string("rcan-ts message: ") + key + " must be a string", key);
  }
  const json::Value* params = msg.find("params");
  if (params && !params->is_null() && !params->is_object())
    return schema("rcan-ts message: params must be an object", "params");
  pre.set("cmd", *msg.find("cmd"));
  pre.set("msg_id", std::string());
  pre.set("params", params && !params->is_null() ? *params : json::Value(json::Object{}));
  pre.set("rcan", *msg.find("rcan"));
  pre.set("target", *msg.find("target"));
  pre.set("timestamp", *msg.find("timestamp"));
  return js_stringify(json::Value(std::move(pre)));
}

Result<SigBlock> verify(const json::Object& msg, const TrustedKeys& trusted) {
  const json::Value* sig = msg.find("sig");
  if (sig && !sig->is_null()) {
    if (is_hybrid_block(*sig)) return verify_hybrid(msg, trusted);
    return verify_block(msg, trusted);
  }
  if (const json::Value* s = msg.find("signature"); s && !s->is_null())
    return verify_rcants(msg, trusted);
  return Error(ErrorCode::kAuthRequired, "message is unsigned (no sig)", "sig");
}

}  // namespace rcan::msgsig

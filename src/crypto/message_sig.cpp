// Message `sig` blocks (see include/rcan/crypto/message_sig.h).
#include "rcan/crypto/message_sig.h"

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/hash.h"

namespace rcan::msgsig {
namespace {

constexpr std::string_view kRcanPySpecVersion = "3.2";

Error sig_error(std::string msg, std::string field = "sig") {
  return Error(ErrorCode::kSignatureInvalid, "message signature: " + std::move(msg),
               std::move(field));
}
Error schema(std::string msg, std::string field) {
  return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), std::move(field));
}

bool lower_hex8(std::string_view s) {
  if (s.size() != 8) return false;
  for (char c : s)
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  return true;
}

// Python str.strip() whitespace, for the characters that can occur in UTF-8 text.
size_t leading_space(std::string_view s) {
  static const std::string_view kUnicodeSpaces[] = {
      "\xc2\x85",     "\xc2\xa0",     "\xe1\x9a\x80", "\xe2\x80\x80", "\xe2\x80\x81",
      "\xe2\x80\x82", "\xe2\x80\x83", "\xe2\x80\x84", "\xe2\x80\x85", "\xe2\x80\x86",
      "\xe2\x80\x87", "\xe2\x80\x88", "\xe2\x80\x89", "\xe2\x80\x8a", "\xe2\x80\xa8",
      "\xe2\x80\xa9", "\xe2\x80\xaf", "\xe2\x81\x9f", "\xe3\x80\x80"};
  unsigned char c = s.empty() ? 0 : static_cast<unsigned char>(s[0]);
  if (c == ' ' || (c >= 0x09 && c <= 0x0d) || (c >= 0x1c && c <= 0x1f)) return 1;
  for (auto u : kUnicodeSpaces)
    if (s.substr(0, u.size()) == u) return u.size();
  return 0;
}
size_t trailing_space(std::string_view s) {
  static const std::string_view kUnicodeSpaces[] = {
      "\xc2\x85",     "\xc2\xa0",     "\xe1\x9a\x80", "\xe2\x80\x80", "\xe2\x80\x81",
      "\xe2\x80\x82", "\xe2\x80\x83", "\xe2\x80\x84", "\xe2\x80\x85", "\xe2\x80\x86",
      "\xe2\x80\x87", "\xe2\x80\x88", "\xe2\x80\x89", "\xe2\x80\x8a", "\xe2\x80\xa8",
      "\xe2\x80\xa9", "\xe2\x80\xaf", "\xe2\x81\x9f", "\xe3\x80\x80"};
  unsigned char c = s.empty() ? 0 : static_cast<unsigned char>(s.back());
  if (c == ' ' || (c >= 0x09 && c <= 0x0d) || (c >= 0x1c && c <= 0x1f)) return 1;
  for (auto u : kUnicodeSpaces)
    if (s.size() >= u.size() && s.substr(s.size() - u.size()) == u) return u.size();
  return 0;
}

bool rcanpy_segment(std::string_view s) {
  if (s.empty()) return false;
  for (char c : s) {
    bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
              c == '.' || c == '_' || c == '-';
    if (!ok) return false;
  }
  return true;
}

// rcan-py RobotURI.parse + str(): strip, 5 segments, one optional trailing '/'.
Result<std::string> rcanpy_target(std::string_view t) {
  while (size_t n = leading_space(t)) t.remove_prefix(n);
  while (size_t n = trailing_space(t)) t.remove_suffix(n);
  constexpr std::string_view kScheme = "rcan://";
  auto bad = [&](std::string why) {
    return Error(ErrorCode::kInvalidRuri,
                 "target is not an rcan-py RobotURI "
                 "(rcan://registry/manufacturer/model/version/device-id): " +
                     std::move(why),
                 "target");
  };
  if (t.substr(0, kScheme.size()) != kScheme) return bad("scheme must be rcan://");
  std::string_view rest = t.substr(kScheme.size());
  if (!rest.empty() && rest.back() == '/') rest.remove_suffix(1);
  std::string out(kScheme);
  size_t count = 0, start = 0;
  for (;;) {
    size_t slash = rest.find('/', start);
    std::string_view seg = rest.substr(
        start, slash == std::string_view::npos ? std::string_view::npos : slash - start);
    if (!rcanpy_segment(seg))
      return bad("segment " + std::to_string(count + 1) +
                 " is empty or has a character outside [A-Za-z0-9._-]");
    if (count) out += '/';
    out += seg;
    ++count;
    if (slash == std::string_view::npos) break;
    start = slash + 1;
  }
  if (count != 5) return bad("expected 5 segments, found " + std::to_string(count));
  return out;
}

std::span<const uint8_t> as_bytes(std::string_view s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

}  // namespace

Result<SigBlock> parse_sig_block(const json::Value& sig) {
  if (!sig.is_object()) return sig_error("sig must be an object {alg, kid, value}");
  const json::Value* alg = sig.get("alg");
  const json::Value* kid = sig.get("kid");
  const json::Value* value = sig.get("value");
  if (!alg || !alg->is_string()) return sig_error("sig.alg is missing", "sig.alg");
  SigBlock b;
  size_t expected = 0;
  if (alg->as_string() == kAlgMlDsa65) {
    b.alg = Alg::kMlDsa65;
    expected = mldsa65::kSignatureBytes;
  } else if (alg->as_string() == kAlgEd25519) {
    b.alg = Alg::kEd25519;
    expected = ed25519::kSignatureBytes;
  } else {
    return sig_error("unsupported sig.alg (ml-dsa-65 or ed25519)", "sig.alg");
  }
  if (!kid || !kid->is_string() || !lower_hex8(kid->as_string()))
    return sig_error("sig.kid must be 8 lower-case hex characters", "sig.kid");
  b.kid = kid->as_string();
  if (!value || !value->is_string()) return sig_error("sig.value is missing", "sig.value");
  const std::string& v = value->as_string();
  if (v == "pending") return sig_error("sig.value \"pending\" is not a signature", "sig.value");
  if (v.size() > kMaxSigValueChars) return sig_error("sig.value is too long", "sig.value");
  auto raw = base64url_decode(v);
  if (!raw) return sig_error("sig.value is not base64url", "sig.value");
  if (raw->size() != expected)
    return sig_error("sig.value decodes to " + std::to_string(raw->size()) + " bytes, expected " +
                         std::to_string(expected),
                     "sig.value");
  b.value = std::move(*raw);
  return b;
}

json::Value make_sig_block(Alg alg, std::string_view kid, std::span<const uint8_t> signature) {
  json::Object o;
  o.set("alg", std::string(alg == Alg::kMlDsa65 ? kAlgMlDsa65 : kAlgEd25519));
  o.set("kid", std::string(kid));
  o.set("value", base64url_encode(signature.data(), signature.size(), true));
  return json::Value(std::move(o));
}

Preimage preimage_kind(const json::Object& msg) {
  return msg.contains("cmd") ? Preimage::kRcanPy : Preimage::kCanonical;
}

Result<std::string> rcanpy_preimage(const json::Object& msg) {
  const json::Value* rcan = msg.find("rcan");
  if (!rcan || !rcan->is_string()) return schema("rcan-py message: rcan must be a string", "rcan");
  const json::Value* rcan_version = msg.find("rcan_version");
  if (rcan_version && !rcan_version->is_string())
    return schema("rcan-py message: rcan_version must be a string", "rcan_version");
  const json::Value* msg_id = msg.find("msg_id");
  if (!msg_id || !msg_id->is_string() || msg_id->as_string().empty())
    return schema("rcan-py message: msg_id must be a non-empty string", "msg_id");
  const json::Value* ts = msg.find("timestamp");
  if (!ts || !ts->is_number())
    return schema("rcan-py message: timestamp must be a number", "timestamp");
  const json::Value* cmd = msg.find("cmd");
  if (!cmd || !cmd->is_string() || cmd->as_string().empty())
    return schema("rcan-py message: cmd must be a non-empty string", "cmd");
  const json::Value* target = msg.find("target");
  if (!target || !target->is_string())
    return schema("rcan-py message: target must be a string", "target");
  const json::Value* params = msg.find("params");
  if (params && !params->is_object())
    return schema("rcan-py message: params must be an object", "params");

  auto tgt = rcanpy_target(target->as_string());
  if (!tgt.ok()) return tgt.error();

  // rcan-py RCANMessage.__post_init__: rcan/rcan_version sync.
  std::string rcan_s = rcan->as_string();
  std::string rv = rcan_version ? rcan_version->as_string() : rcan_s;
  if (rcan_s == kRcanPySpecVersion && rv != kRcanPySpecVersion) rcan_s = rv;

  json::Object pre;
  pre.set("rcan", rcan_s);
  pre.set("msg_id", *msg_id);
  pre.set("timestamp", *ts);
  pre.set("cmd", *cmd);
  pre.set("target", *tgt);
  pre.set("params", params ? *params : json::Value(json::Object{}));
  return json::python_dumps(json::Value(std::move(pre)), true, true);
}

Result<std::string> preimage(const json::Object& msg) {
  if (preimage_kind(msg) == Preimage::kRcanPy) return rcanpy_preimage(msg);
  return json::canonical_without(msg, "sig");
}

Result<SigBlock> verify_block(const json::Object& msg, const TrustedKeys& trusted) {
  const json::Value* sig = msg.find("sig");
  if (!sig) return Error(ErrorCode::kAuthRequired, "message is unsigned (no sig)", "sig");
  auto block = parse_sig_block(*sig);
  if (!block.ok()) return block.error();
  auto pre = preimage(msg);
  if (!pre.ok()) return pre.error();
  bool known = false;
  if (block->alg == Alg::kMlDsa65) {
    for (const auto& pk : trusted.mldsa65) {
      if (pk.size() != mldsa65::kPublicKeyBytes || mldsa65::kid(pk) != block->kid) continue;
      known = true;
      if (mldsa65::verify(pk, as_bytes(*pre), block->value)) return block;
    }
  } else {
    for (const auto& pk : trusted.ed25519) {
      auto kid = keys::ed25519_kid(pk);
      if (!kid.ok() || *kid != block->kid) continue;
      known = true;
      if (ed25519::verify(pk, as_bytes(*pre), block->value)) return block;
    }
  }
  if (!known) return sig_error("no trusted key with kid " + block->kid, "sig.kid");
  return sig_error("signature does not verify", "sig.value");
}

Status sign_mldsa65(json::Object& msg, std::span<const uint8_t> sk, std::span<const uint8_t> pk,
                    const SignOptions& opts) {
  if (pk.size() != mldsa65::kPublicKeyBytes)
    return Error(ErrorCode::kInternal, "ML-DSA-65 public key must be 1952 bytes");
  auto pre = preimage(msg);
  if (!pre.ok()) return pre.error();
  mldsa65::SignOptions so;
  so.deterministic = opts.deterministic;
  auto s = mldsa65::sign(sk, as_bytes(*pre), so);
  if (!s.ok()) return s.error();
  msg.set("sig", make_sig_block(Alg::kMlDsa65, mldsa65::kid(pk), *s));
  return Status::Ok();
}

Status sign_ed25519(json::Object& msg, std::span<const uint8_t> seed) {
  auto pk = ed25519::public_key_from_seed(seed);
  if (!pk.ok()) return pk.error();
  auto kid = keys::ed25519_kid(*pk);
  if (!kid.ok()) return kid.error();
  auto pre = preimage(msg);
  if (!pre.ok()) return pre.error();
  auto s = ed25519::sign(seed, as_bytes(*pre));
  if (!s.ok()) return s.error();
  msg.set("sig", make_sig_block(Alg::kEd25519, *kid, *s));
  return Status::Ok();
}

}  // namespace rcan::msgsig

// rcan sign / rcan verify — raw ML-DSA-65 and Ed25519 signatures over stdin.
#include <cstdio>
#include <iostream>

#include "cli.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/hash.h"

namespace rcan::cli {
namespace {

constexpr const char* kSignHelp =
    "usage: rcan sign --key-dir D --alg ml-dsa-65|ed25519 [--deterministic] [--context HEX]\n"
    "  Signs standard input with the key directory's key and prints the signature in standard\n"
    "  base64. --deterministic (ML-DSA-65 only) uses rnd = 0^32; --context (ML-DSA-65 only) is\n"
    "  the FIPS 204 context string, at most 255 bytes. Exit 0 ok, 1 key error, 2 usage.\n";
constexpr const char* kVerifyHelp =
    "usage: rcan verify --pub FILE --alg ml-dsa-65|ed25519 --sig B64 [--context HEX]\n"
    "  Verifies a signature over standard input. FILE is a raw public key (1952 bytes for\n"
    "  ML-DSA-65, 32 bytes for Ed25519; an Ed25519 SPKI PEM is also accepted). B64 is standard\n"
    "  base64 (base64url accepted). Exit 0 valid, 1 invalid, 2 usage or malformed input.\n";

std::span<const uint8_t> bytes_of(const std::string& s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

int sign_main(const Args& args) {
  if (!args.empty() && (args[0] == "--help" || args[0] == "-h")) {
    std::fputs(kSignHelp, stdout);
    return 0;
  }
  Options o(args, {"deterministic"}, {"key-dir", "alg", "context"});
  if (!o.ok()) return usage_error("sign", o.error());
  if (!o.positional().empty())
    return usage_error("sign", "unexpected argument " + o.positional()[0]);
  if (o.get("key-dir").empty()) return usage_error("sign", "--key-dir D is required");
  std::string alg = o.get("alg");
  if (alg != "ml-dsa-65" && alg != "ed25519")
    return usage_error("sign", "--alg must be ml-dsa-65 or ed25519");
  Bytes ctx;
  if (o.has("context")) {
    auto c = from_hex(o.get("context"));
    if (!c) return usage_error("sign", "--context must be hex");
    if (c->size() > mldsa65::kMaxContextBytes)
      return usage_error("sign", "--context is longer than 255 bytes");
    ctx = *c;
  }
  if (alg == "ed25519" && (o.has("context") || o.has("deterministic")))
    return usage_error(
        "sign", "--context and --deterministic apply to ml-dsa-65 only (Ed25519 is deterministic)");
  auto k = keys::load_dir(o.get("key-dir"));
  if (!k.ok()) {
    std::fprintf(stderr, "rcan sign: %s\n", k.error().message.c_str());
    return 1;
  }
  std::string msg = read_stdin();
  Result<Bytes> sig = Error(ErrorCode::kInternal, "unreachable");
  if (alg == "ml-dsa-65") {
    mldsa65::SignOptions so;
    so.deterministic = o.has("deterministic");
    so.context = ctx;
    sig = mldsa65::sign(k->mldsa65_sk.span(), bytes_of(msg), so);
  } else {
    sig = ed25519::sign(k->ed25519_seed.span(), bytes_of(msg));
  }
  if (!sig.ok()) {
    std::fprintf(stderr, "rcan sign: %s\n", sig.error().message.c_str());
    return 1;
  }
  std::cout << base64_encode(*sig) << "\n";
  return 0;
}

int verify_main(const Args& args) {
  if (!args.empty() && (args[0] == "--help" || args[0] == "-h")) {
    std::fputs(kVerifyHelp, stdout);
    return 0;
  }
  Options o(args, {}, {"pub", "alg", "sig", "context"});
  if (!o.ok()) return usage_error("verify", o.error());
  if (!o.positional().empty())
    return usage_error("verify", "unexpected argument " + o.positional()[0]);
  std::string alg = o.get("alg");
  if (alg != "ml-dsa-65" && alg != "ed25519")
    return usage_error("verify", "--alg must be ml-dsa-65 or ed25519");
  if (o.get("pub").empty()) return usage_error("verify", "--pub FILE is required");
  if (!o.has("sig")) return usage_error("verify", "--sig B64 is required");
  Bytes ctx;
  if (o.has("context")) {
    if (alg == "ed25519") return usage_error("verify", "--context applies to ml-dsa-65 only");
    auto c = from_hex(o.get("context"));
    if (!c || c->size() > mldsa65::kMaxContextBytes)
      return usage_error("verify", "--context must be hex, at most 255 bytes");
    ctx = *c;
  }
  std::string sig_text = o.get("sig");
  while (!sig_text.empty() && (sig_text.back() == '\n' || sig_text.back() == '\r'))
    sig_text.pop_back();
  auto sig = base64_decode(sig_text);
  if (!sig) sig = base64url_decode(sig_text);
  if (!sig) return usage_error("verify", "--sig is not base64");
  auto pub = keys::read_public_file(o.get("pub"), 64 * 1024);
  if (!pub.ok()) return usage_error("verify", pub.error().message);
  Bytes pk = *pub;
  if (alg == "ed25519" && pk.size() != ed25519::kPublicKeyBytes) {
    auto from_pem = ed25519::public_key_from_pem(
        std::string_view(reinterpret_cast<const char*>(pk.data()), pk.size()));
    if (!from_pem.ok())
      return usage_error("verify", o.get("pub") + " is neither a 32-byte Ed25519 key nor its PEM");
    pk = *from_pem;
  }
  if (alg == "ml-dsa-65" && pk.size() != mldsa65::kPublicKeyBytes)
    return usage_error("verify", o.get("pub") + " is not a 1952-byte ML-DSA-65 public key");
  std::string msg = read_stdin();
  bool ok = alg == "ml-dsa-65" ? mldsa65::verify(pk, bytes_of(msg), *sig, ctx)
                               : ed25519::verify(pk, bytes_of(msg), *sig);
  std::cout << (ok ? "valid" : "invalid") << "\n";
  return ok ? 0 : 1;
}

const Registration kSignReg{"sign", "sign stdin with a key directory (ML-DSA-65 or Ed25519)",
                            &sign_main};
const Registration kVerifyReg{"verify", "verify an ML-DSA-65 or Ed25519 signature over stdin",
                              &verify_main};

}  // namespace
}  // namespace rcan::cli

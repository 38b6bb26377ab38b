// libFuzzer target: the JWT parser and verifier. Arbitrary bytes as a token go through
// decode() and a JwtVerifier that trusts one key of every algorithm; when the input decodes,
// its claims also go through check_claims(). Must never crash, and anything that verifies
// must have been signed by one of the fixed keys (impossible for random input) — so a
// successful verification aborts.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "rcan/crypto/jwt.h"

namespace {

using namespace rcan;

const jwt::JwtVerifier& verifier() {
  static const jwt::JwtVerifier v = [] {
    jwt::TrustStore ts;
    Bytes seed(32, 0x11);
    auto ed = jwt::SigningKey::ed25519_seed(seed);
    if (ed.ok()) ts.add("iss", *ed->verification_key(), "ed");
    auto hs = jwt::VerificationKey::hs256_secret(Bytes(32, 0x22));
    if (hs.ok()) ts.add("iss", *hs, "hs");
    // A fixed P-256 public key (RFC 7515 A.3 example key).
    auto ec = jwt::VerificationKey::from_jwk(*json::parse(
        R"({"kty":"EC","crv":"P-256","x":"f83OJ3D2xF1Bg8vub9tLe1gHMzV76e8Tus9uPHvRVEU","y":"x_FEzRu9m36HLN_tue659LNpXW6pM5Ba0ksTgMgkWqA"})"));
    if (ec.ok()) ts.add("iss", *ec, "ec");
    jwt::VerifyOptions o;
    o.audience = "rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6";
    o.fleet_ids = {"d3a4b5c6"};
    return jwt::JwtVerifier(std::move(ts), o);
  }();
  return v;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string_view token(reinterpret_cast<const char*>(data), size);
  auto d = jwt::decode(token);
  if (d.ok()) {
    jwt::VerifyOptions o;
    o.audience = "rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6";
    o.fleet_ids = {"d3a4b5c6"};
    auto c = jwt::check_claims(d->claims, o, 1767225600);
    (void)c;
  }
  auto r = verifier().verify(token, 1767225600);
  if (r.ok()) std::abort();  // a forged token verified
  return 0;
}

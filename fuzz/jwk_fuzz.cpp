// libFuzzer target: key parsers — JWK / JWKS (public keys and, with allow_secret, oct),
// PEM public and private keys, the ML-DSA-65 JWK decoder and a token's `cnf` claim (key-bound
// tokens, rcan/crypto/cnf.h). Byte 0 selects the parser.
// Must never crash; every rejection carries a message.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "rcan/crypto/cnf.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/keys.h"
#include "rcan/errors.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  if (size < 1) return 0;
  const uint8_t mode = data[0];
  std::string_view text(reinterpret_cast<const char*>(data + 1), size - 1);
  switch (mode % 6) {
    case 0: {
      auto ks = jwt::parse_jwk_set(text);
      if (!ks.ok() && ks.error().message.empty()) std::abort();
      if (ks.ok()) {
        for (const auto& k : *ks) (void)k.verify("a.b", std::span<const uint8_t>(data, size));
      }
      break;
    }
    case 1: {
      auto v = json::parse(text);
      if (v.ok()) {
        auto k = jwt::VerificationKey::from_jwk(*v, (mode & 0x80) != 0);
        if (!k.ok() && k.error().message.empty()) std::abort();
      }
      break;
    }
    case 2: {
      auto k = jwt::VerificationKey::from_pem(text);
      if (k.ok()) (void)k->verify("a.b", std::span<const uint8_t>(data, size));
      break;
    }
    case 3: {
      auto k = jwt::SigningKey::from_pem(text);
      if (k.ok()) (void)k->sign("a.b");
      break;
    }
    case 4: {
      auto v = json::parse(text);
      if (v.ok()) {
        auto pk = keys::mldsa65_pk_from_jwk(*v);
        if (pk.ok() && pk->size() != 1952) std::abort();
      }
      break;
    }
    case 5: {
      auto v = json::parse(text);
      if (v.ok()) {
        auto k = cnf::parse(*v);
        if (!k.ok() && (k.error().message.empty() || k.error().code != ErrorCode::kAuthInvalid))
          std::abort();
        if (k.ok() && k->public_key.size() != 32 && k->public_key.size() != 1952) std::abort();
        if (k.ok() && k->kid.size() != 8) std::abort();
      }
      break;
    }
  }
  return 0;
}

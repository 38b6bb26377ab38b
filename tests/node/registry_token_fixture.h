// A robot that follows a registry, and the registry's signing keys, for the in-process tests of
// registry trust (registry_feed_test, registry_trust_link_test): the robot's audience and RRN,
// Ed25519 keys made from a fill byte, their JWKs and the registry's OWNER tokens for the robot.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "node/admission/authenticator.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/jwt.h"
#include "rcan/encoding.h"
#include "rcan/json.h"

namespace rcan::node::registry_fixture {

inline constexpr int64_t kNowS = 1'800'000'000;
inline const std::string kAud = "rcan://local.rcan/acme/rover/abcdef12";
inline const std::string kRrn = "RRN-000000000042";
inline const std::string kIss = "https://registry.example";

inline std::array<uint8_t, 32> seed(uint8_t fill) {
  std::array<uint8_t, 32> s{};
  s.fill(fill);
  return s;
}

// The public JWK of the key made from `fill`.
inline std::string jwk(uint8_t fill, const std::string& kid) {
  auto pk = ed25519::public_key_from_seed(seed(fill));
  return R"({"kty":"OKP","crv":"Ed25519","x":")" + base64url_encode(*pk) + R"(","kid":")" + kid +
         R"(","use":"sig","alg":"EdDSA"})";
}

// An OWNER token for the robot, issued by `iss` at kNowS - 10 for an hour.
inline std::string token(uint8_t fill, const std::string& kid, const std::string& iss = kIss) {
  auto key = jwt::SigningKey::ed25519_seed(seed(fill));
  json::Object c{{"iss", iss},      {"sub", "ops"},      {"aud", kAud},        {"rrn", kRrn},
                 {"role", "owner"}, {"iat", kNowS - 10}, {"exp", kNowS + 3600}};
  return *jwt::issue(c, *key, kid);
}

// The robot's authenticator: its own local key (fill 9), its audience and RRN.
inline Authenticator make_auth() {
  AuthOptions o;
  auto local = jwt::SigningKey::ed25519_seed(seed(9));
  o.trust.add("local", *local->verification_key());
  o.verify.audience = kAud;
  o.own_rrn = kRrn;
  return Authenticator(std::move(o));
}

}  // namespace rcan::node::registry_fixture

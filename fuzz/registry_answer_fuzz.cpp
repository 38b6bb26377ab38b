// libFuzzer target: what rcand reads back from its registry when it introspects a token it
// cannot verify (RFC 7662) and when it registers itself (challenge, registration answer, a
// refusal's error body) — node/admission/registry_feed.h, straight off the network. The first
// byte picks the reader, the rest is the body. Must never crash; an answer never yields an
// `active` claim or a use beyond now + the active window; an introspected answer's claims go
// through the Authenticator as rcand's would, and a principal it yields names the registry as
// its issuer and this robot as the audience; a registration yields a valid RRN; a refusal line
// stays bounded.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <optional>
#include <string>
#include <string_view>

#include "node/admission/authenticator.h"
#include "node/admission/registry_feed.h"
#include "rcan/crypto/jwt.h"
#include "rcan/encoding.h"
#include "rcan/registry.h"

namespace {

constexpr int64_t kNowS = 1'800'000'000;
constexpr int64_t kNowMs = kNowS * 1000, kActiveMs = 60'000, kInactiveMs = 30'000;
const char* const kIss = "https://registry.example";
const char* const kAud = "rcan://local.rcan/acme/rover/abcdef12";

// A token of the registry's issuer under a kid the node has no key for: the node asks the
// registry, and the fuzzed answer decides.
std::string unverifiable_token() {
  const std::string header = R"({"alg":"EdDSA","typ":"JWT","kid":"unknown"})";
  const std::string claims = std::string(R"({"iss":")") + kIss + R"(","sub":"x","exp":)" +
                             std::to_string(kNowS + 60) + "}";
  auto b64 = [](const std::string& s) {
    return rcan::base64url_encode(reinterpret_cast<const uint8_t*>(s.data()), s.size());
  };
  return b64(header) + "." + b64(claims) + "." + std::string(86, 'A');
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  if (size == 0) return 0;
  const uint8_t which = data[0] % 4;
  std::string_view body(reinterpret_cast<const char*>(data) + 1, size - 1);
  switch (which) {
    case 0: {
      auto a = node::parse_introspection_answer(body, kNowMs, kActiveMs, kInactiveMs);
      if (!a.ok()) {
        if (a.error().message.empty()) std::abort();
        break;
      }
      if (a->until_ms > kNowMs + kActiveMs) std::abort();
      if (!a->claims) {
        if (a->until_ms != kNowMs + kInactiveMs) std::abort();
        break;
      }
      if (a->claims->find("active") != nullptr) std::abort();
      node::AuthOptions o;
      o.verify.audience = kAud;
      o.token_cache_entries = 0;
      node::Authenticator auth(std::move(o));
      std::optional<json::Object> answer = a->claims;
      auth.on_unknown_followed_key(
          kIss, [](const std::string&, std::string_view) {},
          [&](std::string_view) { return answer; });
      auto p = auth.authenticate_token(unverifiable_token(), kNowS);
      if (p.ok() && (p->issuer != kIss || !p->authenticated)) std::abort();
      if (!p.ok() && p.error().message.empty()) std::abort();
      break;
    }
    case 1: {
      auto c = node::parse_registry_challenge(body);
      if (c.ok() &&
          (c->id.empty() || c->nonce.empty() || c->id.size() > 512 || c->nonce.size() > 512))
        std::abort();
      if (!c.ok() && c.error().message.empty()) std::abort();
      break;
    }
    case 2: {
      auto r = node::parse_registration_answer(body);
      if (r.ok() && registry::normalize_rrn(r->rrn) != r->rrn) std::abort();
      if (!r.ok() && r.error().message.empty()) std::abort();
      break;
    }
    default: {
      const std::string line = node::registry_refusal(400, body);
      if (line.size() > 600 || line.rfind("the registry answered 400", 0) != 0) std::abort();
      break;
    }
  }
  return 0;
}

// JWT verification cost per algorithm: full JwtVerifier::verify (decode, key selection,
// signature, claim checks incl. aud matching), plus decode-only and issuing.
#include <benchmark/benchmark.h>
#include <openssl/evp.h>
#include <openssl/pem.h>

#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "rcan/crypto/jwt.h"

namespace {

using namespace rcan;

constexpr int64_t kNow = 1767225600;
const std::string kIss = "https://auth.example.org";
const std::string kRobot = "rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6";

std::string private_pem(EVP_PKEY* pk) {
  BIO* bio = BIO_new(BIO_s_mem());
  PEM_write_bio_PrivateKey(bio, pk, nullptr, nullptr, 0, nullptr, nullptr);
  char* p = nullptr;
  long n = BIO_get_mem_data(bio, &p);
  std::string out(p, static_cast<size_t>(n));
  BIO_free(bio);
  EVP_PKEY_free(pk);
  return out;
}

jwt::SigningKey make_key(jwt::Alg alg) {
  Result<jwt::SigningKey> k = Error(ErrorCode::kInternal, "");
  switch (alg) {
    case jwt::Alg::kEdDSA:
      k = jwt::SigningKey::from_pem(private_pem(EVP_PKEY_Q_keygen(nullptr, nullptr, "ED25519")));
      break;
    case jwt::Alg::kES256:
      k = jwt::SigningKey::from_pem(
          private_pem(EVP_PKEY_Q_keygen(nullptr, nullptr, "EC", "P-256")));
      break;
    case jwt::Alg::kRS256:
      k = jwt::SigningKey::from_pem(
          private_pem(EVP_PKEY_Q_keygen(nullptr, nullptr, "RSA", size_t{2048})));
      break;
    case jwt::Alg::kHS256:
      k = jwt::SigningKey::hs256_secret(Bytes(48, 0x5a));
      break;
  }
  if (!k.ok()) {
    std::fprintf(stderr, "key generation failed: %s\n", k.error().message.c_str());
    std::abort();
  }
  return std::move(k).value();
}

json::Object claims() {
  json::Object c;
  c.set("iss", kIss);
  c.set("sub", "user-7f3c");
  c.set("aud", "rcan://continuon.cloud/continuon/companion-v1/*");
  c.set("role", "owner");
  c.set("scope", json::Array{"control", "config", "training"});
  c.set("fleet", json::Array{"d3a4b5c6", "robot-002"});
  c.set("iat", int64_t{kNow - 10});
  c.set("exp", int64_t{kNow + 3600});
  return c;
}

struct Setup {
  std::string token;
  jwt::JwtVerifier verifier;
};

Setup make_setup(jwt::Alg alg) {
  jwt::SigningKey key = make_key(alg);
  auto tok = jwt::issue(claims(), key, "k1");
  jwt::TrustStore ts;
  ts.add(kIss, *key.verification_key(), "k1");
  jwt::VerifyOptions o;
  o.audience = kRobot;
  o.fleet_ids = {"d3a4b5c6"};
  return Setup{*tok, jwt::JwtVerifier(std::move(ts), o)};
}

void BM_JwtVerify(benchmark::State& state, jwt::Alg alg) {
  Setup s = make_setup(alg);
  if (!s.verifier.verify(s.token, kNow).ok()) {
    state.SkipWithError("token does not verify");
    return;
  }
  for (auto _ : state) {
    auto r = s.verifier.verify(s.token, kNow);
    benchmark::DoNotOptimize(r);
  }
  state.SetLabel(std::to_string(s.token.size()) + " B token");
}
BENCHMARK_CAPTURE(BM_JwtVerify, EdDSA, jwt::Alg::kEdDSA);
BENCHMARK_CAPTURE(BM_JwtVerify, ES256, jwt::Alg::kES256);
BENCHMARK_CAPTURE(BM_JwtVerify, RS256, jwt::Alg::kRS256);
BENCHMARK_CAPTURE(BM_JwtVerify, HS256, jwt::Alg::kHS256);

void BM_JwtVerifyBadSignature(benchmark::State& state, jwt::Alg alg) {
  Setup s = make_setup(alg);
  std::string bad = s.token;
  char& c = bad[bad.size() - 3];
  c = c == 'A' ? 'B' : 'A';
  for (auto _ : state) {
    auto r = s.verifier.verify(bad, kNow);
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK_CAPTURE(BM_JwtVerifyBadSignature, EdDSA, jwt::Alg::kEdDSA);
BENCHMARK_CAPTURE(BM_JwtVerifyBadSignature, HS256, jwt::Alg::kHS256);

void BM_JwtDecodeOnly(benchmark::State& state) {
  Setup s = make_setup(jwt::Alg::kHS256);
  for (auto _ : state) {
    auto d = jwt::decode(s.token);
    benchmark::DoNotOptimize(d);
  }
}
BENCHMARK(BM_JwtDecodeOnly);

void BM_JwtIssue(benchmark::State& state, jwt::Alg alg) {
  jwt::SigningKey key = make_key(alg);
  json::Object c = claims();
  for (auto _ : state) {
    auto t = jwt::issue(c, key, "k1");
    benchmark::DoNotOptimize(t);
  }
}
BENCHMARK_CAPTURE(BM_JwtIssue, EdDSA, jwt::Alg::kEdDSA);
BENCHMARK_CAPTURE(BM_JwtIssue, ES256, jwt::Alg::kES256);
BENCHMARK_CAPTURE(BM_JwtIssue, RS256, jwt::Alg::kRS256);
BENCHMARK_CAPTURE(BM_JwtIssue, HS256, jwt::Alg::kHS256);

}  // namespace

BENCHMARK_MAIN();

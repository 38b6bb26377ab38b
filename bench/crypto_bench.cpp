// Crypto micro-benchmarks: ML-DSA-65 keygen/sign/verify, Ed25519 sign/verify, HMAC-SHA256.
//
// ML-DSA signing time depends on the number of rejection-loop iterations (about 5 on average
// for ML-DSA-65, geometrically distributed), so BM_MlDsa65_Sign cycles through 1024 random
// messages and the reported time is the mean over them.
#include <benchmark/benchmark.h>

#include <random>
#include <vector>

#include "crypto/mldsa65_internal.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/hash.h"

namespace {

using rcan::Bytes;

std::vector<Bytes> random_messages(size_t count, size_t len, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<Bytes> out(count, Bytes(len));
  for (auto& m : out)
    for (auto& b : m) b = static_cast<uint8_t>(rng());
  return out;
}

const rcan::mldsa65::KeyPair& mldsa_keys() {
  static const rcan::mldsa65::KeyPair kp = [] {
    Bytes seed(32);
    for (size_t i = 0; i < seed.size(); ++i) seed[i] = static_cast<uint8_t>(i);
    return rcan::mldsa65::keygen_from_seed(seed).value();
  }();
  return kp;
}

void BM_MlDsa65_KeyGen(benchmark::State& state) {
  Bytes seed(32, 0);
  uint32_t counter = 0;
  for (auto _ : state) {
    seed[0] = static_cast<uint8_t>(counter);
    seed[1] = static_cast<uint8_t>(counter++ >> 8);
    auto kp = rcan::mldsa65::keygen_from_seed(seed);
    benchmark::DoNotOptimize(kp);
  }
}
BENCHMARK(BM_MlDsa65_KeyGen)->Unit(benchmark::kMicrosecond);

void BM_MlDsa65_Sign(benchmark::State& state) {
  const auto& kp = mldsa_keys();
  const auto msgs = random_messages(1024, 64, 1);
  size_t i = 0;
  for (auto _ : state) {
    auto sig = rcan::mldsa65::sign(kp.secret_key, msgs[i++ % msgs.size()]);  // hedged
    benchmark::DoNotOptimize(sig);
  }
}
BENCHMARK(BM_MlDsa65_Sign)->Unit(benchmark::kMicrosecond)->MinTime(3.0);

void BM_MlDsa65_SignDeterministic(benchmark::State& state) {
  const auto& kp = mldsa_keys();
  const auto msgs = random_messages(1024, 64, 2);
  rcan::mldsa65::SignOptions o;
  o.deterministic = true;
  size_t i = 0;
  for (auto _ : state) {
    auto sig = rcan::mldsa65::sign(kp.secret_key, msgs[i++ % msgs.size()], o);
    benchmark::DoNotOptimize(sig);
  }
}
BENCHMARK(BM_MlDsa65_SignDeterministic)->Unit(benchmark::kMicrosecond)->MinTime(3.0);

void BM_MlDsa65_Verify(benchmark::State& state) {
  const auto& kp = mldsa_keys();
  const auto msgs = random_messages(64, 64, 3);
  std::vector<Bytes> sigs;
  for (const auto& m : msgs) sigs.push_back(rcan::mldsa65::sign(kp.secret_key, m).value());
  size_t i = 0;
  for (auto _ : state) {
    const size_t k = i++ % msgs.size();
    bool ok = rcan::mldsa65::verify(kp.public_key, msgs[k], sigs[k]);
    if (!ok) state.SkipWithError("verification failed");
    benchmark::DoNotOptimize(ok);
  }
}
BENCHMARK(BM_MlDsa65_Verify)->Unit(benchmark::kMicrosecond);

// The same operations with the baseline-ISA (SSE2) build of the arithmetic, i.e. without the
// AVX2-compiled variant that is chosen by default on CPUs that have it.
template <void (*Fn)(benchmark::State&)>
void Baseline(benchmark::State& state) {
  rcan::mldsa65::internal::select_simd(false);
  Fn(state);
  rcan::mldsa65::internal::select_simd(true);
}
BENCHMARK(Baseline<BM_MlDsa65_KeyGen>)
    ->Name("BM_MlDsa65_KeyGen_Baseline")
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(Baseline<BM_MlDsa65_Sign>)
    ->Name("BM_MlDsa65_Sign_Baseline")
    ->Unit(benchmark::kMicrosecond)
    ->MinTime(3.0);
BENCHMARK(Baseline<BM_MlDsa65_Verify>)
    ->Name("BM_MlDsa65_Verify_Baseline")
    ->Unit(benchmark::kMicrosecond);

void BM_Ed25519_Sign(benchmark::State& state) {
  const Bytes seed(32, 7);
  const auto msgs = random_messages(64, 64, 4);
  size_t i = 0;
  for (auto _ : state) {
    auto sig = rcan::ed25519::sign(seed, msgs[i++ % msgs.size()]);
    benchmark::DoNotOptimize(sig);
  }
}
BENCHMARK(BM_Ed25519_Sign)->Unit(benchmark::kMicrosecond);

void BM_Ed25519_Verify(benchmark::State& state) {
  const Bytes seed(32, 7);
  const Bytes pk = rcan::ed25519::public_key_from_seed(seed).value();
  const auto msgs = random_messages(64, 64, 5);
  std::vector<Bytes> sigs;
  for (const auto& m : msgs) sigs.push_back(rcan::ed25519::sign(seed, m).value());
  size_t i = 0;
  for (auto _ : state) {
    const size_t k = i++ % msgs.size();
    bool ok = rcan::ed25519::verify(pk, msgs[k], sigs[k]);
    if (!ok) state.SkipWithError("verification failed");
    benchmark::DoNotOptimize(ok);
  }
}
BENCHMARK(BM_Ed25519_Verify)->Unit(benchmark::kMicrosecond);

void BM_HmacSha256_1KiB(benchmark::State& state) {
  const Bytes key(32, 0x0b);
  const Bytes data = random_messages(1, 1024, 6)[0];
  for (auto _ : state) {
    auto mac = rcan::hmac_sha256(key.data(), key.size(), data.data(), data.size());
    benchmark::DoNotOptimize(mac);
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) * 1024);
}
BENCHMARK(BM_HmacSha256_1KiB)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();

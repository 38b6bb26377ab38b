// ML-DSA-65 (FIPS 204): arithmetic building blocks, every shared vector case, malformed and
// tampered inputs, hedged/deterministic behaviour, and a cross-check with pyca/cryptography.
#include "rcan/crypto/mldsa65.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <random>
#include <sstream>

#include "crypto/mldsa65_internal.h"
#include "rcan/hash.h"
#include "test_support.h"

namespace {

using rcan::Bytes;
using rcan::test::hex;
namespace mldsa65 = rcan::mldsa65;
namespace internal = rcan::mldsa65::internal;

constexpr int32_t kQ = internal::kQ;
constexpr int32_t kGamma1 = 1 << 19;
constexpr int32_t kBeta = 196;
constexpr size_t kZOffset = 48;
constexpr size_t kHintOffset = 48 + 5 * 640;
constexpr size_t kOmega = 55;

const std::string& str(const rcan::json::Value& v, const char* key) {
  static const std::string kEmpty;
  const auto* f = v.get(key);
  if (f == nullptr || !f->is_string()) {
    ADD_FAILURE() << "vector field missing: " << key;
    return kEmpty;
  }
  return f->as_string();
}

Bytes m_prime(const Bytes& msg, const Bytes& ctx) {
  Bytes m;
  m.reserve(2 + ctx.size() + msg.size());
  m.push_back(0);
  m.push_back(static_cast<uint8_t>(ctx.size()));
  for (uint8_t b : ctx) m.push_back(b);
  for (uint8_t b : msg) m.push_back(b);
  return m;
}

Bytes seed_of(uint8_t start) {
  Bytes s(32);
  for (size_t i = 0; i < s.size(); ++i) s[i] = static_cast<uint8_t>(start + i);
  return s;
}

// Runs `body` once with the baseline-ISA build of the algorithms and once with the AVX2 build
// (when the CPU has it), restoring the default afterwards.
template <typename Body>
void for_each_code_path(Body body) {
  for (bool simd : {false, true}) {
    const bool active = internal::select_simd(simd);
    if (simd && !active) continue;  // no AVX2 on this CPU: baseline only
    SCOPED_TRACE(simd ? "AVX2 code path" : "baseline code path");
    body();
  }
  internal::select_simd(true);
}

// ---- arithmetic ------------------------------------------------------------------------

int64_t mod_q(int64_t a) { return ((a % kQ) + kQ) % kQ; }

TEST(MlDsa65Arithmetic, DecomposeMatchesDefinitionForEveryResidue) {
  // FIPS 204 Alg. 36 written naively, against the branch-free version, for all of [0, q).
  constexpr int32_t two_g2 = 2 * internal::kGamma2;
  size_t mismatches = 0;
  for (int32_t a = 0; a < kQ; ++a) {
    int32_t r0 = a % two_g2;
    if (r0 > internal::kGamma2) r0 -= two_g2;
    int32_t r1;
    if (a - r0 == kQ - 1) {
      r1 = 0;
      r0 -= 1;
    } else {
      r1 = (a - r0) / two_g2;
    }
    int32_t h, l;
    internal::decompose(a, &h, &l);
    if (h != r1 || l != r0) ++mismatches;
  }
  EXPECT_EQ(mismatches, 0u);
}

TEST(MlDsa65Arithmetic, UseHintMatchesDefinition) {
  std::mt19937 rng(7);
  for (int i = 0; i < 200000; ++i) {
    const int32_t a = static_cast<int32_t>(rng() % kQ);
    int32_t r1, r0;
    internal::decompose(a, &r1, &r0);
    EXPECT_EQ(internal::use_hint(a, 0), r1);
    const int32_t want = r0 > 0 ? (r1 + 1) % 16 : (r1 + 15) % 16;
    ASSERT_EQ(internal::use_hint(a, 1), want) << a;
  }
  // Corners: 0, q-1 and the folding region.
  EXPECT_EQ(internal::use_hint(0, 1), 15);
  EXPECT_EQ(internal::use_hint(kQ - 1, 1), 15);
}

TEST(MlDsa65Arithmetic, MontgomeryAndFreeze) {
  std::mt19937_64 rng(11);
  const int64_t r_inv = [] {  // 2^-32 mod q
    int64_t inv = 1, base = mod_q(int64_t{1} << 32);
    for (int64_t e = kQ - 2; e; e >>= 1, base = base * base % kQ)
      if (e & 1) inv = inv * base % kQ;
    return inv;
  }();
  for (int i = 0; i < 100000; ++i) {
    const int64_t a = static_cast<int64_t>(rng() % (uint64_t{1} << 53)) - (int64_t{1} << 52);
    const int32_t r = internal::montgomery_reduce(a);
    ASSERT_LT(std::abs(r), kQ);
    ASSERT_EQ(mod_q(r), mod_q(mod_q(a) * r_inv)) << a;
    const int32_t x = static_cast<int32_t>(rng() % (uint64_t{1} << 32) - (uint64_t{1} << 31)) / 2;
    const int32_t f = internal::freeze(x);
    ASSERT_TRUE(f >= 0 && f < kQ);
    ASSERT_EQ(f, mod_q(x));
  }
}

TEST(MlDsa65Arithmetic, NttProductEqualsNegacyclicSchoolbook) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    int32_t a[256], b[256];
    for (int i = 0; i < 256; ++i) {
      a[i] = static_cast<int32_t>(rng() % kQ) - kQ / 2;
      b[i] = static_cast<int32_t>(rng() % kQ) - kQ / 2;
    }
    int64_t want[256] = {};
    for (int i = 0; i < 256; ++i) {
      for (int j = 0; j < 256; ++j) {
        const int64_t p = mod_q(static_cast<int64_t>(a[i]) * b[j]);
        if (i + j < 256) {
          want[i + j] = mod_q(want[i + j] + p);
        } else {
          want[i + j - 256] = mod_q(want[i + j - 256] - p);
        }
      }
    }
    internal::ntt(a);
    internal::ntt(b);
    int32_t c[256];
    for (int i = 0; i < 256; ++i) c[i] = internal::pointwise_montgomery(a[i], b[i]);
    internal::intt_from_montgomery(c);
    for (int i = 0; i < 256; ++i) {
      ASSERT_LT(std::abs(c[i]), kQ);
      ASSERT_EQ(mod_q(c[i]), want[i]) << "trial " << trial << " coefficient " << i;
    }
  }
}

// ---- vectors -----------------------------------------------------------------------------

TEST(MlDsa65Vectors, KeyGenAllCases) {
  for_each_code_path([&] {
    const auto v = rcan::test::load_vector("mldsa65-keygen.json");
    const auto* cases = v.get("cases");
    ASSERT_NE(cases, nullptr);
    ASSERT_EQ(cases->as_array().size(), 25u);
    size_t checked = 0;
    for (const auto& c : cases->as_array()) {
      const Bytes seed = hex(str(c, "seed_hex"));
      auto kp = mldsa65::keygen_from_seed(seed);
      ASSERT_TRUE(kp.ok()) << kp.error().message;
      ASSERT_EQ(kp->public_key.size(), mldsa65::kPublicKeyBytes);
      ASSERT_EQ(kp->secret_key.size(), mldsa65::kSecretKeyBytes);
      EXPECT_EQ(rcan::to_hex(kp->public_key), str(c, "pk_hex")) << "case " << checked;
      EXPECT_EQ(rcan::to_hex(kp->secret_key), str(c, "sk_hex")) << "case " << checked;
      EXPECT_EQ(mldsa65::kid(kp->public_key), str(c, "kid"));
      auto pk_digest = rcan::sha256(kp->public_key.data(), kp->public_key.size());
      auto sk_digest = rcan::sha256(kp->secret_key.data(), kp->secret_key.size());
      EXPECT_EQ(rcan::to_hex(pk_digest.data(), 32), str(c, "pk_sha256"));
      EXPECT_EQ(rcan::to_hex(sk_digest.data(), 32), str(c, "sk_sha256"));
      ++checked;
    }
    EXPECT_EQ(checked, 25u);
  });
}

TEST(MlDsa65Vectors, DeterministicSignaturesAllCases) {
  for_each_code_path([&] {
    const auto v = rcan::test::load_vector("mldsa65-sign-deterministic.json");
    const auto* cases = v.get("cases");
    ASSERT_NE(cases, nullptr);
    ASSERT_EQ(cases->as_array().size(), 25u);
    size_t checked = 0, with_ctx = 0;
    for (const auto& c : cases->as_array()) {
      auto kp = mldsa65::keygen_from_seed(hex(str(c, "seed_hex")));
      ASSERT_TRUE(kp.ok());
      ASSERT_EQ(rcan::to_hex(kp->public_key), str(c, "pk_hex"));
      const Bytes msg = hex(str(c, "msg_hex"));
      const Bytes ctx = hex(str(c, "ctx_hex"));
      if (!ctx.empty()) ++with_ctx;
      mldsa65::SignOptions opts;
      opts.deterministic = true;
      opts.context = ctx;
      auto sig = mldsa65::sign(kp->secret_key, msg, opts);
      ASSERT_TRUE(sig.ok()) << sig.error().message;
      ASSERT_EQ(sig->size(), mldsa65::kSignatureBytes);
      EXPECT_EQ(rcan::to_hex(*sig), str(c, "sig_hex")) << "case " << checked;
      auto d = rcan::sha256(sig->data(), sig->size());
      EXPECT_EQ(rcan::to_hex(d.data(), 32), str(c, "sig_sha256"));
      EXPECT_TRUE(mldsa65::verify(kp->public_key, msg, *sig, ctx));
      // The deterministic variant is Sign_internal with rnd = 0^32 over M'.
      auto internal_sig = mldsa65::sign_internal(kp->secret_key, m_prime(msg, ctx), Bytes(32, 0));
      ASSERT_TRUE(internal_sig.ok());
      EXPECT_EQ(*internal_sig, *sig);
      ++checked;
    }
    EXPECT_EQ(checked, 25u);
    EXPECT_EQ(with_ctx, 5u);
  });
}

TEST(MlDsa65Vectors, FixedRndSignInternalAllCases) {
  for_each_code_path([&] {
    const auto v = rcan::test::load_vector("mldsa65-sign-deterministic.json");
    const auto* cases = v.get("fixed_rnd_cases");
    ASSERT_NE(cases, nullptr);
    ASSERT_EQ(cases->as_array().size(), 3u);
    for (const auto& c : cases->as_array()) {
      auto kp = mldsa65::keygen_from_seed(hex(str(c, "seed_hex")));
      ASSERT_TRUE(kp.ok());
      const Bytes msg = hex(str(c, "msg_hex"));
      const Bytes ctx = hex(str(c, "ctx_hex"));
      auto sig = mldsa65::sign_internal(kp->secret_key, m_prime(msg, ctx), hex(str(c, "rnd_hex")));
      ASSERT_TRUE(sig.ok()) << sig.error().message;
      EXPECT_EQ(rcan::to_hex(*sig), str(c, "sig_hex"));
      EXPECT_TRUE(mldsa65::verify(kp->public_key, msg, *sig, ctx));
    }
  });
}

TEST(MlDsa65Vectors, VerifyAllCases) {
  for_each_code_path([&] {
    const auto v = rcan::test::load_vector("mldsa65-verify.json");
    const auto* cases = v.get("cases");
    ASSERT_NE(cases, nullptr);
    ASSERT_EQ(cases->as_array().size(), 40u);
    size_t n_valid = 0, n_invalid = 0, index = 0;
    for (const auto& c : cases->as_array()) {
      const auto* valid = c.get("valid");
      ASSERT_TRUE(valid != nullptr && valid->is_bool());
      const bool got = mldsa65::verify(hex(str(c, "pk_hex")), hex(str(c, "msg_hex")),
                                       hex(str(c, "sig_hex")), hex(str(c, "ctx_hex")));
      EXPECT_EQ(got, valid->as_bool()) << "case " << index << ": " << str(c, "why");
      (valid->as_bool() ? n_valid : n_invalid)++;
      ++index;
    }
    EXPECT_EQ(n_valid, 12u);
    EXPECT_EQ(n_invalid, 28u);
  });
}

// ---- behaviour -----------------------------------------------------------------------------

class MlDsa65Signing : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto kp = mldsa65::keygen_from_seed(seed_of(0x40));
    ASSERT_TRUE(kp.ok());
    keys_ = new mldsa65::KeyPair(std::move(kp).value());
  }
  static void TearDownTestSuite() {
    delete keys_;
    keys_ = nullptr;
  }
  static const mldsa65::KeyPair& keys() { return *keys_; }

  // A deterministic signature over "rcan" with a message whose hint is non-trivial.
  static Bytes base_signature(Bytes* msg) {
    *msg = rcan::to_bytes("rcan hint test message");
    mldsa65::SignOptions o;
    o.deterministic = true;
    auto s = mldsa65::sign(keys().secret_key, *msg, o);
    EXPECT_TRUE(s.ok());
    return s.ok() ? *s : Bytes{};
  }

 private:
  static mldsa65::KeyPair* keys_;
};
mldsa65::KeyPair* MlDsa65Signing::keys_ = nullptr;

TEST_F(MlDsa65Signing, HedgedSignaturesDifferAndBothVerify) {
  const Bytes msg = rcan::to_bytes("move_forward 0.5 m/s");
  auto a = mldsa65::sign(keys().secret_key, msg);
  auto b = mldsa65::sign(keys().secret_key, msg);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_NE(*a, *b);
  EXPECT_TRUE(mldsa65::verify(keys().public_key, msg, *a));
  EXPECT_TRUE(mldsa65::verify(keys().public_key, msg, *b));
}

TEST_F(MlDsa65Signing, DeterministicSignaturesRepeat) {
  const Bytes msg = rcan::to_bytes("deterministic");
  mldsa65::SignOptions o;
  o.deterministic = true;
  auto a = mldsa65::sign(keys().secret_key, msg, o);
  auto b = mldsa65::sign(keys().secret_key, msg, o);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(*a, *b);
}

TEST_F(MlDsa65Signing, RoundTripWithAndWithoutContext) {
  std::mt19937 rng(99);
  for (size_t len : {size_t{0}, size_t{1}, size_t{64}, size_t{1000}, size_t{65536}}) {
    Bytes msg(len);
    for (auto& b : msg) b = static_cast<uint8_t>(rng());
    for (size_t ctx_len : {size_t{0}, size_t{1}, size_t{255}}) {
      Bytes ctx(ctx_len, 0x5a);
      mldsa65::SignOptions o;
      o.context = ctx;
      auto sig = mldsa65::sign(keys().secret_key, msg, o);
      ASSERT_TRUE(sig.ok()) << sig.error().message;
      EXPECT_TRUE(mldsa65::verify(keys().public_key, msg, *sig, ctx)) << len << "/" << ctx_len;
      // Context is bound to the signature.
      Bytes other_ctx = ctx;
      if (other_ctx.empty()) {
        other_ctx.push_back(0);
      } else {
        other_ctx.back() ^= 1;
      }
      EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, *sig, other_ctx));
      if (!ctx.empty()) {
        EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, *sig));
      }
    }
  }
}

TEST_F(MlDsa65Signing, ContextLongerThan255IsRejected) {
  const Bytes ctx(256, 1);
  mldsa65::SignOptions o;
  o.context = ctx;
  auto sig = mldsa65::sign(keys().secret_key, rcan::to_bytes("x"), o);
  EXPECT_FALSE(sig.ok());
  // A valid signature never verifies under an over-long context.
  auto good = mldsa65::sign(keys().secret_key, rcan::to_bytes("x"));
  ASSERT_TRUE(good.ok());
  EXPECT_FALSE(mldsa65::verify(keys().public_key, rcan::to_bytes("x"), *good, ctx));
}

TEST_F(MlDsa65Signing, MalformedLengthsAreRejected) {
  const Bytes msg = rcan::to_bytes("m");
  auto sig = mldsa65::sign(keys().secret_key, msg);
  ASSERT_TRUE(sig.ok());
  ASSERT_TRUE(mldsa65::verify(keys().public_key, msg, *sig));
  for (long delta : {-1L, 1L, -3309L, -1000L}) {
    Bytes s = *sig;
    s.resize(static_cast<size_t>(static_cast<long>(s.size()) + delta));
    EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, s)) << delta;
    Bytes pk = keys().public_key;
    pk.resize(static_cast<size_t>(std::max(0L, static_cast<long>(pk.size()) + delta)));
    EXPECT_FALSE(mldsa65::verify(pk, msg, *sig)) << delta;
    Bytes sk = keys().secret_key;
    sk.resize(static_cast<size_t>(std::max(0L, static_cast<long>(sk.size()) + delta)));
    EXPECT_FALSE(mldsa65::sign(sk, msg).ok()) << delta;
    EXPECT_FALSE(mldsa65::sign_internal(sk, msg, Bytes(32)).ok()) << delta;
  }
  EXPECT_FALSE(mldsa65::verify({}, msg, *sig));
  EXPECT_FALSE(mldsa65::sign_internal(keys().secret_key, msg, Bytes(31)).ok());
  EXPECT_FALSE(mldsa65::sign_internal(keys().secret_key, msg, Bytes(33)).ok());
  EXPECT_FALSE(mldsa65::keygen_from_seed(Bytes(31)).ok());
  EXPECT_FALSE(mldsa65::keygen_from_seed(Bytes(33)).ok());
  EXPECT_FALSE(mldsa65::keygen_from_seed({}).ok());
}

TEST_F(MlDsa65Signing, EveryTamperedRegionIsRejected) {
  const Bytes msg = rcan::to_bytes("tamper me");
  auto sig = mldsa65::sign(keys().secret_key, msg);
  ASSERT_TRUE(sig.ok());
  // Flip one bit at a spread of positions in c~, z and the hint section.
  for (size_t pos = 0; pos < sig->size(); pos += 37) {
    Bytes s = *sig;
    s[pos] ^= static_cast<uint8_t>(1u << (pos % 8));
    EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, s)) << "byte " << pos;
  }
  Bytes last = *sig;
  last.back() ^= 1;
  EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, last));
  Bytes m2 = msg;
  m2[0] ^= 0x80;
  EXPECT_FALSE(mldsa65::verify(keys().public_key, m2, *sig));
  for (size_t pos : {size_t{0}, size_t{31}, size_t{32}, size_t{1000}, size_t{1951}}) {
    Bytes pk = keys().public_key;
    pk[pos] ^= 4;
    EXPECT_FALSE(mldsa65::verify(pk, msg, *sig)) << "pk byte " << pos;
  }
  auto other = mldsa65::keygen_from_seed(seed_of(0x80));
  ASSERT_TRUE(other.ok());
  EXPECT_FALSE(mldsa65::verify(other->public_key, msg, *sig));
  EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, Bytes(mldsa65::kSignatureBytes, 0)));
  EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, Bytes(mldsa65::kSignatureBytes, 0xff)));
}

TEST_F(MlDsa65Signing, MalformedHintEncodingsAreRejected) {
  Bytes msg;
  const Bytes sig = base_signature(&msg);
  ASSERT_TRUE(mldsa65::verify(keys().public_key, msg, sig));
  const uint8_t* counts = sig.data() + kHintOffset + kOmega;
  const size_t total = counts[5];
  ASSERT_GT(total, 1u);

  // Find a polynomial with at least two hint indices.
  int poly = -1;
  size_t begin = 0;
  for (int i = 0; i < 6; ++i) {
    const size_t b = i == 0 ? 0 : counts[i - 1];
    if (counts[i] - b >= 2) {
      poly = i;
      begin = b;
      break;
    }
  }
  ASSERT_GE(poly, 0) << "base signature has no polynomial with two hints";
  {  // swapped indices: not strictly increasing
    Bytes s = sig;
    std::swap(s[kHintOffset + begin], s[kHintOffset + begin + 1]);
    EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, s));
  }
  {  // duplicate index
    Bytes s = sig;
    s[kHintOffset + begin + 1] = s[kHintOffset + begin];
    EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, s));
  }
  if (total < kOmega) {  // non-zero padding
    Bytes s = sig;
    s[kHintOffset + kOmega - 1] = 1;
    EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, s));
  }
  {  // last count above omega
    Bytes s = sig;
    s[kHintOffset + kOmega + 5] = kOmega + 1;
    EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, s));
    s[kHintOffset + kOmega + 5] = 255;
    EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, s));
  }
  {  // decreasing counts
    Bytes s = sig;
    s[kHintOffset + kOmega] = static_cast<uint8_t>(counts[1] + 1);
    EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, s));
  }
}

// Writes a 20-bit z coefficient (poly r, index n) encoded as gamma1 - value.
void set_z(Bytes& sig, int r, int n, int32_t value) {
  const uint32_t enc = static_cast<uint32_t>(kGamma1 - value);
  const size_t bit = static_cast<size_t>(r) * 640 * 8 + static_cast<size_t>(n) * 20;
  for (int b = 0; b < 20; ++b) {
    const size_t at = kZOffset + (bit + b) / 8;
    const uint8_t mask = static_cast<uint8_t>(1u << ((bit + b) % 8));
    if ((enc >> b) & 1) {
      sig[at] |= mask;
    } else {
      sig[at] &= static_cast<uint8_t>(~mask);
    }
  }
}

TEST_F(MlDsa65Signing, ZAtOrBeyondTheNormBoundIsRejected) {
  Bytes msg;
  const Bytes sig = base_signature(&msg);
  for (int32_t value : {kGamma1, -(kGamma1 - 1), kGamma1 - kBeta, -(kGamma1 - kBeta)}) {
    for (auto [r, n] : {std::pair{0, 0}, std::pair{2, 17}, std::pair{4, 255}}) {
      Bytes s = sig;
      set_z(s, r, n, value);
      EXPECT_FALSE(mldsa65::verify(keys().public_key, msg, s)) << value << " at " << r << "," << n;
    }
  }
}

TEST(MlDsa65, RandomKeysWorkAndDiffer) {
  auto a = mldsa65::keygen_random();
  auto b = mldsa65::keygen_random();
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_NE(a->public_key, b->public_key);
  auto sig = mldsa65::sign(a->secret_key, rcan::to_bytes("hi"));
  ASSERT_TRUE(sig.ok());
  EXPECT_TRUE(mldsa65::verify(a->public_key, rcan::to_bytes("hi"), *sig));
  EXPECT_FALSE(mldsa65::verify(b->public_key, rcan::to_bytes("hi"), *sig));
  EXPECT_EQ(mldsa65::kid(a->public_key).size(), 8u);
}

TEST(MlDsa65, CodePathsAgreeOnRandomInputs) {
  if (!internal::select_simd(true)) GTEST_SKIP() << "CPU without AVX2: only one code path";
  std::mt19937 rng(77);
  for (int i = 0; i < 20; ++i) {
    Bytes seed(32), msg(rng() % 100), rnd(32);
    for (auto& b : seed) b = static_cast<uint8_t>(rng());
    for (auto& b : msg) b = static_cast<uint8_t>(rng());
    for (auto& b : rnd) b = static_cast<uint8_t>(rng());
    internal::select_simd(false);
    auto kp0 = mldsa65::keygen_from_seed(seed);
    auto sig0 = mldsa65::sign_internal(kp0->secret_key, msg, rnd);
    internal::select_simd(true);
    auto kp1 = mldsa65::keygen_from_seed(seed);
    auto sig1 = mldsa65::sign_internal(kp1->secret_key, msg, rnd);
    ASSERT_TRUE(kp0.ok() && kp1.ok() && sig0.ok() && sig1.ok());
    EXPECT_EQ(kp0->public_key, kp1->public_key);
    EXPECT_EQ(kp0->secret_key, kp1->secret_key);
    EXPECT_EQ(*sig0, *sig1);
  }
}

TEST(MlDsa65, ManyRandomMessagesRoundTrip) {
  auto kp = mldsa65::keygen_from_seed(seed_of(7));
  ASSERT_TRUE(kp.ok());
  std::mt19937 rng(5);
  for (int i = 0; i < 200; ++i) {
    Bytes msg(rng() % 300);
    for (auto& b : msg) b = static_cast<uint8_t>(rng());
    mldsa65::SignOptions o;
    o.deterministic = (i % 2) == 0;
    auto sig = mldsa65::sign(kp->secret_key, msg, o);
    ASSERT_TRUE(sig.ok());
    ASSERT_TRUE(mldsa65::verify(kp->public_key, msg, *sig)) << i;
  }
}

// ---- cross-check with pyca/cryptography ------------------------------------------------

constexpr const char* kPyScript = R"PY(
import sys
try:
    from cryptography.hazmat.primitives.asymmetric import mldsa
    mldsa.MLDSA65PrivateKey.from_seed_bytes(bytes(32))
except Exception as e:
    print("SKIP " + type(e).__name__ + ": " + str(e).replace("\n", " "))
    sys.exit(0)
for line in sys.stdin.read().splitlines():
    seed, msg, ctx, sig = [bytes.fromhex(f[1:]) for f in line.split(" ")]
    key = mldsa.MLDSA65PrivateKey.from_seed_bytes(seed)
    pub = key.public_key()
    try:
        pub.verify(sig, msg, ctx)
        ok = "OK"
    except Exception:
        ok = "BAD"
    print(pub.public_bytes_raw().hex(), ok, key.sign(msg, ctx).hex())
)PY";

TEST(MlDsa65CrossCheck, PycaCryptography) {
  struct Case {
    Bytes seed, msg, ctx, sig;
  };
  std::vector<Case> cases;
  std::mt19937 rng(2024);
  for (int i = 0; i < 6; ++i) {
    Case c;
    c.seed = seed_of(static_cast<uint8_t>(17 * i));
    c.msg.resize(rng() % 200);
    for (auto& b : c.msg) b = static_cast<uint8_t>(rng());
    c.ctx.resize(i % 3 == 0 ? 0 : (i % 3 == 1 ? 4 : 255), static_cast<uint8_t>(i));
    auto kp = mldsa65::keygen_from_seed(c.seed);
    ASSERT_TRUE(kp.ok());
    mldsa65::SignOptions o;
    o.context = c.ctx;
    o.deterministic = (i % 2) == 1;
    auto sig = mldsa65::sign(kp->secret_key, c.msg, o);
    ASSERT_TRUE(sig.ok());
    c.sig = *sig;
    cases.push_back(std::move(c));
  }
  std::string input;
  for (const auto& c : cases) {
    for (const Bytes* field : {&c.seed, &c.msg, &c.ctx, &c.sig}) {
      input += field == &c.seed ? "x" : " x";
      input += rcan::to_hex(*field);
    }
    input += '\n';
  }
  auto r = rcan::test::run({"/usr/bin/env", "python3", "-c", kPyScript}, input);
  if (r.exit_code == 127) GTEST_SKIP() << "python3 not found on PATH";
  if (r.out.rfind("SKIP", 0) == 0) {
    GTEST_SKIP() << "pyca/cryptography lacks ML-DSA-65: " << r.out.substr(5);
  }
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::istringstream lines(r.out);
  std::string pk_hex, verdict, their_sig_hex;
  size_t i = 0;
  while (lines >> pk_hex >> verdict >> their_sig_hex) {
    ASSERT_LT(i, cases.size());
    const auto& c = cases[i];
    auto kp = mldsa65::keygen_from_seed(c.seed);
    ASSERT_TRUE(kp.ok());
    EXPECT_EQ(pk_hex, rcan::to_hex(kp->public_key)) << "case " << i;
    EXPECT_EQ(verdict, "OK") << "cryptography rejected our signature, case " << i;
    const Bytes theirs = hex(their_sig_hex);
    EXPECT_TRUE(mldsa65::verify(kp->public_key, c.msg, theirs, c.ctx)) << "case " << i;
    Bytes bad = theirs;
    bad[100] ^= 1;
    EXPECT_FALSE(mldsa65::verify(kp->public_key, c.msg, bad, c.ctx));
    ++i;
  }
  EXPECT_EQ(i, cases.size()) << r.out << r.err;
}

}  // namespace

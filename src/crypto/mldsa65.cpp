// ML-DSA-65 (FIPS 204), written from the standard on top of OpenSSL's SHAKE128/SHAKE256.
//
// Layout of this file:
//   1. parameters and modular arithmetic (Montgomery, Barrett-style reduce, NTT)
//   2. SHAKE through EVP (one reusable EVP_MD_CTX per operation)
//   3. samplers: RejNTTPoly/ExpandA, RejBoundedPoly/ExpandS, ExpandMask, SampleInBall
//   4. rounding: Power2Round, Decompose, MakeHint, UseHint
//   5. encodings: pk, sk, sig (BitPack/SimpleBitPack, HintBitPack)
//   6. KeyGen_internal, Sign_internal, Verify_internal and the public wrappers
//
// Side channels. All arithmetic on secret values (s1, s2, t0, y, w, c·s1, c·s2, c·t0, z
// before acceptance) is branch-free and indexes memory only by public loop counters:
// Montgomery/Barrett-style reductions use multiplications and arithmetic shifts, conditional
// corrections use sign masks, norm checks accumulate a flag over every coefficient. Where
// rejection sampling consumes secret-derived XOF output (ExpandS in key generation), the
// data-dependent part is only *which candidate nibbles are rejected*; rejected candidates are
// discarded and accepted coefficients are independent of that pattern, so timing reveals
// nothing about s1/s2. SampleInBall runs in constant time with respect to the positions it
// writes (the challenge of a rejected Sign iteration is never output and must stay secret).
// The Sign loop itself reveals the number of iterations — see sign_internal_impl().
#include "rcan/crypto/mldsa65.h"

#include <openssl/crypto.h>
#include <openssl/evp.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstring>
#include <memory>
#include <mutex>
#include <vector>

#include "crypto/mldsa65_internal.h"
#include "rcan/hash.h"

#if (defined(__x86_64__) || defined(__i386__)) && (defined(__GNUC__) || defined(__clang__))
#define RCAN_MLDSA_X86_DISPATCH 1
#else
#define RCAN_MLDSA_X86_DISPATCH 0
#endif
#if defined(__GNUC__) || defined(__clang__)
#define RCAN_MLDSA_INLINE [[gnu::always_inline]] inline
#else
#define RCAN_MLDSA_INLINE inline
#endif

namespace rcan::mldsa65 {

// ---------------------------------------------------------------------------------------
// 1. Parameters and arithmetic
// ---------------------------------------------------------------------------------------
namespace internal {
namespace {

constexpr int kK = 6;
constexpr int kL = 5;
constexpr int32_t kEta = 4;
constexpr int kTau = 49;
constexpr int32_t kBeta = 196;  // tau * eta
constexpr int kOmega = 55;
constexpr int32_t kGamma1 = 1 << 19;
constexpr int kD = 13;
constexpr size_t kCTildeBytes = 48;  // lambda / 4 with lambda = 192
constexpr size_t kTrBytes = 64;
constexpr size_t kMuBytes = 64;
constexpr size_t kPolyT1Bytes = 320;   // 256 · 10 bits
constexpr size_t kPolyEtaBytes = 128;  // 256 · 4 bits
constexpr size_t kPolyT0Bytes = 416;   // 256 · 13 bits
constexpr size_t kPolyZBytes = 640;    // 256 · 20 bits
constexpr size_t kPolyW1Bytes = 128;   // 256 · 4 bits
constexpr size_t kHintBytes = kOmega + kK;
constexpr size_t kSkS1Offset = 32 + 32 + kTrBytes;
constexpr size_t kSkS2Offset = kSkS1Offset + kL * kPolyEtaBytes;
constexpr size_t kSkT0Offset = kSkS2Offset + kK * kPolyEtaBytes;
constexpr size_t kSigZOffset = kCTildeBytes;
constexpr size_t kSigHintOffset = kSigZOffset + kL * kPolyZBytes;
static_assert(32 + kK * kPolyT1Bytes == kPublicKeyBytes);
static_assert(kSkT0Offset + kK * kPolyT0Bytes == kSecretKeyBytes);
static_assert(kSigHintOffset + kHintBytes == kSignatureBytes);
static_assert(kBeta == kTau * kEta);

constexpr size_t kShake128Rate = 168;
constexpr size_t kShake256Rate = 136;

// q^-1 mod 2^32 by Newton iteration (each step doubles the number of correct low bits).
constexpr uint32_t compute_qinv() {
  uint32_t x = static_cast<uint32_t>(kQ);  // correct to 3 bits since q is odd... q·q ≡ 1 mod 8
  for (int i = 0; i < 5; ++i) x *= 2u - static_cast<uint32_t>(kQ) * x;
  return x;
}
constexpr uint32_t kQInv = compute_qinv();
static_assert(static_cast<uint32_t>(kQ) * kQInv == 1u);

constexpr int64_t pow_mod(int64_t base, uint64_t e) {
  int64_t r = 1;
  base %= kQ;
  while (e) {
    if (e & 1) r = r * base % kQ;
    base = base * base % kQ;
    e >>= 1;
  }
  return r;
}
constexpr int32_t centered(int64_t x) {  // x in [0, q) to (-q/2, q/2]
  return static_cast<int32_t>(x > kQ / 2 ? x - kQ : x);
}
constexpr uint32_t bitrev8(uint32_t x) {
  uint32_t r = 0;
  for (int i = 0; i < 8; ++i) r |= ((x >> i) & 1u) << (7 - i);
  return r;
}

constexpr int64_t kMont = (int64_t{1} << 32) % kQ;  // 2^32 mod q
constexpr int64_t kZeta = 1753;                     // primitive 512-th root of unity mod q
static_assert(pow_mod(kZeta, 256) == kQ - 1);

// zetas[m] = zeta^brv8(m) · 2^32 mod q (Montgomery form), centered.
constexpr std::array<int32_t, 256> make_zetas() {
  std::array<int32_t, 256> z{};
  for (uint32_t m = 0; m < 256; ++m) z[m] = centered(pow_mod(kZeta, bitrev8(m)) * kMont % kQ);
  return z;
}
constexpr std::array<int32_t, 256> kZetas = make_zetas();
// The inverse NTT butterflies produce 256·NTT^-1(x); its input carries a factor 2^-32 from the
// Montgomery pointwise product. One Montgomery multiplication by 2^64/256 = 2^56 fixes both.
constexpr int32_t kInvNttScale = centered(pow_mod(2, 56));

RCAN_MLDSA_INLINE int32_t mont_reduce(int64_t a) {
  const int32_t t = static_cast<int32_t>(static_cast<uint32_t>(static_cast<uint64_t>(a)) * kQInv);
  return static_cast<int32_t>((a - static_cast<int64_t>(t) * kQ) >> 32);
}
// For |a| <= 2^31 - 2^22 - 1: r ≡ a (mod q) with |r| <= 6291456 < q.
RCAN_MLDSA_INLINE int32_t reduce32(int32_t a) {
  const int32_t t = (a + (1 << 22)) >> 23;
  return a - t * kQ;
}
// Adds q when negative (sign mask, no branch).
RCAN_MLDSA_INLINE int32_t caddq(int32_t a) { return a + ((a >> 31) & kQ); }
RCAN_MLDSA_INLINE int32_t freeze_impl(int32_t a) { return caddq(reduce32(a)); }
// [0, q) to the centered representative (-(q-1)/2, (q-1)/2].
RCAN_MLDSA_INLINE int32_t center(int32_t a) { return a - (((((kQ - 1) / 2) - a) >> 31) & kQ); }
RCAN_MLDSA_INLINE int32_t ct_abs(int32_t a) {
  const int32_t m = a >> 31;
  return (a ^ m) - m;
}
// All-ones when a >= bound (both non-negative), else 0.
RCAN_MLDSA_INLINE uint32_t ct_ge_mask(int32_t a, int32_t bound) {
  return static_cast<uint32_t>((bound - 1 - a) >> 31);
}

struct Poly {
  alignas(32) int32_t c[kN];
};

// FIPS 204 Alg. 41 with each layer instantiated for its compile-time half-length, so that
// the compiler can vectorise every layer (the short layers as interleaved groups) instead of
// only the ones with long inner loops. Layer `Len` uses zetas[128/Len + block].
template <size_t Len>
RCAN_MLDSA_INLINE void ntt_layer(int32_t* a) {
  for (size_t block = 0; block < 128 / Len; ++block) {
    const int64_t z = kZetas[128 / Len + block];
    int32_t* x = a + 2 * Len * block;
    for (size_t j = 0; j < Len; ++j) {
      const int32_t t = mont_reduce(z * x[j + Len]);
      x[j + Len] = x[j] - t;
      x[j] = x[j] + t;
    }
  }
}
RCAN_MLDSA_INLINE void ntt_impl(int32_t a[kN]) {
  ntt_layer<128>(a);
  ntt_layer<64>(a);
  ntt_layer<32>(a);
  ntt_layer<16>(a);
  ntt_layer<8>(a);
  ntt_layer<4>(a);
  ntt_layer<2>(a);
  ntt_layer<1>(a);
}

// FIPS 204 Alg. 42 walks the zetas backwards (m = 255 down to 1) with negated values; this
// table stores them in the order the blocks of each layer visit them:
// kInvZetas[128/Len + block] = -zetas[256/Len - 1 - block].
constexpr std::array<int32_t, 256> make_inv_zetas() {
  std::array<int32_t, 256> t{};
  for (size_t len = 1; len < 256; len <<= 1)
    for (size_t block = 0; block < 128 / len; ++block)
      t[128 / len + block] = -kZetas[256 / len - 1 - block];
  return t;
}
constexpr std::array<int32_t, 256> kInvZetas = make_inv_zetas();

template <size_t Len>
RCAN_MLDSA_INLINE void intt_layer(int32_t* a) {
  for (size_t block = 0; block < 128 / Len; ++block) {
    const int64_t z = kInvZetas[128 / Len + block];
    int32_t* x = a + 2 * Len * block;
    for (size_t j = 0; j < Len; ++j) {
      const int32_t t = x[j];
      x[j] = t + x[j + Len];
      x[j + Len] = mont_reduce(z * (t - x[j + Len]));
    }
  }
}
// Bounds: with |in| < q the "sum" lanes at most double per layer, so after 8 layers they stay
// below 256·q < 2^31; every "difference" lane is Montgomery-reduced back below q.
RCAN_MLDSA_INLINE void intt_impl(int32_t a[kN]) {
  intt_layer<1>(a);
  intt_layer<2>(a);
  intt_layer<4>(a);
  intt_layer<8>(a);
  intt_layer<16>(a);
  intt_layer<32>(a);
  intt_layer<64>(a);
  intt_layer<128>(a);
  for (size_t j = 0; j < kN; ++j) a[j] = mont_reduce(static_cast<int64_t>(kInvNttScale) * a[j]);
}

// out = Σ_j a[j] ∘ b[j] (NTT domain), one Montgomery reduction per coefficient.
// Caller guarantees Σ |a·b| < 2^31·q (e.g. a in [0,q), |b| < 9q, up to 5 terms: 45q^2).
template <size_t Count>
RCAN_MLDSA_INLINE void dot_montgomery(Poly& out, const Poly* const (&a)[Count], const Poly* b) {
  for (size_t n = 0; n < kN; ++n) {
    int64_t acc = 0;
    for (size_t j = 0; j < Count; ++j) acc += static_cast<int64_t>(a[j]->c[n]) * b[j].c[n];
    out.c[n] = mont_reduce(acc);
  }
}
RCAN_MLDSA_INLINE void mul_montgomery(Poly& out, const Poly& a, const Poly& b) {
  for (size_t n = 0; n < kN; ++n) out.c[n] = mont_reduce(static_cast<int64_t>(a.c[n]) * b.c[n]);
}

// ---------------------------------------------------------------------------------------
// 2. SHAKE via EVP
// ---------------------------------------------------------------------------------------
// Explicitly fetched once: passing EVP_shake128() to EVP_DigestInit_ex makes OpenSSL 3.0 do an
// implicit provider fetch on every init, which costs more than a Keccak permutation.
const EVP_MD* fetch_md(const char* name, const EVP_MD* fallback) {
  EVP_MD* md = EVP_MD_fetch(nullptr, name, nullptr);
  return md != nullptr ? md : fallback;
}
const EVP_MD* shake128_md() {
  static const EVP_MD* const md = fetch_md("SHAKE128", EVP_shake128());
  return md;
}
const EVP_MD* shake256_md() {
  static const EVP_MD* const md = fetch_md("SHAKE256", EVP_shake256());
  return md;
}

// One EVP_MD_CTX reused for every hash of an operation. OpenSSL 3.0 allows a single
// EVP_DigestFinalXOF per init, so each squeeze() asks for all the output at once. Any OpenSSL
// failure latches ok() to false and makes squeeze() return zeros (all samplers terminate on
// zeros); callers check ok() before releasing results.
class Shake {
 public:
  Shake() : ctx_(EVP_MD_CTX_new()), ok_(ctx_ != nullptr) {}
  ~Shake() { EVP_MD_CTX_free(ctx_); }
  Shake(const Shake&) = delete;
  Shake& operator=(const Shake&) = delete;

  void begin(const EVP_MD* md) {
    if (ok_ && EVP_DigestInit_ex(ctx_, md, nullptr) != 1) ok_ = false;
  }
  void absorb(const void* p, size_t n) {
    if (ok_ && n != 0 && EVP_DigestUpdate(ctx_, p, n) != 1) ok_ = false;
  }
  void absorb(std::span<const uint8_t> s) { absorb(s.data(), s.size()); }
  void squeeze(uint8_t* out, size_t n) {
    if (ok_ && EVP_DigestFinalXOF(ctx_, out, n) != 1) ok_ = false;
    if (!ok_) std::memset(out, 0, n);
  }
  bool ok() const { return ok_; }

 private:
  EVP_MD_CTX* ctx_;
  bool ok_;
};

// M' given as up to three pieces (0 ‖ |ctx| header, ctx, M) so it is never concatenated.
struct MessageParts {
  std::span<const uint8_t> parts[3];
};

// ---------------------------------------------------------------------------------------
// 3. Samplers
// ---------------------------------------------------------------------------------------
// RejNTTPoly (Alg. 30) over a byte stream: CoeffFromThreeBytes with the top bit cleared.
// Operates on public data (rho).
size_t parse_uniform(int32_t* a, size_t ctr, const uint8_t* buf, size_t len) {
  for (size_t pos = 0; ctr < kN && pos + 3 <= len; pos += 3) {
    const uint32_t t = static_cast<uint32_t>(buf[pos]) | static_cast<uint32_t>(buf[pos + 1]) << 8 |
                       static_cast<uint32_t>(buf[pos + 2] & 0x7f) << 16;
    if (t < static_cast<uint32_t>(kQ)) a[ctr++] = static_cast<int32_t>(t);
  }
  return ctr;
}

// Squeezes `first` bytes; in the rare case the sampler needs more, restarts the XOF and
// squeezes a longer stream (the shorter output is its prefix), parsing only the new tail.
// `first` and the increments are multiples of 3 so three-byte groups never straddle.
template <typename Parse>
void sample_with_fallback(Shake& x, const EVP_MD* md, std::span<const uint8_t> seed, uint8_t* buf,
                          size_t first, size_t step, int32_t* out, Parse parse) {
  x.begin(md);
  x.absorb(seed);
  x.squeeze(buf, first);
  size_t ctr = parse(out, 0, buf, first);
  size_t have = first;
  while (ctr < kN) {  // rare path (probability < 1e-5 per polynomial)
    const size_t want = have + step;
    std::vector<uint8_t> big(want);
    x.begin(md);
    x.absorb(seed);
    x.squeeze(big.data(), want);
    ctr = parse(out, ctr, big.data() + have, step);
    secure_wipe(big.data(), big.size());
    have = want;
  }
}

void expand_a_entry(Shake& x, Poly& out, const uint8_t rho[32], uint8_t row, uint8_t col) {
  uint8_t seed[34];
  std::memcpy(seed, rho, 32);
  seed[32] = col;  // ρ ‖ IntegerToBytes(s, 1) ‖ IntegerToBytes(r, 1)
  seed[33] = row;
  constexpr size_t kFirst = 5 * kShake128Rate;  // 280 candidates for 256 coefficients
  uint8_t buf[kFirst];
  sample_with_fallback(x, shake128_md(), seed, buf, kFirst, 3 * kShake128Rate, out.c,
                       parse_uniform);
}

// RejBoundedPoly (Alg. 31) for eta = 4: a nibble b < 9 becomes 4 - b, others are rejected.
// Branch-free: every candidate is written at the current position and the position advances
// by the acceptance bit, so neither timing nor branch prediction depends on the nibble values
// beyond the rejection pattern itself (see the file comment). The scratch buffer has room for
// the two candidates a byte can produce past the last needed slot.
size_t parse_eta(int32_t* a, size_t ctr, const uint8_t* buf, size_t len) {
  int32_t tmp[kN + 2];
  std::memcpy(tmp, a, ctr * sizeof(int32_t));
  for (size_t pos = 0; ctr < kN && pos < len; ++pos) {
    const uint32_t lo = buf[pos] & 0x0fu;
    const uint32_t hi = static_cast<uint32_t>(buf[pos]) >> 4;
    tmp[ctr] = kEta - static_cast<int32_t>(lo);
    ctr += (lo - 9u) >> 31;  // 1 iff lo < 9
    tmp[ctr] = kEta - static_cast<int32_t>(hi);
    ctr += (hi - 9u) >> 31;
  }
  if (ctr > kN) ctr = kN;  // the second nibble of the last byte may overshoot by one
  std::memcpy(a, tmp, ctr * sizeof(int32_t));
  secure_wipe(tmp, sizeof tmp);
  return ctr;
}

void expand_s_entry(Shake& x, Poly& out, const uint8_t rho_prime[64], uint16_t index) {
  uint8_t seed[66];
  std::memcpy(seed, rho_prime, 64);
  seed[64] = static_cast<uint8_t>(index);
  seed[65] = static_cast<uint8_t>(index >> 8);
  constexpr size_t kFirst = 2 * kShake256Rate;  // 544 candidates, ~306 accepted on average
  uint8_t buf[kFirst];
  sample_with_fallback(x, shake256_md(), seed, buf, kFirst, kShake256Rate, out.c, parse_eta);
  secure_wipe(buf, sizeof buf);
  secure_wipe(seed, sizeof seed);
}

// 20-bit little-endian bit stream helpers (BitPack / BitUnpack with a general width).
template <unsigned Bits, typename Get>
void pack_bits(uint8_t* out, Get get) {
  uint64_t acc = 0;
  unsigned n = 0;
  size_t o = 0;
  for (size_t i = 0; i < kN; ++i) {
    acc |= static_cast<uint64_t>(get(i)) << n;
    n += Bits;
    while (n >= 8) {
      out[o++] = static_cast<uint8_t>(acc);
      acc >>= 8;
      n -= 8;
    }
  }
}
template <unsigned Bits, typename Put>
void unpack_bits(const uint8_t* in, Put put) {
  uint64_t acc = 0;
  unsigned n = 0;
  size_t p = 0;
  for (size_t i = 0; i < kN; ++i) {
    while (n < Bits) {
      acc |= static_cast<uint64_t>(in[p++]) << n;
      n += 8;
    }
    put(i, static_cast<uint32_t>(acc & ((uint64_t{1} << Bits) - 1)));
    acc >>= Bits;
    n -= Bits;
  }
}

// BitUnpack(·, γ1-1, γ1): two 20-bit fields per 5 bytes, value γ1 - field.
RCAN_MLDSA_INLINE void unpack_z20(Poly& z, const uint8_t* in) {
  for (size_t i = 0; i < kN / 2; ++i) {
    const uint8_t* b = in + 5 * i;
    const uint32_t f0 =
        b[0] | static_cast<uint32_t>(b[1]) << 8 | static_cast<uint32_t>(b[2] & 0x0f) << 16;
    const uint32_t f1 = static_cast<uint32_t>(b[2]) >> 4 | static_cast<uint32_t>(b[3]) << 4 |
                        static_cast<uint32_t>(b[4]) << 12;
    z.c[2 * i] = kGamma1 - static_cast<int32_t>(f0);
    z.c[2 * i + 1] = kGamma1 - static_cast<int32_t>(f1);
  }
}

// ExpandMask (Alg. 34), one polynomial: y = γ1 - BitUnpack20(H(ρ'' ‖ IntegerToBytes(κ, 2), 640)).
void expand_mask_entry(Shake& x, Poly& out, const uint8_t rho_pp[64], uint16_t kappa) {
  uint8_t seed[66];
  std::memcpy(seed, rho_pp, 64);
  seed[64] = static_cast<uint8_t>(kappa);
  seed[65] = static_cast<uint8_t>(kappa >> 8);
  uint8_t buf[kPolyZBytes];
  x.begin(shake256_md());
  x.absorb(seed, sizeof seed);
  x.squeeze(buf, sizeof buf);
  unpack_z20(out, buf);
  secure_wipe(buf, sizeof buf);
  secure_wipe(seed, sizeof seed);
}

// SampleInBall (Alg. 29). The byte-rejection loop (j > i) only discards candidates; the swap
// c_i = c_j, c_j = ±1 touches every position 0..i with masks, so memory access does not depend
// on j. The sign bits come from the first 8 bytes, bit (i + τ - 256) for position i.
RCAN_MLDSA_INLINE void sample_in_ball(Shake& x, Poly& c, const uint8_t* ctilde) {
  constexpr size_t kFirst = kShake256Rate;
  uint8_t buf[kFirst];
  x.begin(shake256_md());
  x.absorb(ctilde, kCTildeBytes);
  x.squeeze(buf, kFirst);
  std::vector<uint8_t> big;  // only for the (never observed) case of > 128 candidate bytes
  const uint8_t* stream = buf;
  size_t have = kFirst;
  uint64_t signs = 0;
  for (int i = 0; i < 8; ++i) signs |= static_cast<uint64_t>(buf[i]) << (8 * i);
  size_t pos = 8;
  std::memset(c.c, 0, sizeof c.c);
  for (uint32_t i = kN - kTau; i < kN; ++i) {
    uint32_t j;
    do {
      if (pos >= have) {
        big.resize(have + kShake256Rate);
        x.begin(shake256_md());
        x.absorb(ctilde, kCTildeBytes);
        x.squeeze(big.data(), big.size());
        have = big.size();
        stream = big.data();
      }
      j = stream[pos++];
    } while (j > i);
    const int32_t s = 1 - 2 * static_cast<int32_t>(signs & 1);
    signs >>= 1;
    // One masked pass: read the old c_j and write ±1 at j. Position i is still 0 before this
    // step, so afterwards c_i = (j == i) ? s : old c_j.
    int32_t cj = 0;
    for (uint32_t k = 0; k < i; ++k) {
      const int32_t eq = -static_cast<int32_t>(((k ^ j) - 1u) >> 31);
      cj |= c.c[k] & eq;
      c.c[k] = (c.c[k] & ~eq) | (s & eq);
    }
    const int32_t j_is_i = -static_cast<int32_t>(((i ^ j) - 1u) >> 31);
    c.c[i] = (cj & ~j_is_i) | (s & j_is_i);
  }
  secure_wipe(buf, sizeof buf);
}

// ---------------------------------------------------------------------------------------
// 4. Rounding
// ---------------------------------------------------------------------------------------
// Power2Round (Alg. 35) for a in [0, q): a = r1·2^13 + r0, r0 in (-2^12, 2^12].
RCAN_MLDSA_INLINE void power2round(int32_t a, int32_t* r1, int32_t* r0) {
  *r1 = (a + (1 << (kD - 1)) - 1) >> kD;
  *r0 = a - (*r1 << kD);
}

// Decompose (Alg. 36) for a in [0, q), γ2 = (q-1)/32, 2γ2 = 523776 = 2^9·1023.
// r1 = floor((a + γ2 - 1) / 2γ2) computed as ((a + γ2 - 1) >> 9) / 1023 with the division
// replaced by a multiply-shift (exact for the < 2^15 range involved; checked exhaustively in
// the unit tests), so it is constant time on every compiler and optimisation level.
// When r1 = 16 (a > q-1-γ2) the standard folds it to r1 = 0 and r0 - 1.
RCAN_MLDSA_INLINE void decompose_impl(int32_t a, int32_t* r1, int32_t* r0) {
  const uint32_t t = static_cast<uint32_t>(a + kGamma2 - 1) >> 9;
  int32_t h = static_cast<int32_t>((static_cast<uint64_t>(t) * 4198405u) >> 32);  // t / 1023
  int32_t l = a - h * 2 * kGamma2;
  const int32_t wrap = -(h >> 4);  // -1 iff h == 16
  h &= 15;
  l += wrap;
  *r1 = h;
  *r0 = l;
}
RCAN_MLDSA_INLINE int32_t high_bits(int32_t a) {
  int32_t r1, r0;
  decompose_impl(a, &r1, &r0);
  return r1;
}

RCAN_MLDSA_INLINE int32_t use_hint_impl(int32_t a, uint32_t h) {
  int32_t r1, r0;
  decompose_impl(a, &r1, &r0);
  // delta = +1 if r0 > 0, -1 otherwise; applied only when h = 1.
  const int32_t positive = static_cast<int32_t>(static_cast<uint32_t>(-r0) >> 31);  // r0 > 0
  const int32_t delta = (2 * positive - 1) * static_cast<int32_t>(h);
  return (r1 + delta) & 15;
}

// ---------------------------------------------------------------------------------------
// 5. Encodings
// ---------------------------------------------------------------------------------------
void pack_t1(uint8_t* out, const Poly& t1) {
  pack_bits<10>(out, [&](size_t i) { return static_cast<uint32_t>(t1.c[i]); });
}
void unpack_t1(Poly& t1, const uint8_t* in) {
  unpack_bits<10>(in, [&](size_t i, uint32_t v) { t1.c[i] = static_cast<int32_t>(v); });
}
void pack_eta(uint8_t* out, const Poly& s) {
  pack_bits<4>(out, [&](size_t i) { return static_cast<uint32_t>(kEta - s.c[i]); });
}
void unpack_eta(Poly& s, const uint8_t* in) {
  unpack_bits<4>(in, [&](size_t i, uint32_t v) { s.c[i] = kEta - static_cast<int32_t>(v); });
}
void pack_t0(uint8_t* out, const Poly& t0) {
  pack_bits<13>(out, [&](size_t i) { return static_cast<uint32_t>((1 << (kD - 1)) - t0.c[i]); });
}
void unpack_t0(Poly& t0, const uint8_t* in) {
  unpack_bits<13>(
      in, [&](size_t i, uint32_t v) { t0.c[i] = (1 << (kD - 1)) - static_cast<int32_t>(v); });
}
void pack_z(uint8_t* out, const Poly& z) {
  pack_bits<20>(out, [&](size_t i) { return static_cast<uint32_t>(kGamma1 - z.c[i]); });
}
void unpack_z(Poly& z, const uint8_t* in) { unpack_z20(z, in); }
// w1Encode for one polynomial: two 4-bit values per byte, low nibble first.
RCAN_MLDSA_INLINE void pack_w1(uint8_t* out, const Poly& w1) {
  for (size_t i = 0; i < kN / 2; ++i) {
    out[i] = static_cast<uint8_t>(w1.c[2 * i] | (w1.c[2 * i + 1] << 4));
  }
}

// HintBitUnpack (Alg. 21) with every malformation rejected: a count that decreases or exceeds
// ω, indices that are not strictly increasing within a polynomial (this also rejects
// duplicates), and non-zero bytes in the unused index slots.
bool unpack_hint(uint8_t h[kK][kN], const uint8_t* y) {
  std::memset(h, 0, kK * kN);
  size_t index = 0;
  for (int i = 0; i < kK; ++i) {
    const size_t end = y[kOmega + i];
    if (end < index || end > static_cast<size_t>(kOmega)) return false;
    const size_t first = index;
    for (; index < end; ++index) {
      if (index > first && y[index - 1] >= y[index]) return false;
      h[i][y[index]] = 1;
    }
  }
  for (; index < static_cast<size_t>(kOmega); ++index) {
    if (y[index] != 0) return false;
  }
  return true;
}

// ---------------------------------------------------------------------------------------
// 6. The algorithms
// ---------------------------------------------------------------------------------------
void hash_mu(Shake& x, uint8_t mu[kMuBytes], const uint8_t tr[kTrBytes], const MessageParts& m) {
  x.begin(shake256_md());
  x.absorb(tr, kTrBytes);
  for (const auto& p : m.parts) x.absorb(p);
  x.squeeze(mu, kMuBytes);
}

// Secret intermediate state of KeyGen, wiped on exit.
struct KeygenSecrets {
  uint8_t expanded[128];  // ρ ‖ ρ' ‖ K
  Poly s1[kL];
  Poly s1_hat[kL];
  Poly s2[kK];
  Poly t0[kK];
  Poly acc;
};

RCAN_MLDSA_INLINE bool keygen_body(const uint8_t xi[32], uint8_t pk[kPublicKeyBytes],
                                   uint8_t sk[kSecretKeyBytes]) {
  Shake x;
  KeygenSecrets sec;
  Poly a_entry, t1;

  uint8_t seed_in[34];
  std::memcpy(seed_in, xi, 32);
  seed_in[32] = kK;
  seed_in[33] = kL;
  x.begin(shake256_md());
  x.absorb(seed_in, sizeof seed_in);
  x.squeeze(sec.expanded, sizeof sec.expanded);
  secure_wipe(seed_in, sizeof seed_in);
  const uint8_t* rho = sec.expanded;
  const uint8_t* rho_prime = sec.expanded + 32;
  const uint8_t* key = sec.expanded + 96;

  for (int r = 0; r < kL; ++r) expand_s_entry(x, sec.s1[r], rho_prime, static_cast<uint16_t>(r));
  for (int r = 0; r < kK; ++r)
    expand_s_entry(x, sec.s2[r], rho_prime, static_cast<uint16_t>(r + kL));
  for (int r = 0; r < kL; ++r) {
    sec.s1_hat[r] = sec.s1[r];
    ntt_impl(sec.s1_hat[r].c);
  }

  std::memcpy(pk, rho, 32);
  for (int i = 0; i < kK; ++i) {
    // t_i = NTT^-1(Σ_j A[i][j] ∘ ŝ1[j]) + s2_i, A generated row by row (never stored whole).
    int64_t acc[kN] = {};
    for (int j = 0; j < kL; ++j) {
      expand_a_entry(x, a_entry, rho, static_cast<uint8_t>(i), static_cast<uint8_t>(j));
      for (size_t n = 0; n < kN; ++n)
        acc[n] += static_cast<int64_t>(a_entry.c[n]) * sec.s1_hat[j].c[n];
    }
    for (size_t n = 0; n < kN; ++n) sec.acc.c[n] = mont_reduce(acc[n]);
    secure_wipe(acc, sizeof acc);
    intt_impl(sec.acc.c);
    for (size_t n = 0; n < kN; ++n) {
      const int32_t t = freeze_impl(sec.acc.c[n] + sec.s2[i].c[n]);
      power2round(t, &t1.c[n], &sec.t0[i].c[n]);
    }
    pack_t1(pk + 32 + i * kPolyT1Bytes, t1);
  }

  std::memcpy(sk, rho, 32);
  std::memcpy(sk + 32, key, 32);
  x.begin(shake256_md());
  x.absorb(pk, kPublicKeyBytes);
  x.squeeze(sk + 64, kTrBytes);
  for (int r = 0; r < kL; ++r) pack_eta(sk + kSkS1Offset + r * kPolyEtaBytes, sec.s1[r]);
  for (int r = 0; r < kK; ++r) pack_eta(sk + kSkS2Offset + r * kPolyEtaBytes, sec.s2[r]);
  for (int r = 0; r < kK; ++r) pack_t0(sk + kSkT0Offset + r * kPolyT0Bytes, sec.t0[r]);
  secure_wipe(&sec, sizeof sec);
  return x.ok();
}

// Secret intermediate state of Sign, wiped on exit.
struct SignSecrets {
  uint8_t key[32];
  uint8_t rho_pp[64];  // ρ''
  Poly s1_hat[kL];
  Poly s2_hat[kK];
  Poly t0_hat[kK];
  Poly y[kL];
  Poly y_hat[kL];
  Poly w[kK];  // A·y in [0, q)
  Poly z[kL];
  Poly c_hat;
  Poly tmp;
  Poly ct0;
  uint8_t hint[kK][kN];
};

enum class SignStatus { kOk, kHashFailure, kIterationLimit };

// Sign_internal (Alg. 7). The loop below is FIPS 204's rejection sampling: an iteration is
// rejected when ||z||∞ ≥ γ1-β, ||r0||∞ ≥ γ2-β, ||c·t0||∞ ≥ γ2 or the hint has more than ω
// ones. Each candidate is computed with constant-time arithmetic and the norm checks scan all
// coefficients; the only secret-dependent control flow is the accept/reject decision itself,
// so timing reveals the number of iterations (κ/ℓ) and nothing else — which is what FIPS 204
// (and every implementation of it) leaks by design, since the rejected candidates are
// independent of the accepted signature. Rejected z, h and c are never output.
RCAN_MLDSA_INLINE SignStatus sign_body(const uint8_t* sk, const MessageParts& m_prime,
                                       const uint8_t rnd[32], uint8_t sig[kSignatureBytes]) {
  Shake x;
  SignSecrets sec;
  Poly a[kK][kL];
  Poly c;
  Poly w1;
  uint8_t mu[kMuBytes];
  uint8_t w1_packed[kK * kPolyW1Bytes];

  const uint8_t* rho = sk;
  std::memcpy(sec.key, sk + 32, 32);
  const uint8_t* tr = sk + 64;
  for (int r = 0; r < kL; ++r) {
    unpack_eta(sec.s1_hat[r], sk + kSkS1Offset + r * kPolyEtaBytes);
    ntt_impl(sec.s1_hat[r].c);
  }
  for (int r = 0; r < kK; ++r) {
    unpack_eta(sec.s2_hat[r], sk + kSkS2Offset + r * kPolyEtaBytes);
    ntt_impl(sec.s2_hat[r].c);
    unpack_t0(sec.t0_hat[r], sk + kSkT0Offset + r * kPolyT0Bytes);
    ntt_impl(sec.t0_hat[r].c);
  }
  for (int i = 0; i < kK; ++i)
    for (int j = 0; j < kL; ++j)
      expand_a_entry(x, a[i][j], rho, static_cast<uint8_t>(i), static_cast<uint8_t>(j));

  hash_mu(x, mu, tr, m_prime);
  x.begin(shake256_md());
  x.absorb(sec.key, 32);
  x.absorb(rnd, 32);
  x.absorb(mu, kMuBytes);
  x.squeeze(sec.rho_pp, sizeof sec.rho_pp);

  SignStatus status = SignStatus::kIterationLimit;
  // FIPS 204 allows an implementation-chosen loop limit well above the expected ~5 iterations;
  // 1000 iterations of ℓ = 5 keep κ below 2^16.
  for (uint32_t kappa = 0; kappa < 1000u * kL; kappa += kL) {
    if (!x.ok()) {
      status = SignStatus::kHashFailure;
      break;
    }
    for (int r = 0; r < kL; ++r) {
      expand_mask_entry(x, sec.y[r], sec.rho_pp, static_cast<uint16_t>(kappa + r));
      sec.y_hat[r] = sec.y[r];
      ntt_impl(sec.y_hat[r].c);
    }
    for (int i = 0; i < kK; ++i) {
      const Poly* row[kL] = {&a[i][0], &a[i][1], &a[i][2], &a[i][3], &a[i][4]};
      dot_montgomery<kL>(sec.w[i], row, sec.y_hat);
      intt_impl(sec.w[i].c);
      for (size_t n = 0; n < kN; ++n) {
        sec.w[i].c[n] = caddq(sec.w[i].c[n]);
        w1.c[n] = high_bits(sec.w[i].c[n]);
      }
      pack_w1(w1_packed + i * kPolyW1Bytes, w1);
    }
    x.begin(shake256_md());
    x.absorb(mu, kMuBytes);
    x.absorb(w1_packed, sizeof w1_packed);
    x.squeeze(sig, kCTildeBytes);  // c~, kept only if this iteration is accepted
    sample_in_ball(x, c, sig);
    sec.c_hat = c;
    ntt_impl(sec.c_hat.c);

    uint32_t reject = 0;
    // z = y + c·s1 (exact integers; |c·s1| ≤ β), require ||z||∞ < γ1 - β.
    for (int r = 0; r < kL; ++r) {
      mul_montgomery(sec.tmp, sec.c_hat, sec.s1_hat[r]);
      intt_impl(sec.tmp.c);
      for (size_t n = 0; n < kN; ++n) {
        const int32_t zc = sec.y[r].c[n] + center(caddq(sec.tmp.c[n]));
        sec.z[r].c[n] = zc;
        reject |= ct_ge_mask(ct_abs(zc), kGamma1 - kBeta);
      }
    }
    // r = w - c·s2 in [0, q): require ||LowBits(r)||∞ < γ2 - β and ||c·t0||∞ < γ2; the hint
    // marks where HighBits(r + c·t0) ≠ HighBits(r), i.e. MakeHint(-c·t0, w - c·s2 + c·t0).
    int32_t ones = 0;
    for (int i = 0; i < kK; ++i) {
      mul_montgomery(sec.tmp, sec.c_hat, sec.s2_hat[i]);
      intt_impl(sec.tmp.c);
      Poly& r = sec.tmp;  // r = w - c·s2 mod q, in place
      for (size_t n = 0; n < kN; ++n) r.c[n] = freeze_impl(sec.w[i].c[n] - caddq(r.c[n]));
      for (size_t n = 0; n < kN; ++n) {
        int32_t r1, r0;
        decompose_impl(r.c[n], &r1, &r0);
        reject |= ct_ge_mask(ct_abs(r0), kGamma2 - kBeta);
        sec.w[i].c[n] = r1;  // w_i is not needed any more: keep HighBits(r) there
      }
      mul_montgomery(sec.ct0, sec.c_hat, sec.t0_hat[i]);
      intt_impl(sec.ct0.c);
      for (size_t n = 0; n < kN; ++n) {
        const int32_t ct0 = center(caddq(sec.ct0.c[n]));
        reject |= ct_ge_mask(ct_abs(ct0), kGamma2);
        const int32_t moved = high_bits(freeze_impl(r.c[n] + ct0));
        const uint32_t diff = static_cast<uint32_t>(moved ^ sec.w[i].c[n]);
        const uint32_t bit = (diff | (0u - diff)) >> 31;  // 1 iff the high bits differ
        sec.hint[i][n] = static_cast<uint8_t>(bit);
        ones += static_cast<int32_t>(bit);
      }
    }
    reject |= ct_ge_mask(ones, kOmega + 1);
    if (reject != 0) continue;  // the permitted leak: this iteration was rejected

    // Accepted: sig = c~ ‖ BitPack(z, γ1-1, γ1) ‖ HintBitPack(h). z and h are now public.
    for (int r = 0; r < kL; ++r) pack_z(sig + kSigZOffset + r * kPolyZBytes, sec.z[r]);
    uint8_t* y = sig + kSigHintOffset;
    std::memset(y, 0, kHintBytes);
    size_t index = 0;
    for (int i = 0; i < kK; ++i) {
      for (size_t n = 0; n < kN; ++n) {
        if (sec.hint[i][n] != 0) y[index++] = static_cast<uint8_t>(n);
      }
      y[kOmega + i] = static_cast<uint8_t>(index);
    }
    status = x.ok() ? SignStatus::kOk : SignStatus::kHashFailure;
    break;
  }
  secure_wipe(&sec, sizeof sec);
  secure_wipe(&c, sizeof c);
  secure_wipe(w1_packed, sizeof w1_packed);
  secure_wipe(&w1, sizeof w1);
  if (status != SignStatus::kOk) secure_wipe(sig, kSignatureBytes);
  return status;
}

// Verify_internal (Alg. 8). All inputs are public; lengths are checked by the caller.
// The public-key half of Verify_internal, which depends on pk alone: tr = H(pk), Â =
// ExpandA(ρ) and NTT(t1 · 2^d). It is computed once per key and cached (see
// prepared_key()), so a robot verifying a stream of messages from the same signer does not
// re-sample the 30 polynomials of Â for every message. Everything here is public data.
struct PreparedKey {
  std::array<uint8_t, kPublicKeyBytes> pk;
  uint8_t tr[kTrBytes];
  Poly a_hat[kK][kL];
  Poly t1_hat[kK];
  bool ok = false;
};

RCAN_MLDSA_INLINE void prepare_body(const uint8_t* pk, PreparedKey& k) {
  std::memcpy(k.pk.data(), pk, kPublicKeyBytes);
  Shake x;
  x.begin(shake256_md());
  x.absorb(pk, kPublicKeyBytes);
  x.squeeze(k.tr, sizeof k.tr);
  for (int i = 0; i < kK; ++i) {
    for (int j = 0; j < kL; ++j)
      expand_a_entry(x, k.a_hat[i][j], pk, static_cast<uint8_t>(i), static_cast<uint8_t>(j));
    unpack_t1(k.t1_hat[i], pk + 32 + i * kPolyT1Bytes);
    for (size_t n = 0; n < kN; ++n) k.t1_hat[i].c[n] <<= kD;
    ntt_impl(k.t1_hat[i].c);
  }
  k.ok = x.ok();
}

RCAN_MLDSA_INLINE bool verify_body(const PreparedKey& k, const MessageParts& m_prime,
                                   const uint8_t* sig) {
  uint8_t hint[kK][kN];
  if (!unpack_hint(hint, sig + kSigHintOffset)) return false;
  Poly z_hat[kL];
  uint32_t too_big = 0;
  for (int r = 0; r < kL; ++r) {
    unpack_z(z_hat[r], sig + kSigZOffset + r * kPolyZBytes);
    for (size_t n = 0; n < kN; ++n) too_big |= ct_ge_mask(ct_abs(z_hat[r].c[n]), kGamma1 - kBeta);
  }
  if (too_big != 0) return false;  // ||z||∞ must be < γ1 - β
  for (int r = 0; r < kL; ++r) ntt_impl(z_hat[r].c);

  Shake x;
  uint8_t mu[kMuBytes];
  hash_mu(x, mu, k.tr, m_prime);

  Poly c_hat;
  sample_in_ball(x, c_hat, sig);
  ntt_impl(c_hat.c);

  Poly w;
  uint8_t w1_packed[kK * kPolyW1Bytes];
  for (int i = 0; i < kK; ++i) {
    // w'_i = NTT^-1(Σ_j A[i][j] ∘ ẑ_j - ĉ ∘ NTT(t1_i · 2^d)); the single Montgomery reduction
    // is safe: 5 terms below 9q^2 plus one below 81q^2 stay under 2^31·q.
    int64_t acc[kN];
    for (size_t n = 0; n < kN; ++n) acc[n] = -static_cast<int64_t>(c_hat.c[n]) * k.t1_hat[i].c[n];
    for (int j = 0; j < kL; ++j)
      for (size_t n = 0; n < kN; ++n)
        acc[n] += static_cast<int64_t>(k.a_hat[i][j].c[n]) * z_hat[j].c[n];
    for (size_t n = 0; n < kN; ++n) w.c[n] = mont_reduce(acc[n]);
    intt_impl(w.c);
    for (size_t n = 0; n < kN; ++n) w.c[n] = use_hint_impl(caddq(w.c[n]), hint[i][n]);
    pack_w1(w1_packed + i * kPolyW1Bytes, w);
  }
  uint8_t c_tilde[kCTildeBytes];
  x.begin(shake256_md());
  x.absorb(mu, kMuBytes);
  x.absorb(w1_packed, sizeof w1_packed);
  x.squeeze(c_tilde, sizeof c_tilde);
  return x.ok() && CRYPTO_memcmp(c_tilde, sig, kCTildeBytes) == 0;
}

// ---------------------------------------------------------------------------------------
// 7. Code generation variants
// ---------------------------------------------------------------------------------------
// The algorithm bodies and every arithmetic kernel are force-inlined into two entry points
// each: one compiled for the baseline ISA and one compiled with AVX2 enabled, where the
// compiler vectorises the NTT butterflies, the Montgomery products and the rounding loops
// (all written as straight-line lane-wise code). The same C++ source, hence the same
// constant-time properties, backs both; the choice is made once from CPUID.
bool keygen_generic(const uint8_t* xi, uint8_t* pk, uint8_t* sk) { return keygen_body(xi, pk, sk); }
SignStatus sign_generic(const uint8_t* sk, const MessageParts& m, const uint8_t* rnd,
                        uint8_t* sig) {
  return sign_body(sk, m, rnd, sig);
}
bool verify_generic(const PreparedKey& k, const MessageParts& m, const uint8_t* sig) {
  return verify_body(k, m, sig);
}
void prepare_generic(const uint8_t* pk, PreparedKey& k) { prepare_body(pk, k); }
#if RCAN_MLDSA_X86_DISPATCH
[[gnu::target("avx2")]] bool keygen_avx2(const uint8_t* xi, uint8_t* pk, uint8_t* sk) {
  return keygen_body(xi, pk, sk);
}
[[gnu::target("avx2")]] SignStatus sign_avx2(const uint8_t* sk, const MessageParts& m,
                                             const uint8_t* rnd, uint8_t* sig) {
  return sign_body(sk, m, rnd, sig);
}
[[gnu::target("avx2")]] bool verify_avx2(const PreparedKey& k, const MessageParts& m,
                                         const uint8_t* sig) {
  return verify_body(k, m, sig);
}
[[gnu::target("avx2")]] void prepare_avx2(const uint8_t* pk, PreparedKey& k) {
  prepare_body(pk, k);
}
bool cpu_has_avx2() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") != 0;
}
std::atomic<bool>& avx2_enabled() {
  static std::atomic<bool> enabled{cpu_has_avx2()};
  return enabled;
}
bool use_avx2() { return avx2_enabled().load(std::memory_order_relaxed); }
#else
bool use_avx2() { return false; }
#endif

bool keygen_internal(const uint8_t* xi, uint8_t* pk, uint8_t* sk) {
#if RCAN_MLDSA_X86_DISPATCH
  if (use_avx2()) return keygen_avx2(xi, pk, sk);
#endif
  return keygen_generic(xi, pk, sk);
}
SignStatus sign_internal_impl(const uint8_t* sk, const MessageParts& m, const uint8_t* rnd,
                              uint8_t* sig) {
#if RCAN_MLDSA_X86_DISPATCH
  if (use_avx2()) return sign_avx2(sk, m, rnd, sig);
#endif
  return sign_generic(sk, m, rnd, sig);
}
std::shared_ptr<const PreparedKey> prepare(const uint8_t* pk) {
  auto k = std::make_shared<PreparedKey>();
#if RCAN_MLDSA_X86_DISPATCH
  if (use_avx2()) {
    prepare_avx2(pk, *k);
    return k;
  }
#endif
  prepare_generic(pk, *k);
  return k;
}

// A small most-recently-used cache of prepared public keys (about 37 KiB each). A node
// verifies messages from a handful of signers; an unknown key costs one preparation, as
// verification without the cache would.
constexpr size_t kPreparedCacheSize = 8;
std::shared_ptr<const PreparedKey> prepared_key(const uint8_t* pk) {
  static std::mutex mu;
  static std::vector<std::shared_ptr<const PreparedKey>> cache;  // most recent first
  {
    std::lock_guard<std::mutex> lock(mu);
    for (size_t i = 0; i < cache.size(); ++i) {
      if (std::memcmp(cache[i]->pk.data(), pk, kPublicKeyBytes) == 0) {
        const auto at = cache.begin() + static_cast<std::ptrdiff_t>(i);
        std::rotate(cache.begin(), at, at + 1);
        return cache.front();
      }
    }
  }
  auto k = prepare(pk);
  if (!k->ok) return k;  // never cache a failed preparation
  std::lock_guard<std::mutex> lock(mu);
  if (cache.size() < kPreparedCacheSize)
    cache.push_back(k);
  else
    cache.back() = k;
  std::rotate(cache.begin(), cache.end() - 1, cache.end());
  return k;
}

bool verify_internal_impl(const uint8_t* pk, const MessageParts& m, const uint8_t* sig) {
  auto k = prepared_key(pk);
  if (!k->ok) return false;
#if RCAN_MLDSA_X86_DISPATCH
  if (use_avx2()) return verify_avx2(*k, m, sig);
#endif
  return verify_generic(*k, m, sig);
}

}  // namespace

int32_t montgomery_reduce(int64_t a) { return mont_reduce(a); }
void ntt(int32_t a[kN]) { ntt_impl(a); }
void intt_from_montgomery(int32_t a[kN]) { intt_impl(a); }
int32_t pointwise_montgomery(int32_t a, int32_t b) {
  return mont_reduce(static_cast<int64_t>(a) * b);
}
void decompose(int32_t a, int32_t* r1, int32_t* r0) { decompose_impl(a, r1, r0); }
int32_t use_hint(int32_t a, uint32_t h) { return use_hint_impl(a, h); }
int32_t freeze(int32_t a) { return freeze_impl(a); }
bool select_simd(bool allow) {
#if RCAN_MLDSA_X86_DISPATCH
  avx2_enabled().store(allow && cpu_has_avx2(), std::memory_order_relaxed);
#else
  (void)allow;
#endif
  return use_avx2();
}

}  // namespace internal

// ---------------------------------------------------------------------------------------
// Public API
// ---------------------------------------------------------------------------------------
KeyPair::~KeyPair() { secure_wipe(secret_key.data(), secret_key.size()); }

Result<KeyPair> keygen_from_seed(std::span<const uint8_t> seed) {
  if (seed.size() != kSeedBytes) {
    return Error(ErrorCode::kInternal, "ML-DSA-65 seed must be 32 bytes", "seed");
  }
  KeyPair kp;
  kp.public_key.resize(kPublicKeyBytes);
  kp.secret_key.resize(kSecretKeyBytes);
  if (!internal::keygen_internal(seed.data(), kp.public_key.data(), kp.secret_key.data())) {
    return Error(ErrorCode::kInternal, "ML-DSA-65 key generation failed (SHAKE unavailable)");
  }
  return kp;
}

Result<KeyPair> keygen_random() {
  uint8_t seed[kSeedBytes];
  if (!random_bytes(seed, sizeof seed)) {
    return Error(ErrorCode::kInternal, "random number generator failure");
  }
  auto kp = keygen_from_seed(seed);
  secure_wipe(seed, sizeof seed);
  return kp;
}

namespace {
Result<Bytes> run_sign(std::span<const uint8_t> secret_key, const internal::MessageParts& m_prime,
                       const uint8_t rnd[32]) {
  if (secret_key.size() != kSecretKeyBytes) {
    return Error(ErrorCode::kInternal, "ML-DSA-65 secret key must be 4032 bytes", "secret_key");
  }
  Bytes sig(kSignatureBytes);
  switch (internal::sign_internal_impl(secret_key.data(), m_prime, rnd, sig.data())) {
    case internal::SignStatus::kOk:
      return sig;
    case internal::SignStatus::kHashFailure:
      return Error(ErrorCode::kInternal, "ML-DSA-65 signing failed (SHAKE unavailable)");
    case internal::SignStatus::kIterationLimit:
      break;
  }
  return Error(ErrorCode::kInternal, "ML-DSA-65 signing exceeded its iteration limit");
}
}  // namespace

Result<Bytes> sign(std::span<const uint8_t> secret_key, std::span<const uint8_t> message,
                   const SignOptions& opts) {
  if (opts.context.size() > kMaxContextBytes) {
    return Error(ErrorCode::kInternal, "ML-DSA-65 context must be at most 255 bytes", "context");
  }
  if (secret_key.size() != kSecretKeyBytes) {
    return Error(ErrorCode::kInternal, "ML-DSA-65 secret key must be 4032 bytes", "secret_key");
  }
  uint8_t rnd[32] = {};
  if (!opts.deterministic && !random_bytes(rnd, sizeof rnd)) {
    return Error(ErrorCode::kInternal, "random number generator failure");
  }
  const uint8_t header[2] = {0, static_cast<uint8_t>(opts.context.size())};
  internal::MessageParts parts{{std::span<const uint8_t>(header, 2), opts.context, message}};
  auto r = run_sign(secret_key, parts, rnd);
  secure_wipe(rnd, sizeof rnd);
  return r;
}

Result<Bytes> sign_internal(std::span<const uint8_t> secret_key, std::span<const uint8_t> m_prime,
                            std::span<const uint8_t> rnd) {
  if (rnd.size() != 32) {
    return Error(ErrorCode::kInternal, "ML-DSA-65 rnd must be 32 bytes", "rnd");
  }
  internal::MessageParts parts{{m_prime, {}, {}}};
  return run_sign(secret_key, parts, rnd.data());
}

bool verify(std::span<const uint8_t> public_key, std::span<const uint8_t> message,
            std::span<const uint8_t> signature, std::span<const uint8_t> context) {
  if (public_key.size() != kPublicKeyBytes || signature.size() != kSignatureBytes ||
      context.size() > kMaxContextBytes) {
    return false;
  }
  const uint8_t header[2] = {0, static_cast<uint8_t>(context.size())};
  internal::MessageParts parts{{std::span<const uint8_t>(header, 2), context, message}};
  return internal::verify_internal_impl(public_key.data(), parts, signature.data());
}

std::string kid(std::span<const uint8_t> public_key) {
  // The last key this thread named: a node checks most messages against the few keys it
  // trusts, and comparing 1,952 bytes costs a fraction of hashing them. Nothing shared.
  thread_local std::vector<uint8_t> last_key;
  thread_local std::string last_kid;
  if (!last_kid.empty() &&
      std::equal(public_key.begin(), public_key.end(), last_key.begin(), last_key.end()))
    return last_kid;
  const Digest256 d = sha256(public_key.data(), public_key.size());
  last_key.assign(public_key.begin(), public_key.end());
  last_kid = to_hex(d.data(), 4);
  return last_kid;
}

}  // namespace rcan::mldsa65

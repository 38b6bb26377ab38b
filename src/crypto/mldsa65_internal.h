// Internals of the ML-DSA-65 implementation, exposed only so that the unit tests can check
// the arithmetic building blocks against naive definitions. Not part of the public API.
#pragma once

#include <cstddef>
#include <cstdint>

namespace rcan::mldsa65::internal {

inline constexpr int32_t kQ = 8380417;             // 2^23 - 2^13 + 1
inline constexpr int32_t kGamma2 = (kQ - 1) / 32;  // 261888
inline constexpr size_t kN = 256;

// Montgomery reduction with R = 2^32: for |a| < 2^31·q returns r ≡ a·2^-32 (mod q), |r| < q.
int32_t montgomery_reduce(int64_t a);
// Forward NTT (FIPS 204 Alg. 41) in place. Input |a_i| < q; output |a_i| < 9q (not reduced).
void ntt(int32_t a[kN]);
// Inverse NTT (FIPS 204 Alg. 42) of a Montgomery product: input |a_i| < q, output
// NTT^-1(a)·2^32 folded so that intt(montgomery pointwise product) is the plain product,
// |out_i| < q.
void intt_from_montgomery(int32_t a[kN]);
// Pointwise product in the NTT domain with Montgomery reduction.
int32_t pointwise_montgomery(int32_t a, int32_t b);
// FIPS 204 Alg. 36 Decompose for a in [0, q): a ≡ r1·2γ2 + r0, r0 in (-γ2, γ2] (with the
// q-1 corner case folded to r1 = 0). Branch-free.
void decompose(int32_t a, int32_t* r1, int32_t* r0);
// FIPS 204 Alg. 40 UseHint for a in [0, q), h in {0, 1}.
int32_t use_hint(int32_t a, uint32_t h);
// Chooses the AVX2-compiled variant (when the CPU has AVX2 and `allow`) or the baseline one;
// returns whether the AVX2 variant is now active. Both run the same source code.
bool select_simd(bool allow);
// Any int32 with |a| < 2^31 - 2^22 to its representative in [0, q), branch-free.
int32_t freeze(int32_t a);

}  // namespace rcan::mldsa65::internal

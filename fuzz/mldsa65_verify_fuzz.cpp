// libFuzzer target: ML-DSA-65 verification on arbitrary public keys, signatures, contexts and
// messages. verify() must return (true or false) for every input and never crash.
//
// Input layout: byte 0 = mode, byte 1 = context length, then the rest is split.
//   mode bit 0: use a fixed, valid public key (seed 00..1f) so that the fuzzer reaches the
//               signature decoding and arithmetic with a real key; otherwise the key comes
//               from the input.
//   mode bit 1: take the key/signature lengths from the input (mode >> 2 scaled) instead of
//               the correct sizes, to exercise length checks.
//   mode bit 7: context length + 1 (so 256, one above the limit, is reachable).
#include <cstddef>
#include <cstdint>
#include <span>

#include "rcan/crypto/mldsa65.h"

namespace {

const rcan::Bytes& fixed_public_key() {
  static const rcan::Bytes pk = [] {
    uint8_t seed[32];
    for (int i = 0; i < 32; ++i) seed[i] = static_cast<uint8_t>(i);
    auto kp = rcan::mldsa65::keygen_from_seed(seed);
    return kp.ok() ? kp->public_key : rcan::Bytes{};
  }();
  return pk;
}

std::span<const uint8_t> take(std::span<const uint8_t>& in, size_t n) {
  n = n < in.size() ? n : in.size();
  auto head = in.first(n);
  in = in.subspan(n);
  return head;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  const uint8_t mode = data[0];
  size_t ctx_len = data[1];
  if (mode & 0x80) ctx_len += 1;
  std::span<const uint8_t> in(data + 2, size - 2);

  const bool odd_lengths = (mode & 2) != 0;
  const size_t scale = static_cast<size_t>((mode >> 2) & 0x1f);  // 0..31
  std::span<const uint8_t> pk;
  if (mode & 1) {
    pk = fixed_public_key();
  } else {
    pk = take(in, odd_lengths ? rcan::mldsa65::kPublicKeyBytes * scale / 16
                              : rcan::mldsa65::kPublicKeyBytes);
  }
  const auto sig = take(in, odd_lengths ? rcan::mldsa65::kSignatureBytes * scale / 16
                                        : rcan::mldsa65::kSignatureBytes);
  const auto ctx = take(in, ctx_len);
  const auto msg = in;
  const bool ok = rcan::mldsa65::verify(pk, msg, sig, ctx);
  // A valid signature needs well-formed lengths; anything else must be rejected.
  if (ok && (pk.size() != rcan::mldsa65::kPublicKeyBytes ||
             sig.size() != rcan::mldsa65::kSignatureBytes || ctx.size() > 255)) {
    __builtin_trap();
  }
  return 0;
}

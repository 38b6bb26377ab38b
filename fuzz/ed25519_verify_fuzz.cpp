// libFuzzer target: Ed25519 verification on arbitrary keys, signatures and messages, plus
// the PEM parser. Must never crash.
//
// Input layout: byte 0 = mode; bit 0 selects a fixed valid key (seed 00..1f), bit 1 takes
// odd key/signature lengths from bits 2..6; bit 7 additionally feeds the whole input to
// public_key_from_pem.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "rcan/crypto/ed25519.h"

namespace {

const rcan::Bytes& fixed_public_key() {
  static const rcan::Bytes pk = [] {
    uint8_t seed[32];
    for (int i = 0; i < 32; ++i) seed[i] = static_cast<uint8_t>(i);
    auto r = rcan::ed25519::public_key_from_seed(seed);
    return r.ok() ? *r : rcan::Bytes{};
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
  if (size < 1) return 0;
  const uint8_t mode = data[0];
  std::span<const uint8_t> in(data + 1, size - 1);
  if (mode & 0x80) {
    auto pk = rcan::ed25519::public_key_from_pem(
        std::string_view(reinterpret_cast<const char*>(in.data()), in.size()));
    if (pk.ok() && pk->size() != rcan::ed25519::kPublicKeyBytes) __builtin_trap();
  }
  const bool odd_lengths = (mode & 2) != 0;
  const size_t scale = static_cast<size_t>((mode >> 2) & 0x1f);
  std::span<const uint8_t> pk;
  if (mode & 1) {
    pk = fixed_public_key();
  } else {
    pk = take(in, odd_lengths ? scale * 2 : rcan::ed25519::kPublicKeyBytes);
  }
  const auto sig = take(in, odd_lengths ? scale * 4 : rcan::ed25519::kSignatureBytes);
  const bool ok = rcan::ed25519::verify(pk, in, sig);
  if (ok && (pk.size() != rcan::ed25519::kPublicKeyBytes ||
             sig.size() != rcan::ed25519::kSignatureBytes)) {
    __builtin_trap();
  }
  return 0;
}

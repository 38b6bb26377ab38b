// libFuzzer target: the §16.6 watermark format check. valid_format() and check_format() must
// agree with each other and with an independent reading of ^rcan-wm-v1:[0-9a-f]{32}$ (whole
// string). Also computes a token keyed with the input, which must itself be well-formed and
// verify.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string_view>

#include "rcan/crypto/watermark.h"

namespace {

bool reference(std::string_view t) {
  static const char kPrefix[] = "rcan-wm-v1:";
  if (t.size() != 43 || std::memcmp(t.data(), kPrefix, 11) != 0) return false;
  for (size_t i = 11; i < t.size(); ++i)
    if (std::strchr("0123456789abcdef", t[i]) == nullptr || t[i] == '\0') return false;
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  std::string_view token(reinterpret_cast<const char*>(data), size);
  bool v = watermark::valid_format(token);
  bool c = watermark::check_format(token).ok();
  if (v != c || v != reference(token)) std::abort();
  std::span<const uint8_t> key(data, size);
  std::string t = watermark::compute(key, "RRN-000000000001", token, "2026-04-10T14:32:01.123456");
  if (!watermark::valid_format(t)) std::abort();
  if (!watermark::verify(key, "RRN-000000000001", token, "2026-04-10T14:32:01.123456", t))
    std::abort();
  return 0;
}

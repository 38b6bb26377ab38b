// Uses an installed librcan as any other program would: parses a RURI, writes a message as
// canonical JSON, signs it with Ed25519 and verifies the signature. Prints one line per step;
// tests/install/consumer_test.sh compares them.
#include <rcan/crypto/ed25519.h>
#include <rcan/encoding.h>
#include <rcan/json.h>
#include <rcan/ruri.h>
#include <rcan/version.h>

#include <cstdio>
#include <span>
#include <string>

int main() {
  auto ruri = rcan::parse_ruri("rcan://registry.rcan.dev/acme/robotarm/v2/unit-001");
  if (!ruri.ok()) {
    std::printf("ruri: %s\n", ruri.error().message.c_str());
    return 1;
  }
  std::printf("ruri: %s\n", ruri.value().str().c_str());

  auto msg = rcan::json::parse(R"({"target":"x","cmd":"move","params":{"b":2,"a":1.0}})");
  if (!msg.ok()) {
    std::printf("json: %s\n", msg.error().message.c_str());
    return 1;
  }
  const std::string text = rcan::json::canonical(msg.value());
  std::printf("canonical: %s\n", text.c_str());

  const rcan::Bytes seed(32, 7);
  auto pub = rcan::ed25519::public_key_from_seed(seed);
  const std::span<const uint8_t> bytes(reinterpret_cast<const uint8_t*>(text.data()), text.size());
  auto sig = rcan::ed25519::sign(seed, bytes);
  if (!pub.ok() || !sig.ok()) {
    std::printf("ed25519: no key or signature\n");
    return 1;
  }
  std::printf("verify: %s\n",
              rcan::ed25519::verify(pub.value(), bytes, sig.value()) ? "ok" : "bad");
  std::string altered = text + " ";
  const std::span<const uint8_t> other(reinterpret_cast<const uint8_t*>(altered.data()),
                                       altered.size());
  std::printf("verify altered: %s\n",
              rcan::ed25519::verify(pub.value(), other, sig.value()) ? "ok" : "bad");
  std::printf("version: %s\n", std::string(rcan::kSoftwareVersion).c_str());
  return 0;
}

// Ed25519 through OpenSSL: every shared vector case, malformed input, PEM round trips and a
// cross-check with pyca/cryptography.
#include "rcan/crypto/ed25519.h"

#include <gtest/gtest.h>

#include <sstream>

#include "test_support.h"

namespace {

using rcan::Bytes;
using rcan::test::hex;
namespace ed25519 = rcan::ed25519;

const std::string& str(const rcan::json::Value& v, const char* key) {
  static const std::string kEmpty;
  const auto* f = v.get(key);
  if (f == nullptr || !f->is_string()) {
    ADD_FAILURE() << "vector field missing: " << key;
    return kEmpty;
  }
  return f->as_string();
}

Bytes flipped(const Bytes& b, size_t pos, uint8_t mask) {
  Bytes out = b;
  if (pos < out.size()) out.at(pos) ^= mask;
  return out;
}

TEST(Ed25519Vectors, ValidCasesReproduceExactly) {
  const auto v = rcan::test::load_vector("ed25519.json");
  const auto* cases = v.get("valid");
  ASSERT_NE(cases, nullptr);
  ASSERT_EQ(cases->as_array().size(), 10u);
  size_t i = 0;
  for (const auto& c : cases->as_array()) {
    const Bytes seed = hex(str(c, "seed_hex"));
    const Bytes pk = hex(str(c, "pk_hex"));
    const Bytes msg = hex(str(c, "msg_hex"));
    auto derived = ed25519::public_key_from_seed(seed);
    ASSERT_TRUE(derived.ok()) << derived.error().message;
    EXPECT_EQ(*derived, pk) << "case " << i;
    auto sig = ed25519::sign(seed, msg);
    ASSERT_TRUE(sig.ok()) << sig.error().message;
    EXPECT_EQ(rcan::to_hex(*sig), str(c, "sig_hex")) << "case " << i;
    EXPECT_TRUE(ed25519::verify(pk, msg, hex(str(c, "sig_hex")))) << "case " << i;
    ++i;
  }
}

TEST(Ed25519Vectors, InvalidCasesAreRejected) {
  const auto v = rcan::test::load_vector("ed25519.json");
  const auto* cases = v.get("invalid");
  ASSERT_NE(cases, nullptr);
  ASSERT_EQ(cases->as_array().size(), 6u);
  for (const auto& c : cases->as_array()) {
    const auto* valid = c.get("valid");
    ASSERT_TRUE(valid != nullptr && valid->is_bool());
    EXPECT_FALSE(valid->as_bool());
    EXPECT_FALSE(
        ed25519::verify(hex(str(c, "pk_hex")), hex(str(c, "msg_hex")), hex(str(c, "sig_hex"))))
        << str(c, "why");
  }
}

TEST(Ed25519, RoundTripAndTampering) {
  const Bytes seed = ed25519::random_seed();
  ASSERT_EQ(seed.size(), ed25519::kSeedBytes);
  EXPECT_NE(seed, ed25519::random_seed());
  auto pk = ed25519::public_key_from_seed(seed);
  ASSERT_TRUE(pk.ok());
  for (size_t len : {size_t{0}, size_t{1}, size_t{1000}}) {
    const Bytes msg(len, 0x42);
    auto sig = ed25519::sign(seed, msg);
    ASSERT_TRUE(sig.ok());
    ASSERT_EQ(sig->size(), ed25519::kSignatureBytes);
    EXPECT_TRUE(ed25519::verify(*pk, msg, *sig));
    for (size_t pos = 0; pos < sig->size(); pos += 7) {
      EXPECT_FALSE(ed25519::verify(*pk, msg, flipped(*sig, pos, 0x10))) << pos;
    }
    Bytes m2 = msg;
    m2.push_back(0);
    EXPECT_FALSE(ed25519::verify(*pk, m2, *sig));
    EXPECT_FALSE(ed25519::verify(flipped(*pk, 5, 1), msg, *sig));
  }
}

TEST(Ed25519, MalformedInputsAreRejected) {
  const Bytes seed(32, 9);
  auto pk = ed25519::public_key_from_seed(seed);
  ASSERT_TRUE(pk.ok());
  const Bytes msg = rcan::to_bytes("abc");
  auto sig = ed25519::sign(seed, msg);
  ASSERT_TRUE(sig.ok());
  EXPECT_FALSE(ed25519::public_key_from_seed(Bytes(31)).ok());
  EXPECT_FALSE(ed25519::public_key_from_seed({}).ok());
  EXPECT_FALSE(ed25519::sign(Bytes(33), msg).ok());
  EXPECT_FALSE(ed25519::verify(*pk, msg, Bytes(sig->begin(), sig->end() - 1)));
  Bytes longer = *sig;
  longer.push_back(0);
  EXPECT_FALSE(ed25519::verify(*pk, msg, longer));
  EXPECT_FALSE(ed25519::verify({}, msg, *sig));
  EXPECT_FALSE(ed25519::verify(Bytes(pk->begin(), pk->end() - 1), msg, *sig));
  EXPECT_FALSE(ed25519::verify(*pk, msg, {}));
  EXPECT_FALSE(ed25519::verify(*pk, msg, Bytes(64, 0)));
  EXPECT_FALSE(ed25519::verify(*pk, msg, Bytes(64, 0xff)));   // S >= L
  EXPECT_FALSE(ed25519::verify(Bytes(32, 0xff), msg, *sig));  // not a point encoding
}

TEST(Ed25519, PemRoundTrip) {
  auto pk = ed25519::public_key_from_seed(Bytes(32, 3));
  ASSERT_TRUE(pk.ok());
  auto pem = ed25519::public_key_to_pem(*pk);
  ASSERT_TRUE(pem.ok()) << pem.error().message;
  EXPECT_EQ(pem->rfind("-----BEGIN PUBLIC KEY-----\n", 0), 0u);
  auto back = ed25519::public_key_from_pem(*pem);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(*back, *pk);

  // RFC 8410 §10.1 example SubjectPublicKeyInfo.
  const std::string rfc8410 =
      "-----BEGIN PUBLIC KEY-----\n"
      "MCowBQYDK2VwAyEAGb9ECWmEzf6FQbrBZ9w7lshQhqowtrbLDFw4rXAxZuE=\n"
      "-----END PUBLIC KEY-----\n";
  auto parsed = ed25519::public_key_from_pem(rfc8410);
  ASSERT_TRUE(parsed.ok());
  EXPECT_EQ(rcan::to_hex(*parsed),
            "19bf44096984cdfe8541bac167dc3b96c85086aa30b6b6cb0c5c38ad703166e1");
  auto again = ed25519::public_key_to_pem(*parsed);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(*again, rfc8410);
}

TEST(Ed25519, PemRejectsGarbageAndOtherKeyTypes) {
  EXPECT_FALSE(ed25519::public_key_from_pem("").ok());
  EXPECT_FALSE(ed25519::public_key_from_pem("not pem at all").ok());
  EXPECT_FALSE(ed25519::public_key_from_pem("-----BEGIN PUBLIC KEY-----\nAAAA\n"
                                            "-----END PUBLIC KEY-----\n")
                   .ok());
  const std::string p256 =
      "-----BEGIN PUBLIC KEY-----\n"
      "MFkwEwYHKoZIzj0CAQYIKoZIzj0DAQcDQgAEJu/OvQ7p40pmkYfhizqRIrL3M5Rb\n"
      "ZJzJ+fkh6fna2BKQI4venMe7Mw0VDGdwTdJa5wVSBXRLbzG/QHB0WHLQ5g==\n"
      "-----END PUBLIC KEY-----\n";
  EXPECT_FALSE(ed25519::public_key_from_pem(p256).ok());
  EXPECT_FALSE(ed25519::public_key_to_pem(Bytes(31)).ok());
}

constexpr const char* kPyScript = R"PY(
import sys
try:
    from cryptography.hazmat.primitives.asymmetric import ed25519
    from cryptography.hazmat.primitives import serialization
except Exception as e:
    print("SKIP " + type(e).__name__ + ": " + str(e).replace("\n", " "))
    sys.exit(0)
for line in sys.stdin.read().splitlines():
    seed, msg, sig = [bytes.fromhex(f[1:]) for f in line.split(" ")]
    key = ed25519.Ed25519PrivateKey.from_private_bytes(seed)
    pub = key.public_key()
    try:
        pub.verify(sig, msg)
        ok = "OK"
    except Exception:
        ok = "BAD"
    pem = pub.public_bytes(serialization.Encoding.PEM,
                           serialization.PublicFormat.SubjectPublicKeyInfo)
    print(pub.public_bytes_raw().hex(), ok, key.sign(msg).hex(), pem.hex())
)PY";

TEST(Ed25519CrossCheck, PycaCryptography) {
  std::string input;
  std::vector<std::pair<Bytes, Bytes>> cases;
  for (int i = 0; i < 4; ++i) {
    Bytes seed = ed25519::random_seed();
    Bytes msg(static_cast<size_t>(i * 31), static_cast<uint8_t>(i));
    auto sig = ed25519::sign(seed, msg);
    ASSERT_TRUE(sig.ok());
    input.append("x").append(rcan::to_hex(seed));
    input.append(" x").append(rcan::to_hex(msg));
    input.append(" x").append(rcan::to_hex(*sig));
    input.append("\n");
    cases.emplace_back(seed, msg);
  }
  auto r = rcan::test::run({"/usr/bin/env", "python3", "-c", kPyScript}, input);
  if (r.exit_code == 127) GTEST_SKIP() << "python3 not found on PATH";
  if (r.out.rfind("SKIP", 0) == 0) GTEST_SKIP() << "pyca/cryptography unavailable: " << r.out;
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::istringstream lines(r.out);
  std::string pk_hex, verdict, sig_hex, pem_hex;
  size_t i = 0;
  while (lines >> pk_hex >> verdict >> sig_hex >> pem_hex) {
    ASSERT_LT(i, cases.size());
    auto pk = ed25519::public_key_from_seed(cases[i].first);
    ASSERT_TRUE(pk.ok());
    EXPECT_EQ(pk_hex, rcan::to_hex(*pk));
    EXPECT_EQ(verdict, "OK");
    auto ours = ed25519::sign(cases[i].first, cases[i].second);
    ASSERT_TRUE(ours.ok());
    EXPECT_EQ(sig_hex, rcan::to_hex(*ours));  // Ed25519 is deterministic
    EXPECT_TRUE(ed25519::verify(*pk, cases[i].second, hex(sig_hex)));
    auto pem = ed25519::public_key_to_pem(*pk);
    ASSERT_TRUE(pem.ok());
    EXPECT_EQ(rcan::to_hex(*pem), pem_hex);
    ++i;
  }
  EXPECT_EQ(i, cases.size()) << r.out << r.err;
}

}  // namespace

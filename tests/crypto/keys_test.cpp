// Robot identity key directories: derivation against the vectors, file modes, refusal of
// loose permissions / overwrites / mismatches, JWK, and the keys/sign/verify verbs.
#include "rcan/crypto/keys.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <fstream>

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/hash.h"
#include "test_support.h"

namespace rcan::keys {
namespace {

const std::string kSeed0 = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";
const std::string kEdSeed7 = "0707070707070707070707070707070707070707070707070707070707070707";
const std::string kEdPub7 = "ea4a6c63e29c520abef5507b132ec5f9954776aebebe7b92421eea691446d22c";

unsigned mode_of(const std::string& p) {
  struct stat st {};
  EXPECT_EQ(::lstat(p.c_str(), &st), 0) << p;
  return st.st_mode & 07777;
}

RobotKeys derived0() {
  auto k = derive(test::hex(kSeed0), test::hex(kEdSeed7));
  EXPECT_TRUE(k.ok());
  return std::move(k).value();
}

std::string sha256_of(const Bytes& b) {
  return sha256_hex(std::string_view(reinterpret_cast<const char*>(b.data()), b.size()));
}

TEST(Keys, DeriveMatchesTheVectors) {
  auto kg = test::load_vector("mldsa65-keygen.json");
  const auto& c0 = kg.get("cases")->as_array()[0];
  RobotKeys k = derived0();
  EXPECT_EQ(to_hex(k.pub.mldsa65_pk), c0.get("pk_hex")->as_string());
  EXPECT_EQ(k.mldsa65_sk.size(), 4032u);
  EXPECT_EQ(to_hex(k.mldsa65_sk.data(), k.mldsa65_sk.size()), c0.get("sk_hex")->as_string());
  EXPECT_EQ(k.pub.kid(), "d666806e");
  EXPECT_EQ(to_hex(k.pub.ed25519_pk), kEdPub7);
  EXPECT_FALSE(derive(Bytes(31, 0), test::hex(kEdSeed7)).ok());
  EXPECT_FALSE(derive(test::hex(kSeed0), Bytes(33, 0)).ok());
}

TEST(Keys, GenerateGivesFreshKeys) {
  auto a = generate();
  auto b = generate();
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_NE(a->pub.mldsa65_pk, b->pub.mldsa65_pk);
  EXPECT_NE(a->pub.ed25519_pk, b->pub.ed25519_pk);
  EXPECT_EQ(a->mldsa65_seed.size(), 32u);
  EXPECT_EQ(a->pub.mldsa65_pk.size(), 1952u);
}

TEST(Keys, WriteDirCreatesFilesWithSecretModesAndLoadsBack) {
  test::TempDir tmp;
  std::string dir = tmp.file("robot");
  RobotKeys k = derived0();
  ASSERT_TRUE(write_dir(dir, k).ok());
  EXPECT_EQ(mode_of(dir), 0700u);
  EXPECT_EQ(mode_of(dir + "/mldsa65.seed"), 0600u);
  EXPECT_EQ(mode_of(dir + "/ed25519.seed"), 0600u);
  EXPECT_EQ(mode_of(dir + "/mldsa65.pub"), 0644u);
  EXPECT_EQ(mode_of(dir + "/ed25519.pub"), 0644u);
  EXPECT_EQ(test::read_file(dir + "/mldsa65.seed").size(), 32u);
  EXPECT_EQ(test::read_file(dir + "/mldsa65.pub").size(), 1952u);
  EXPECT_EQ(test::read_file(dir + "/ed25519.pub").size(), 32u);
  auto back = load_dir(dir);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->pub.kid(), "d666806e");
  EXPECT_EQ(back->pub.mldsa65_pk, k.pub.mldsa65_pk);
  EXPECT_EQ(to_hex(back->mldsa65_sk.data(), 16), to_hex(k.mldsa65_sk.data(), 16));
  auto pub = load_public_dir(dir);
  ASSERT_TRUE(pub.ok());
  EXPECT_EQ(pub->ed25519_pk, k.pub.ed25519_pk);
}

TEST(Keys, WriteDirNeverOverwrites) {
  test::TempDir tmp;
  RobotKeys k = derived0();
  std::ofstream(tmp.file("ed25519.seed")) << "existing";
  auto s = write_dir(tmp.path(), k);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("already exists"), std::string::npos);
  EXPECT_EQ(test::read_file(tmp.file("ed25519.seed")), "existing");
  EXPECT_NE(::access(tmp.file("mldsa65.seed").c_str(), F_OK), 0);  // nothing new written
  // A directory written once refuses a second write.
  test::TempDir tmp2;
  ASSERT_TRUE(write_dir(tmp2.path(), k).ok());
  EXPECT_FALSE(write_dir(tmp2.path(), derived0()).ok());
  // Not a directory.
  EXPECT_FALSE(write_dir(tmp.file("ed25519.seed"), k).ok());
}

TEST(Keys, LoadRefusesLooseModesSymlinksWrongSizesAndMismatches) {
  test::TempDir tmp;
  ASSERT_TRUE(write_dir(tmp.path(), derived0()).ok());
  for (unsigned bad : {0640u, 0604u, 0660u, 0644u, 0601u}) {
    chmod(tmp.file("mldsa65.seed").c_str(), bad);
    auto r = load_dir(tmp.path());
    ASSERT_FALSE(r.ok()) << std::oct << bad;
    EXPECT_EQ(r.error().reason, "insecure_permissions");
    EXPECT_NE(r.error().message.find("chmod 600"), std::string::npos);
  }
  chmod(tmp.file("mldsa65.seed").c_str(), 0400);
  EXPECT_TRUE(load_dir(tmp.path()).ok());
  chmod(tmp.file("mldsa65.seed").c_str(), 0600);

  // A symlinked secret is refused (O_NOFOLLOW).
  test::TempDir link_dir;
  for (const char* f : {"mldsa65.pub", "ed25519.seed", "ed25519.pub"})
    ASSERT_EQ(::symlink(tmp.file(f).c_str(), link_dir.file(f).c_str()), 0);
  ASSERT_EQ(::symlink(tmp.file("mldsa65.seed").c_str(), link_dir.file("mldsa65.seed").c_str()), 0);
  EXPECT_FALSE(load_dir(link_dir.path()).ok());

  // Wrong size.
  { std::ofstream(tmp.file("ed25519.seed"), std::ios::trunc) << std::string(33, 'x'); }
  auto r = load_dir(tmp.path());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("exactly 32 bytes"), std::string::npos);

  // Public file that does not match the seed.
  test::TempDir tmp3;
  ASSERT_TRUE(write_dir(tmp3.path(), derived0()).ok());
  chmod(tmp3.file("ed25519.pub").c_str(), 0644);
  {
    std::ofstream(tmp3.file("ed25519.pub"), std::ios::trunc | std::ios::binary)
        << std::string(32, '\x01');
  }
  r = load_dir(tmp3.path());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("does not match"), std::string::npos);
  // Missing directory.
  EXPECT_FALSE(load_dir(tmp.file("nope")).ok());
  EXPECT_FALSE(load_public_dir(tmp.file("nope")).ok());
}

TEST(Keys, ReadSecretFileChecks) {
  test::TempDir tmp;
  ASSERT_TRUE(write_new_file(tmp.file("s"), Bytes(10, 7), 0600).ok());
  EXPECT_FALSE(write_new_file(tmp.file("s"), Bytes(10, 7), 0600).ok());  // O_EXCL
  auto s = read_secret_file(tmp.file("s"), 10);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->size(), 10u);
  EXPECT_FALSE(read_secret_file(tmp.file("s"), 11).ok());
  EXPECT_FALSE(read_secret_file(tmp.path(), 0).ok());  // a directory
}

TEST(Keys, MlDsaJwkHasTheRcanPyShape) {
  RobotKeys k = derived0();
  json::Value jwk = mldsa65_jwk(k.pub.mldsa65_pk);
  std::string text = json::dump(jwk);
  EXPECT_EQ(text.rfind(R"({"kty":"OKP","crv":"ML-DSA-65","x":")", 0), 0u) << text.substr(0, 60);
  EXPECT_NE(text.find(R"(","kid":"d666806e","use":"sig","alg":"ml-dsa-65"})"), std::string::npos);
  EXPECT_EQ(text.find('='), std::string::npos);  // x is unpadded
  auto back = mldsa65_pk_from_jwk(jwk);
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(*back, k.pub.mldsa65_pk);
  // rcan-ts shape.
  json::Object ts{
      {"kty", "OKP"}, {"alg", "ML-DSA-65"}, {"use", "sig"}, {"x", jwk.get("x")->as_string()}};
  EXPECT_TRUE(mldsa65_pk_from_jwk(json::Value(ts)).ok());
  // Broken ones.
  json::Value bad = jwk;
  bad.as_object().set("kid", "00000000");
  EXPECT_FALSE(mldsa65_pk_from_jwk(bad).ok());
  bad = jwk;
  bad.as_object().set("crv", "Ed25519");
  EXPECT_FALSE(mldsa65_pk_from_jwk(bad).ok());
  bad = jwk;
  bad.as_object().set("x", "AAAA");
  EXPECT_FALSE(mldsa65_pk_from_jwk(bad).ok());
  bad = jwk;
  bad.as_object().set("x", "!!");
  EXPECT_FALSE(mldsa65_pk_from_jwk(bad).ok());
  EXPECT_FALSE(mldsa65_pk_from_jwk(json::Value("x")).ok());
  EXPECT_FALSE(mldsa65_pk_from_jwk(json::Value(json::Object{{"kty", "OKP"}})).ok());
}

TEST(Keys, Ed25519KidIsTheRcanPyPemHash) {
  // pyca/cryptography: sha256(public_bytes(PEM, SubjectPublicKeyInfo))[:8] for seed 07*32.
  auto kid = ed25519_kid(test::hex(kEdPub7));
  ASSERT_TRUE(kid.ok());
  EXPECT_EQ(*kid, "5cc558a6");
  EXPECT_FALSE(ed25519_kid(Bytes(5, 0)).ok());
}

// ---------------------------------------------------------------------------------------
// CLI

std::string trim(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  return s;
}

TEST(KeysCli, DeriveShowAndRefuseSecondWrite) {
  test::TempDir tmp;
  std::string dir = tmp.file("k");
  auto r = test::run_cli(
      {"keys", "derive", "--dir", dir, "--mldsa-seed", kSeed0, "--ed25519-seed", kEdSeed7});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("d666806e"), std::string::npos);
  auto show = test::run_cli({"keys", "show", "--dir", dir, "--json"});
  ASSERT_EQ(show.exit_code, 0) << show.err;
  auto doc = json::parse(trim(show.out));
  ASSERT_TRUE(doc.ok()) << show.out;
  EXPECT_EQ(doc->get("kid")->as_string(), "d666806e");
  EXPECT_EQ(doc->get("mldsa65")->get("jwk")->get("crv")->as_string(), "ML-DSA-65");
  EXPECT_EQ(doc->get("ed25519")->get("public_key_hex")->as_string(), kEdPub7);
  EXPECT_EQ(doc->get("ed25519")->get("kid")->as_string(), "5cc558a6");
  EXPECT_NE(doc->get("ed25519")->get("pem")->as_string().find("BEGIN PUBLIC KEY"),
            std::string::npos);
  auto again = test::run_cli({"keys", "generate", "--dir", dir});
  EXPECT_EQ(again.exit_code, 1);
  EXPECT_NE(again.err.find("already exists"), std::string::npos);
  EXPECT_EQ(test::run_cli({"keys", "derive", "--dir", tmp.file("x"), "--mldsa-seed", "zz",
                           "--ed25519-seed", kEdSeed7})
                .exit_code,
            2);
  EXPECT_EQ(test::run_cli({"keys", "generate"}).exit_code, 2);
  EXPECT_EQ(test::run_cli({"keys", "show", "--dir", tmp.file("missing")}).exit_code, 1);
  auto gen = test::run_cli({"keys", "generate", "--dir", tmp.file("g")});
  ASSERT_EQ(gen.exit_code, 0) << gen.err;
  EXPECT_EQ(mode_of(tmp.file("g") + "/mldsa65.seed"), 0600u);
}

TEST(KeysCli, SignAndVerifyMatchTheVectors) {
  auto sv = test::load_vector("mldsa65-sign-deterministic.json");
  test::TempDir tmp;
  for (const auto& c : sv.get("cases")->as_array()) {
    const std::string& msg_hex = c.get("msg_hex")->as_string();
    const std::string& ctx_hex = c.get("ctx_hex")->as_string();
    if (msg_hex.size() > 400) continue;
    if (!(msg_hex == "616263" || (!ctx_hex.empty() && ctx_hex.size() <= 64))) continue;
    SCOPED_TRACE(c.get("seed_hex")->as_string() + " ctx " + ctx_hex);
    std::string dir =
        tmp.file("k" + c.get("seed_hex")->as_string().substr(0, 8) + ctx_hex.substr(0, 4));
    auto d = test::run_cli({"keys", "derive", "--dir", dir, "--mldsa-seed",
                            c.get("seed_hex")->as_string(), "--ed25519-seed", kEdSeed7});
    if (d.exit_code != 0 && d.err.find("already exists") != std::string::npos) continue;
    ASSERT_EQ(d.exit_code, 0) << d.err;
    std::string msg = to_string(test::hex(msg_hex));
    std::vector<std::string> args = {"sign",  "--key-dir", dir,
                                     "--alg", "ml-dsa-65", "--deterministic"};
    if (!ctx_hex.empty()) {
      args.push_back("--context");
      args.push_back(ctx_hex);
    }
    auto s = test::run_cli(args, msg);
    ASSERT_EQ(s.exit_code, 0) << s.err;
    auto sig = base64_decode(trim(s.out));
    ASSERT_TRUE(sig.has_value());
    EXPECT_EQ(sha256_of(*sig), c.get("sig_sha256")->as_string());
    std::string pub = dir + "/mldsa65.pub";
    std::vector<std::string> vargs = {"verify",    "--pub", pub,        "--alg",
                                      "ml-dsa-65", "--sig", trim(s.out)};
    if (!ctx_hex.empty()) {
      vargs.push_back("--context");
      vargs.push_back(ctx_hex);
    }
    EXPECT_EQ(test::run_cli(vargs, msg).exit_code, 0);
    EXPECT_EQ(test::run_cli(vargs, msg + "x").exit_code, 1);
  }
}

TEST(KeysCli, Ed25519SignVerifyAndMalformedInput) {
  test::TempDir tmp;
  std::string dir = tmp.file("k");
  ASSERT_EQ(test::run_cli({"keys", "derive", "--dir", dir, "--mldsa-seed", kSeed0, "--ed25519-seed",
                           kEdSeed7})
                .exit_code,
            0);
  const std::string msg = "rcan ed25519 cli test";
  auto s = test::run_cli({"sign", "--key-dir", dir, "--alg", "ed25519"}, msg);
  ASSERT_EQ(s.exit_code, 0) << s.err;
  // pyca/cryptography signature of the same message with seed 07*32.
  EXPECT_EQ(
      trim(s.out),
      "3C7kMBhSfRbPbMJCTISA/Y0sadq+oq3PZR4WhdXxZRSpiM4NEWqIjhxTAMLWAMeGKM8WN/reDKYre8up766zDQ==");
  std::string pub = dir + "/ed25519.pub";
  std::string sig = trim(s.out);
  EXPECT_EQ(
      test::run_cli({"verify", "--pub", pub, "--alg", "ed25519", "--sig", sig}, msg).exit_code, 0);
  EXPECT_EQ(test::run_cli({"verify", "--pub", pub, "--alg", "ed25519", "--sig", sig}, msg + "!")
                .exit_code,
            1);
  // Wrong algorithm for the key file, malformed signature, unknown alg, missing args.
  EXPECT_EQ(
      test::run_cli({"verify", "--pub", pub, "--alg", "ml-dsa-65", "--sig", sig}, msg).exit_code,
      2);
  EXPECT_EQ(
      test::run_cli({"verify", "--pub", pub, "--alg", "ed25519", "--sig", "@@@"}, msg).exit_code,
      2);
  EXPECT_EQ(
      test::run_cli({"verify", "--pub", pub, "--alg", "ed25519", "--sig", "AAAA"}, msg).exit_code,
      1);
  EXPECT_EQ(test::run_cli({"verify", "--pub", pub, "--alg", "rsa", "--sig", sig}, msg).exit_code,
            2);
  EXPECT_EQ(test::run_cli({"verify", "--alg", "ed25519", "--sig", sig}, msg).exit_code, 2);
  EXPECT_EQ(test::run_cli({"sign", "--key-dir", dir, "--alg", "ed25519", "--context", "00"}, msg)
                .exit_code,
            2);
  EXPECT_EQ(
      test::run_cli(
          {"sign", "--key-dir", dir, "--alg", "ml-dsa-65", "--context", std::string(512, 'a')}, msg)
          .exit_code,
      2);
  chmod((dir + "/ed25519.seed").c_str(), 0644);
  auto loose = test::run_cli({"sign", "--key-dir", dir, "--alg", "ed25519"}, msg);
  EXPECT_EQ(loose.exit_code, 1);
  EXPECT_NE(loose.err.find("group/world"), std::string::npos);
}

}  // namespace
}  // namespace rcan::keys

// §16.6 watermark: tests/vectors/watermark.json byte-exact, malformed tokens, key loading, CLI.
#include "rcan/crypto/watermark.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>

#include "rcan/crypto/keys.h"
#include "rcan/crypto/mldsa65.h"
#include "test_support.h"

namespace rcan::watermark {
namespace {

void write_file(const std::string& path, const Bytes& b, unsigned mode) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  chmod(path.c_str(), mode);
}

TEST(Watermark, VectorsAreByteExact) {
  auto v = test::load_vector("watermark.json");
  const auto& cases = v.get("cases")->as_array();
  ASSERT_EQ(cases.size(), 10u);
  for (const auto& c : cases) {
    Bytes key = test::hex(c.get("key_hex")->as_string());
    std::string token = compute(key, c.get("rrn")->as_string(), c.get("thought_id")->as_string(),
                                c.get("timestamp_iso")->as_string());
    EXPECT_EQ(token, c.get("token")->as_string()) << c.get("hmac_input_utf8")->as_string();
    EXPECT_TRUE(valid_format(token));
    EXPECT_TRUE(verify(key, c.get("rrn")->as_string(), c.get("thought_id")->as_string(),
                       c.get("timestamp_iso")->as_string(), token));
  }
}

TEST(Watermark, AllMalformedTokensAreRejected) {
  auto v = test::load_vector("watermark.json");
  const auto& bad = v.get("malformed_tokens")->as_array();
  ASSERT_EQ(bad.size(), 25u);
  for (const auto& c : bad) {
    const std::string& t = c.get("token")->as_string();
    EXPECT_FALSE(valid_format(t)) << c.get("why")->as_string();
    Status s = check_format(t);
    ASSERT_FALSE(s.ok()) << c.get("why")->as_string();
    EXPECT_EQ(s.error().code, ErrorCode::kSchemaValidationFailed);
    EXPECT_EQ(s.error().field, "watermark_token");
    EXPECT_NE(s.error().message.find("Invalid watermark token format"), std::string::npos);
  }
  EXPECT_TRUE(check_format("rcan-wm-v1:d32a0ea8db075e0ec9c7c313e75a5011").ok());
  EXPECT_FALSE(valid_format(std::string("rcan-wm-v1:d32a0ea8db075e0ec9c7c313e75a501\0", 44)));
}

TEST(Watermark, VerifyRejectsOtherInputsAndMalformedTokens) {
  Bytes key(64, 0x78);
  std::string t = compute(key, "RRN-000000000001", "thought-abc123", "2026-04-10T14:32:01.123456");
  EXPECT_TRUE(verify(key, "RRN-000000000001", "thought-abc123", "2026-04-10T14:32:01.123456", t));
  EXPECT_FALSE(verify(key, "RRN-000000000002", "thought-abc123", "2026-04-10T14:32:01.123456", t));
  EXPECT_FALSE(verify(Bytes(64, 0x79), "RRN-000000000001", "thought-abc123",
                      "2026-04-10T14:32:01.123456", t));
  EXPECT_FALSE(
      verify(key, "RRN-000000000001", "thought-abc123", "2026-04-10T14:32:01.123456", t + "\n"));
  std::string upper = t;
  for (auto& ch : upper)
    if (ch >= 'a' && ch <= 'f') ch = static_cast<char>(ch - 32);
  EXPECT_FALSE(
      verify(key, "RRN-000000000001", "thought-abc123", "2026-04-10T14:32:01.123456", upper));
}

TEST(Watermark, TimestampFormatIsUtcMicroseconds) {
  using namespace std::chrono;
  system_clock::time_point t{microseconds(int64_t{1775831521123456})};
  EXPECT_EQ(format_timestamp(t), "2026-04-10T14:32:01.123456");
  EXPECT_EQ(format_timestamp(system_clock::time_point{}), "1970-01-01T00:00:00.000000");
}

TEST(Watermark, KeyFromRawSecretKeySeedOrKeyDirectory) {
  auto kg = test::load_vector("mldsa65-keygen.json");
  const auto& c0 = kg.get("cases")->as_array()[0];
  Bytes seed = test::hex(c0.get("seed_hex")->as_string());
  Bytes sk = test::hex(c0.get("sk_hex")->as_string());
  const std::string expected = "rcan-wm-v1:c9d8cade857a95562fb6d69563889ad0";
  test::TempDir dir;
  write_file(dir.file("robot.sk"), sk, 0600);
  write_file(dir.file("mldsa65.seed"), seed, 0600);
  for (const std::string& path : {dir.file("robot.sk"), dir.file("mldsa65.seed"), dir.path()}) {
    auto key = load_key(path);
    ASSERT_TRUE(key.ok()) << path << ": " << key.error().message;
    EXPECT_EQ(key->size(), mldsa65::kSecretKeyBytes);
    EXPECT_EQ(compute(*key, "RRN-000000000001", "thought-abc123", "2026-04-10T14:32:01.123456"),
              expected);
  }
  write_file(dir.file("loose.sk"), sk, 0644);
  auto loose = load_key(dir.file("loose.sk"));
  ASSERT_FALSE(loose.ok());
  EXPECT_NE(loose.error().message.find("group/world"), std::string::npos);
  write_file(dir.file("short.sk"), Bytes(100, 1), 0600);
  auto shortk = load_key(dir.file("short.sk"));
  ASSERT_FALSE(shortk.ok());
  EXPECT_NE(shortk.error().message.find("4032"), std::string::npos);
  EXPECT_FALSE(load_key(dir.file("missing")).ok());
}

TEST(WatermarkCli, ComputeCheckAndVerify) {
  auto kg = test::load_vector("mldsa65-keygen.json");
  Bytes sk = test::hex(kg.get("cases")->as_array()[0].get("sk_hex")->as_string());
  test::TempDir dir;
  write_file(dir.file("robot.sk"), sk, 0600);
  auto r = test::run_cli({"watermark", "compute", "--key-file", dir.file("robot.sk"), "--rrn",
                          "RRN-000000000001", "--thought-id", "thought-abc123", "--timestamp",
                          "2026-04-10T14:32:01.123456"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, "rcan-wm-v1:c9d8cade857a95562fb6d69563889ad0\n");
  auto v =
      test::run_cli({"watermark", "verify", "--key-file", dir.file("robot.sk"), "--rrn",
                     "RRN-000000000001", "--thought-id", "thought-abc123", "--timestamp",
                     "2026-04-10T14:32:01.123456", "rcan-wm-v1:c9d8cade857a95562fb6d69563889ad0"});
  EXPECT_EQ(v.exit_code, 0) << v.out << v.err;
  v = test::run_cli({"watermark", "verify", "--key-file", dir.file("robot.sk"), "--rrn",
                     "RRN-000000000001", "--thought-id", "thought-abc124", "--timestamp",
                     "2026-04-10T14:32:01.123456", "rcan-wm-v1:c9d8cade857a95562fb6d69563889ad0"});
  EXPECT_EQ(v.exit_code, 1);
  EXPECT_EQ(test::run_cli({"watermark", "check", "rcan-wm-v1:c9d8cade857a95562fb6d69563889ad0"})
                .exit_code,
            0);
  EXPECT_EQ(test::run_cli({"watermark", "check", "rcan-wm-v1:c9d8cade857a95562fb6d69563889ad0\n"})
                .exit_code,
            1);
  EXPECT_EQ(test::run_cli({"watermark", "compute", "--rrn", "x"}).exit_code, 2);
  write_file(dir.file("loose.sk"), sk, 0644);
  EXPECT_EQ(test::run_cli({"watermark", "compute", "--key-file", dir.file("loose.sk"), "--rrn", "R",
                           "--thought-id", "t", "--timestamp", "x"})
                .exit_code,
            2);
}

}  // namespace
}  // namespace rcan::watermark

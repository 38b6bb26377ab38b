// Hex, base64, base64url, hashes and the error catalogue.
#include "rcan/encoding.h"

#include <gtest/gtest.h>

#include "rcan/errors.h"
#include "rcan/hash.h"

namespace rcan {
namespace {

TEST(Encoding, HexRoundTripAndRejects) {
  Bytes b{0x00, 0x7f, 0x80, 0xff};
  EXPECT_EQ(to_hex(b), "007f80ff");
  EXPECT_EQ(*from_hex("007F80ff"), b);
  EXPECT_FALSE(from_hex("abc").has_value());
  EXPECT_FALSE(from_hex("zz").has_value());
}

TEST(Encoding, Base64Rfc4648Vectors) {
  const char* plain[] = {"", "f", "fo", "foo", "foob", "fooba", "foobar"};
  const char* enc[] = {"", "Zg==", "Zm8=", "Zm9v", "Zm9vYg==", "Zm9vYmE=", "Zm9vYmFy"};
  for (int i = 0; i < 7; ++i) {
    Bytes b = to_bytes(plain[i]);
    EXPECT_EQ(base64_encode(b), enc[i]);
    EXPECT_EQ(base64_decode(enc[i]), b);
  }
  EXPECT_FALSE(base64_decode("Zg=").has_value());
  EXPECT_FALSE(base64_decode("Zh==").has_value());  // non-canonical trailing bits
  EXPECT_FALSE(base64_decode("Zm9v\n").has_value());
  EXPECT_FALSE(base64_decode("Zm-v").has_value());
}

TEST(Encoding, Base64UrlWithAndWithoutPadding) {
  Bytes b{0xfb, 0xff, 0xbf};
  EXPECT_EQ(base64url_encode(b), "-_-_");
  Bytes two{0xfb, 0xff};
  EXPECT_EQ(base64url_encode(two), "-_8");
  EXPECT_EQ(base64url_encode(two, true), "-_8=");
  EXPECT_EQ(base64url_decode("-_8"), two);
  EXPECT_EQ(base64url_decode("-_8="), two);
  EXPECT_FALSE(base64url_decode("-_8==").has_value());
  EXPECT_FALSE(base64url_decode("+/8").has_value());
  EXPECT_FALSE(base64url_decode("a").has_value());
}

// Every length and every byte value round-trips; every symbol position refuses a foreign
// symbol, and a tail with unused bits set is refused (the decoder works four symbols at a time).
TEST(Encoding, Base64EveryLengthRoundTripsAndEveryPositionRefuses) {
  Bytes data;
  for (int i = 0; i < 70; ++i) {
    std::string std_enc = base64_encode(data), url_enc = base64url_encode(data);
    ASSERT_EQ(base64_decode(std_enc), data) << std_enc;
    ASSERT_EQ(base64url_decode(url_enc), data) << url_enc;
    for (size_t at = 0; at < url_enc.size(); ++at) {
      std::string bad = url_enc;
      bad[at] = '*';
      EXPECT_FALSE(base64url_decode(bad).has_value()) << bad;
    }
    data.push_back(static_cast<uint8_t>(i * 37 + 11));
  }
  EXPECT_TRUE(base64url_decode("Zm9vYg").has_value());    // canonical 2-symbol tail
  EXPECT_FALSE(base64url_decode("Zm9vYh").has_value());   // 4 unused bits not zero
  EXPECT_TRUE(base64url_decode("Zm9vYmE").has_value());   // canonical 3-symbol tail
  EXPECT_FALSE(base64url_decode("Zm9vYmF").has_value());  // 2 unused bits not zero
  EXPECT_FALSE(base64url_decode("Zm9vY").has_value());    // length 1 mod 4
}

TEST(Hash, KnownAnswers) {
  EXPECT_EQ(sha256_hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(hmac_sha256_hex("key", "The quick brown fox jumps over the lazy dog"),
            "f7bc83f430538424b13298e6aa6fb143ef4d59a14946175997479dbc2d1a3cd8");
  EXPECT_TRUE(constant_time_equal("abc", "abc"));
  EXPECT_FALSE(constant_time_equal("abc", "abd"));
  EXPECT_FALSE(constant_time_equal("abc", "ab"));
}

TEST(Errors, CatalogueStatusesFollowTheProfile) {
  EXPECT_EQ(http_status(ErrorCode::kSchemaValidationFailed), 400);
  EXPECT_EQ(http_status(ErrorCode::kInvalidRuri), 400);
  EXPECT_EQ(http_status(ErrorCode::kAuthRequired), 401);
  EXPECT_EQ(http_status(ErrorCode::kSessionExpired), 401);
  EXPECT_EQ(http_status(ErrorCode::kInsufficientPrivileges), 403);
  EXPECT_EQ(http_status(ErrorCode::kConfidenceGateFail), 403);
  EXPECT_EQ(http_status(ErrorCode::kHitlDenied), 403);
  EXPECT_EQ(http_status(ErrorCode::kMessageStale), 408);
  EXPECT_EQ(http_status(ErrorCode::kHitlTimeout), 408);
  EXPECT_EQ(http_status(ErrorCode::kReplayDetected), 409);
  EXPECT_EQ(http_status(ErrorCode::kControlConflict), 409);
  EXPECT_EQ(http_status(ErrorCode::kBodyTooLarge), 413);
  EXPECT_EQ(http_status(ErrorCode::kCommandRejected, "estop_active"), 423);
  EXPECT_EQ(http_status(ErrorCode::kCommandRejected, "prompt_injection"), 422);
  EXPECT_EQ(http_status(ErrorCode::kRateLimited), 429);
  EXPECT_EQ(http_status(ErrorCode::kSafeStop), 503);
  EXPECT_EQ(http_status(ErrorCode::kLockdown), 503);
  EXPECT_EQ(error_from_name("REPLAY_DETECTED"), ErrorCode::kReplayDetected);
  EXPECT_EQ(error_from_name("NOPE"), std::nullopt);
}

TEST(Errors, BodyShape) {
  Error e(ErrorCode::kInsufficientPrivileges, "GUEST may not use scope control", "scope");
  json::Value b = error_body(e, "0b0a6d4e-5f3c-4a2b-9c1d-2e3f4a5b6c7d", 1234);
  EXPECT_EQ(b.get("type")->as_string(), "ERROR");
  EXPECT_TRUE(is_uuid(b.get("message_id")->as_string()));
  EXPECT_EQ(b.get("reply_to")->as_string(), "0b0a6d4e-5f3c-4a2b-9c1d-2e3f4a5b6c7d");
  EXPECT_EQ(b.get("timestamp_ms")->as_int(), 1234);
  EXPECT_EQ(b.get("payload")->get("error_code")->as_string(), "INSUFFICIENT_PRIVILEGES");
  EXPECT_EQ(b.get("payload")->get("error")->as_string(), "GUEST may not use scope control");
  EXPECT_EQ(b.get("payload")->get("detail")->get("field")->as_string(), "scope");
  EXPECT_TRUE(error_body(e, "", 0).get("reply_to")->is_null());
}

TEST(Uuid, FreshV4AndValidation) {
  std::string a = new_uuid_v4(), b = new_uuid_v4();
  EXPECT_NE(a, b);
  EXPECT_TRUE(is_uuid(a));
  EXPECT_EQ(a[14], '4');
  EXPECT_TRUE(a[19] == '8' || a[19] == '9' || a[19] == 'a' || a[19] == 'b');
  EXPECT_FALSE(is_uuid("not-a-uuid"));
  EXPECT_FALSE(is_uuid("0b0a6d4e-5f3c-4a2b-9c1d-2e3f4a5b6c7"));
  EXPECT_FALSE(is_uuid("0b0a6d4e05f3c-4a2b-9c1d-2e3f4a5b6c7d"));
}

}  // namespace
}  // namespace rcan

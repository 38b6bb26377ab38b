// The registry's request bodies (src/registry/api/body.h) in-process: the reference's slugging
// and RRN pattern, field validation, the proof-of-possession string, endpoint normalisation.
#include <gtest/gtest.h>

#include "rcan/encoding.h"
#include "rcan/json.h"
#include "registry/api/address.h"
#include "registry/api/body.h"
#include "registry/api/oauth_form.h"
#include "registry/api/rate_limit.h"

namespace rcan::registry::api {
namespace {

const std::string kNow = "2026-11-27T05:20:00.000Z";

TEST(RegistryBody, SlugifyLikeTheReference) {
  EXPECT_EQ(slugify("Acme Robotics"), "acme-robotics");
  EXPECT_EQ(slugify("v2.1_beta"), "v2-1-beta");
  EXPECT_EQ(slugify("a  --  b"), "a-b");
  EXPECT_EQ(slugify("ünï"), "-n-");  // each byte outside [a-z0-9-] is one '-', runs collapse
  EXPECT_EQ(slugify(std::string(100, 'x')).size(), 64u);
  EXPECT_FALSE(usable_slug("---"));
  EXPECT_TRUE(usable_slug("-a-"));
}

TEST(RegistryBody, RrnPatternOfTheReference) {
  EXPECT_EQ(parse_rrn("RRN-000000000001")->prefix, "");
  EXPECT_EQ(parse_rrn("rrn-bd-00000001")->rrn, "RRN-BD-000000000001");  // canonical: 12 digits
  EXPECT_EQ(parse_rrn("RRN-ACME1234-0000000000000001")->prefix, "ACME1234");
  EXPECT_FALSE(parse_rrn("RRN-1234567"));             // 7 digits
  EXPECT_FALSE(parse_rrn("RRN-12345678901234567"));   // 17 digits
  EXPECT_FALSE(parse_rrn("RRN-A-00000001"));          // 1-character prefix
  EXPECT_FALSE(parse_rrn("RRN-ABCDEFGHI-00000001"));  // 9-character prefix
  EXPECT_FALSE(parse_rrn("RRN-B_D-00000001"));
  EXPECT_FALSE(parse_rrn("XRN-00000001"));
}

TEST(RegistryBody, Registration) {
  auto r = parse_registration(
      R"({"manufacturer":"Acme","model":"Arm X","version":"2","device_id":"U1","rcan_version":"3.4",
          "metadata":{"dof":6},"endpoints":["https://a.example",{"url":"wss://b.example"}]})",
      kNow);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->model, "arm-x");
  EXPECT_EQ(r->metadata_json, R"({"dof":6})");
  auto eps = json::parse(r->endpoints_json);
  ASSERT_TRUE(eps.ok());
  EXPECT_EQ(eps->as_array()[1].get("url")->as_string(), "wss://b.example");
  EXPECT_EQ(eps->as_array()[1].get("last_seen")->as_string(), kNow);
  EXPECT_EQ(proof_message("c1", "n1", r->manufacturer, r->model, r->version, r->device_id),
            "rcan-registry-pop:c1:n1:acme/arm-x/2/u1");

  EXPECT_EQ(parse_registration("[]", kNow).error().code, ErrorCode::kSchemaValidationFailed);
  EXPECT_EQ(parse_registration("{", kNow).error().code, ErrorCode::kMalformedJson);
  EXPECT_FALSE(parse_registration(R"({"manufacturer":"a","model":"b","version":"c"})", kNow).ok());
  EXPECT_FALSE(
      parse_registration(R"({"manufacturer":1,"model":"b","version":"c","device_id":"d"})", kNow)
          .ok());
  EXPECT_FALSE(
      parse_registration(
          R"({"manufacturer":"a","model":"b","version":"c","device_id":"d","metadata":[]})", kNow)
          .ok());
  EXPECT_FALSE(
      parse_registration(
          R"({"manufacturer":"a","model":"b","version":"c","device_id":"d","endpoints":["ftp://x"]})",
          kNow)
          .ok());
  EXPECT_FALSE(
      parse_registration(
          R"({"manufacturer":"a","model":"b","version":"c","device_id":"d","contact_email":"nobody"})",
          kNow)
          .ok());
  EXPECT_FALSE(
      parse_registration(
          R"({"manufacturer":"a","model":"b","version":"c","device_id":"d","ed25519_public_key":"a+b/"})",
          kNow)
          .ok());
  EXPECT_FALSE(
      parse_registration(
          R"({"manufacturer":"a","model":"b","version":"c","device_id":"d","proof":{}})", kNow)
          .ok());
}

TEST(RegistryBody, UpdateKeyAndNodeRequests) {
  auto u = parse_update(R"({"description":"x","unknown":1})", kNow);
  ASSERT_TRUE(u.ok());
  EXPECT_EQ(*u->description, "x");
  EXPECT_FALSE(u->metadata_json);
  EXPECT_TRUE(parse_update("{}", kNow)->empty());
  EXPECT_EQ(parse_key_request("{}")->role, "registrant");
  EXPECT_FALSE(parse_key_request(R"({"role":"robot"})").ok());
  auto n =
      parse_node_request(R"({"prefix":"bd","operator":"o","node_url":"https://bd.example//"})");
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(n->prefix, "BD");
  EXPECT_EQ(n->node_url, "https://bd.example");
  EXPECT_FALSE(parse_node_request(R"({"prefix":"BD","operator":"o","node_url":"http://x"})").ok());
  EXPECT_TRUE(
      parse_node_request(R"({"prefix":"BD","operator":"o","node_url":"http://x"})", true).ok());
  EXPECT_FALSE(parse_node_request(R"({"prefix":"B","operator":"o","node_url":"https://x"})").ok());
  EXPECT_FALSE(parse_node_request(R"({"prefix":"BD","node_url":"https://x"})").ok());
}

TEST(RegistryBody, WebhookSubscription) {
  auto w = parse_webhook_request(
      R"({"node_prefix":"bd","webhook_url":"https://h.example.com/x","secret":"0123456789abcdef"})");
  ASSERT_TRUE(w.ok()) << w.error().message;
  EXPECT_EQ(w->prefix, "BD");
  EXPECT_EQ(w->url, "https://h.example.com/x");
  EXPECT_TRUE(parse_webhook_request(
                  R"({"node_prefix":"RRN","webhook_url":"https://h/","secret":"0123456789abcdef"})")
                  .ok());
  const std::string http =
      R"({"node_prefix":"RRN","webhook_url":"http://h/","secret":"0123456789abcdef"})";
  EXPECT_FALSE(parse_webhook_request(http).ok());
  EXPECT_TRUE(parse_webhook_request(http, true).ok());
  for (const char* bad :
       {R"({"webhook_url":"https://h/","secret":"0123456789abcdef"})",
        R"({"node_prefix":"B","webhook_url":"https://h/","secret":"0123456789abcdef"})",
        R"({"node_prefix":"RRN","webhook_url":"https://","secret":"0123456789abcdef"})",
        R"({"node_prefix":"RRN","webhook_url":"https://h/a b","secret":"0123456789abcdef"})",
        R"({"node_prefix":"RRN","webhook_url":"https://h/\u0000","secret":"0123456789abcdef"})",
        R"({"node_prefix":"RRN","webhook_url":"https://h/","secret":"0123456789abcde"})",
        R"({"node_prefix":"RRN","webhook_url":"https://h/","secret":"0123456789abcdef\n"})",
        R"({"node_prefix":"RRN","webhook_url":"https://h/"})",
        R"({"node_prefix":"RRN","webhook_url":7,"secret":"0123456789abcdef"})", "[]", "nope"})
    EXPECT_FALSE(parse_webhook_request(bad, true).ok()) << bad;
  auto e = parse_webhook_request("{}");
  EXPECT_EQ(e.error().code, ErrorCode::kSchemaValidationFailed);
}

TEST(RegistryBody, TokenBucket) {
  RateLimiter l(BucketConfig{2, 3}, 4);
  int64_t t = 1'000'000;
  for (int i = 0; i < 3; ++i) EXPECT_EQ(l.take("k", t), 0);
  EXPECT_EQ(l.take("k", t), 1);            // empty: wait a second (rounded up)
  EXPECT_EQ(l.take("k", t + 500'000), 0);  // 2/s: one token after 0.5 s
  EXPECT_EQ(l.take("other", t), 0);        // buckets are per key
  for (int i = 0; i < 10; ++i) l.take("k" + std::to_string(i), t);  // bounded table
  EXPECT_LE(l.size(), 4u);
  EXPECT_EQ(RateLimiter(BucketConfig{0, 0}).take("x", t), 0);  // 0 = unlimited
}

// --trusted-proxy: the client is the right-most X-Forwarded-For address that is not a trusted
// proxy, and only when the peer is one.
TEST(RegistryAddress, ClientAddressBelievesXForwardedForFromTrustedProxiesOnly) {
  std::vector<Cidr> trusted{*parse_cidr("10.0.0.0/8"), *parse_cidr("fd00::/8"),
                            *parse_cidr("192.0.2.1")};
  EXPECT_EQ(client_address("203.0.113.5", {"198.51.100.1"}, trusted), "203.0.113.5");
  EXPECT_EQ(client_address("203.0.113.5", {"198.51.100.1"}, {}), "203.0.113.5");
  EXPECT_EQ(client_address("10.1.2.3", {"198.51.100.1"}, trusted), "198.51.100.1");
  EXPECT_EQ(client_address("10.1.2.3", {"6.6.6.6, 198.51.100.1"}, trusted), "198.51.100.1");
  EXPECT_EQ(client_address("10.1.2.3", {"198.51.100.1, 10.9.9.9"}, trusted), "198.51.100.1");
  EXPECT_EQ(client_address("10.1.2.3", {"6.6.6.6", "198.51.100.1"}, trusted), "198.51.100.1");
  EXPECT_EQ(client_address("192.0.2.1", {" 2001:db8::7 "}, trusted), "2001:db8::7");
  EXPECT_EQ(client_address("fd00::1", {"198.51.100.1"}, trusted), "198.51.100.1");
  // All trusted: the left-most. A hop that is no address ends the walk at the last believed.
  EXPECT_EQ(client_address("10.1.2.3", {"10.0.0.9, 10.0.0.8"}, trusted), "10.0.0.9");
  EXPECT_EQ(client_address("10.1.2.3", {"198.51.100.1, junk"}, trusted), "10.1.2.3");
  EXPECT_EQ(client_address("10.1.2.3", {"6.6.6.6, junk, 10.0.0.7"}, trusted), "10.0.0.7");
  EXPECT_EQ(client_address("10.1.2.3", {}, trusted), "10.1.2.3");
  EXPECT_EQ(client_address("::ffff:10.1.2.3", {"198.51.100.1"}, trusted), "198.51.100.1");
  EXPECT_FALSE(parse_cidr("10.0.0.0/33").ok());
  EXPECT_FALSE(parse_cidr("proxy.example").ok());
  EXPECT_FALSE(parse_cidr("10.0.0.0/").ok());
  EXPECT_FALSE(parse_cidr("fd00::/129").ok());
  EXPECT_TRUE(parse_cidr("0.0.0.0/0").ok());
}

// Webhooks go to public addresses only (--allow-private-webhooks aside).
TEST(RegistryAddress, OnlyPublicAddressesArePublic) {
  for (const char* a : {"8.8.8.8", "1.1.1.1", "203.0.114.1", "2606:4700::1111", "2001:4860::8888"})
    EXPECT_TRUE(is_public_address(*parse_ip(a))) << a;
  for (const char* a : {"127.0.0.1",
                        "127.255.0.1",
                        "10.0.0.1",
                        "172.16.0.1",
                        "172.31.255.255",
                        "192.168.1.1",
                        "169.254.169.254",
                        "100.64.0.1",
                        "100.127.255.255",
                        "0.0.0.0",
                        "224.0.0.1",
                        "255.255.255.255",
                        "240.0.0.1",
                        "192.0.2.1",
                        "198.18.0.1",
                        "::",
                        "::1",
                        "::ffff:8.8.8.8",
                        "::ffff:127.0.0.1",
                        "::127.0.0.1",
                        "64:ff9b::a00:1",
                        "2002:a00:1::",
                        "fc00::1",
                        "fd12::1",
                        "fe80::1",
                        "ff02::1",
                        "2001:db8::1",
                        "2001::1"})
    EXPECT_FALSE(is_public_address(*parse_ip(a))) << a;
  EXPECT_FALSE(parse_ip("localhost"));
  EXPECT_FALSE(parse_ip("127.1"));  // glibc's resolver takes it: the connect-time check sees it
  EXPECT_TRUE(parse_ip("[::1]"));
}

}  // namespace
}  // namespace rcan::registry::api

namespace rcan::registry::api {
namespace {

// A NUL byte in a token request (raw, or as %00) is refused: it would end the client id where a
// C string ends, so the database could look up another client than the one checked (found by
// the oauth_form fuzz target; fuzz/regressions/oauth_form/raw-nul-in-form).
TEST(OAuthForm, NulBytesAreRefusedInFormsAndBasicCredentials) {
  using namespace std::string_literals;
  ASSERT_TRUE(parse_form("grant_type=client_credentials&client_id=abc").ok());
  for (const std::string& body :
       {"client_id=abc\0x&client_secret=s"s, "a\0b=1"s, "client_secret=s\0"s}) {
    auto f = parse_form(body);
    ASSERT_FALSE(f.ok()) << body;
    EXPECT_NE(f.error().message.find("NUL"), std::string::npos) << f.error().message;
  }
  EXPECT_FALSE(parse_form("client_id=abc%00x").ok());  // percent_decode refuses an escaped NUL
  auto basic = [](const std::string& raw) {
    return parse_basic("Basic " +
                       base64_encode(reinterpret_cast<const uint8_t*>(raw.data()), raw.size()));
  };
  ASSERT_TRUE(basic("client:secret").has_value());
  EXPECT_EQ(basic("client:secret")->id, "client");
  EXPECT_FALSE(basic("cli\0ent:secret"s).has_value());
  EXPECT_FALSE(basic("client:sec\0ret"s).has_value());
  EXPECT_FALSE(basic("cli%00ent:secret").has_value());
}

}  // namespace
}  // namespace rcan::registry::api

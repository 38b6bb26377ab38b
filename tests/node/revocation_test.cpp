// The revocation list (src/node/admission/revocation.h): what its entries match, how it is
// bounded, what survives a restart, and that a bad file is a clear error — never a crash, never
// an empty list that silently accepts what was revoked.
#include "node/admission/revocation.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

#include "rcan/base/env.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "test_support.h"
#include "testing/fault_env.h"

namespace rcan::node {
namespace {

constexpr int64_t kNow = 1'800'000'000;

Principal who(const std::string& iss, const std::string& sub, const std::string& jti = "",
              const std::string& kid = "", std::optional<int64_t> iat = kNow - 10) {
  Principal p;
  p.authenticated = true;
  p.issuer = iss;
  p.sub = sub;
  p.role = Role::kUser;
  p.jti = jti;
  p.kid = kid;
  p.token_iat = iat;
  return p;
}

Revocation entry(Revocation::Kind k, const std::string& value, const std::string& iss = "",
                 std::optional<int64_t> exp = std::nullopt, int64_t at_s = kNow) {
  Revocation r;
  r.kind = k;
  r.value = value;
  r.iss = iss;
  r.exp = exp;
  r.at_ms = at_s * 1000;
  r.by = PrincipalId{"rcand-local", "local-owner"};
  return r;
}

void write(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

TEST(RevocationList, MatchesByJtiSubjectAndKidEachWithItsIssuer) {
  RevocationList list;
  EXPECT_FALSE(list.revoked(who("a", "alice", "j1", "k1")));
  ASSERT_TRUE(list.add(entry(Revocation::Kind::kJti, "j1", "a", kNow + 100), kNow).ok());
  EXPECT_EQ(list.revoked(who("a", "alice", "j1")), "jti");
  EXPECT_FALSE(list.revoked(who("b", "alice", "j1")));  // another issuer's j1
  EXPECT_FALSE(list.revoked(who("a", "alice", "j2")));

  ASSERT_TRUE(list.add(entry(Revocation::Kind::kSubject, "bob", "a"), kNow).ok());
  EXPECT_EQ(list.revoked(who("a", "bob")), "sub");
  EXPECT_EQ(list.revoked(who("a", "bob", "", "", std::nullopt)), "sub");        // no iat
  EXPECT_FALSE(list.revoked(who("b", "bob")));                                  // (issuer, subject)
  EXPECT_FALSE(list.revoked(who("a", "bob", "", "", kNow + 1)));                // minted afterwards
  ASSERT_TRUE(list.add(entry(Revocation::Kind::kSubject, "carl"), kNow).ok());  // any issuer
  EXPECT_EQ(list.revoked(who("x", "carl")), "sub");

  ASSERT_TRUE(list.add(entry(Revocation::Kind::kKid, "k1"), kNow).ok());
  EXPECT_EQ(list.revoked(who("z", "zed", "", "k1", kNow + 999)), "kid");  // whenever issued
  EXPECT_FALSE(list.revoked(who("z", "zed", "", "k2")));
  Principal anon;
  EXPECT_FALSE(list.revoked(anon));
  // The same jti or kid twice changes nothing.
  EXPECT_FALSE(*list.add(entry(Revocation::Kind::kKid, "k1"), kNow));
  EXPECT_EQ(list.size(), 4u);
}

TEST(RevocationList, IsBoundedAndDropsJtiEntriesOnceTheirTokenHasExpired) {
  RevocationList list({}, 3, 60);
  ASSERT_TRUE(*list.add(entry(Revocation::Kind::kJti, "j1", "a", kNow + 10), kNow));
  ASSERT_TRUE(*list.add(entry(Revocation::Kind::kJti, "j2", "a", kNow + 1000), kNow));
  ASSERT_TRUE(*list.add(entry(Revocation::Kind::kSubject, "s"), kNow));
  auto full = list.add(entry(Revocation::Kind::kJti, "j3", "a", kNow + 1000), kNow);
  ASSERT_FALSE(full.ok());
  EXPECT_EQ(full.error().reason, "revocation_list_full");
  EXPECT_FALSE(list.revoked(who("a", "u", "j3")));
  // j1's token has expired (plus the leeway): its place is free.
  ASSERT_TRUE(*list.add(entry(Revocation::Kind::kJti, "j3", "a", kNow + 1000), kNow + 71));
  EXPECT_EQ(list.size(), 3u);
  EXPECT_FALSE(list.revoked(who("a", "u", "j1")));
  EXPECT_TRUE(list.revoked(who("a", "u", "j3")));
  // A token that has already expired needs no entry.
  EXPECT_FALSE(*list.add(entry(Revocation::Kind::kJti, "old", "a", kNow - 1000), kNow));
}

TEST(RevocationList, PersistsWithMode0600AndLoadsBackDroppingExpiredJtis) {
  test::TempDir dir;
  const std::string path = dir.file("revocations.json");
  {
    RevocationList list(path);
    ASSERT_TRUE(list.load(kNow).ok());  // absent: empty
    EXPECT_EQ(list.size(), 0u);
    ASSERT_TRUE(*list.add(entry(Revocation::Kind::kJti, "j1", "a", kNow + 100), kNow));
    Revocation r = entry(Revocation::Kind::kKid, "k1");
    r.reason = "key leaked";
    ASSERT_TRUE(*list.add(r, kNow));
  }
  struct stat st {};
  ASSERT_EQ(::stat((path + ".journal").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  RevocationList back(path);
  ASSERT_TRUE(back.load(kNow).ok());
  ASSERT_EQ(::stat(path.c_str(), &st), 0);  // the start folded the journal into the snapshot
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back.list()[1].reason, "key leaked");
  EXPECT_EQ(back.list()[1].by.sub, "local-owner");
  EXPECT_TRUE(back.revoked(who("a", "u", "j1")));
  RevocationList later(path);
  ASSERT_TRUE(later.load(kNow + 1000).ok());
  EXPECT_EQ(later.size(), 1u);  // j1's token has expired since
  EXPECT_FALSE(later.revoked(who("a", "u", "j1")));
  EXPECT_TRUE(later.revoked(who("a", "u", "", "k1")));
}

TEST(RevocationList, BadFileContentIsAClearErrorAndChangesNothing) {
  test::TempDir dir;
  const std::string path = dir.file("revocations.json");
  const char* bad[] = {
      "",
      "not json",
      "[]",
      R"({"revocations":[]})",
      R"({"version":2,"revocations":[]})",
      R"({"version":1,"revocations":{}})",
      R"({"version":1,"revocations":[7]})",
      R"({"version":1,"revocations":[{"kind":"jti"}]})",
      R"({"version":1,"revocations":[{"kind":"jti","jti":""}]})",
      R"({"version":1,"revocations":[{"kind":"who","who":"x"}]})",
      R"({"version":1,"revocations":[{"kind":"sub","sub":"x","exp":"soon"}]})",
      R"({"version":1,"revocations":[{"kind":"kid","kid":"x","by":"me"}]})",
      R"({"version":1,"revocations":[{"kind":"kid","kid":["x"]}]})",
  };
  for (const char* text : bad) {
    write(path, text);
    RevocationList fresh(path);
    Status s = fresh.load(kNow);
    ASSERT_FALSE(s.ok()) << text;
    EXPECT_EQ(s.error().code, ErrorCode::kSchemaValidationFailed) << text;
    EXPECT_NE(s.error().message.find(path), std::string::npos) << s.error().message;
    EXPECT_EQ(fresh.size(), 0u);
  }
  // More entries than the list may hold.
  std::string many = R"({"version":1,"revocations":[)";
  for (int i = 0; i < 5; ++i)
    many += std::string(i ? "," : "") + R"({"kind":"kid","kid":"k)" + std::to_string(i) + "\"}";
  write(path, many + "]}");
  RevocationList small(path, 4);
  EXPECT_FALSE(small.load(kNow).ok());
  RevocationList big(path, 5);
  EXPECT_TRUE(big.load(kNow).ok());
}

TEST(RevocationList, AnEntryTheFileCouldNotHoldIsNotInForce) {
  test::TempDir dir;
  base::FaultInjectionEnv env(base::Env::posix());
  RevocationList list(dir.file("revocations.json"), RevocationList::kDefaultCapacity, 60, &env);
  int heard = 0;
  list.subscribe([&](const Revocation&) { ++heard; });
  env.fail_after(1);
  auto r = list.add(entry(Revocation::Kind::kSubject, "bob"), kNow);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kInternal);
  EXPECT_FALSE(list.revoked(who("a", "bob")));
  EXPECT_EQ(heard, 0);
  env.fail_after(0);
  ASSERT_TRUE(*list.add(entry(Revocation::Kind::kSubject, "bob"), kNow));
  EXPECT_TRUE(list.revoked(who("a", "bob")));
  EXPECT_EQ(heard, 1);
}

// docs/THREATS.md T4: an entry is one appended line, not a rewrite of the whole list (a flood
// of a registry's feed cost every trusting robot a rewrite and an fsync of the list per entry).
TEST(RevocationList, AnEntryIsAppendedToTheJournalAndTheStartFoldsItIn) {
  test::TempDir dir;
  const std::string path = dir.file("revocations.json");
  RevocationList list(path);
  ASSERT_TRUE(list.load(kNow).ok());
  for (int i = 0; i < 50; ++i)
    ASSERT_TRUE(
        *list.add(entry(Revocation::Kind::kJti, "j" + std::to_string(i), "a", kNow + 100), kNow));
  EXPECT_FALSE(std::filesystem::exists(path));  // no rewrite of a snapshot per entry
  const std::string journal = test::read_file(path + ".journal");
  EXPECT_EQ(std::count(journal.begin(), journal.end(), '\n'), 50);
  // A crash during the 51st append leaves part of its line: never acknowledged, dropped.
  { std::ofstream(path + ".journal", std::ios::app) << R"({"kind":"jti","jti":"j5)"; }
  RevocationList back(path);
  ASSERT_TRUE(back.load(kNow).ok());
  EXPECT_EQ(back.size(), 50u);
  EXPECT_TRUE(back.revoked(who("a", "u", "j49")));
  EXPECT_EQ(std::filesystem::file_size(path + ".journal"), 0u);
  EXPECT_TRUE(std::filesystem::exists(path));
  ASSERT_TRUE(*back.add(entry(Revocation::Kind::kSubject, "bob"), kNow));
  RevocationList again(path);
  ASSERT_TRUE(again.load(kNow).ok());
  EXPECT_EQ(again.size(), 51u);
  // A complete line that does not parse is damage, not a torn append: the start refuses.
  { std::ofstream(path + ".journal", std::ios::app) << "{\"kind\":\"who\"}\n"; }
  RevocationList damaged(path);
  Status s = damaged.load(kNow);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("line 1"), std::string::npos) << s.error().message;
}

// A crash between a fold's snapshot and its emptying of the journal leaves entries in both; a
// list written before the feed had its own table holds the registry's entries as its own.
TEST(RevocationList, AnEntryInTheSnapshotAndTheJournalCountsOnceAndOldFeedEntriesAreTheFeeds) {
  test::TempDir dir;
  const std::string path = dir.file("revocations.json");
  Revocation a = entry(Revocation::Kind::kKid, "k1");
  Revocation reg = entry(Revocation::Kind::kJti, "r1", "https://reg", kNow + 1000);
  reg.by = PrincipalId{"https://reg", "registry"};
  reg.reason = "registry revocation 7";
  json::Array snap{a.to_json(), reg.to_json()};
  write(path, json::dump(json::Value(json::Object{{"version", 1}, {"revocations", snap}})));
  write(path + ".journal", json::dump(a.to_json()) + "\n" +
                               json::dump(entry(Revocation::Kind::kKid, "k2").to_json()) + "\n");
  // Room for two entries of the node's own: k1 twice would not fit, nor the registry's r1.
  RevocationList list(path, 2, 60, nullptr, 1);
  ASSERT_TRUE(list.load(kNow).ok());
  EXPECT_EQ(list.size(), 3u);
  EXPECT_TRUE(list.revoked(who("https://reg", "u", "r1")));
  const auto all = list.list();
  EXPECT_EQ(std::count_if(all.begin(), all.end(), [](const Revocation& r) { return r.feed; }), 1);
}

TEST(RevocationList, TheJournalIsFoldedInEveryCompactEveryEntries) {
  test::TempDir dir;
  const std::string path = dir.file("revocations.json");
  RevocationList list(path, 5000);
  for (size_t i = 0; i < RevocationList::kCompactEvery + 3; ++i)
    ASSERT_TRUE(*list.add(entry(Revocation::Kind::kKid, "k" + std::to_string(i)), kNow));
  const std::string journal = test::read_file(path + ".journal");
  EXPECT_EQ(std::count(journal.begin(), journal.end(), '\n'), 3);
  RevocationList back(path, 5000);
  ASSERT_TRUE(back.load(kNow).ok());
  EXPECT_EQ(back.size(), RevocationList::kCompactEvery + 3);
}

// The OWNER's entries and those of a registry's feed are bounded apart: a full feed table
// refuses only feed entries (revocation_feed_full), and the OWNER still revokes.
TEST(RevocationList, FeedEntriesHaveATableOfTheirOwn) {
  RevocationList list({}, 2, 60, nullptr, 3);
  auto feed = [](const std::string& jti, int64_t exp = kNow + 1000) {
    Revocation r = entry(Revocation::Kind::kJti, jti, "reg", exp);
    r.feed = true;
    return r;
  };
  for (const char* j : {"f1", "f2", "f3"}) ASSERT_TRUE(*list.add(feed(j), kNow));
  auto full = list.add(feed("f4"), kNow);
  ASSERT_FALSE(full.ok());
  EXPECT_EQ(full.error().reason, "revocation_feed_full");
  ASSERT_TRUE(*list.add(entry(Revocation::Kind::kSubject, "mallory"), kNow));
  ASSERT_TRUE(*list.add(entry(Revocation::Kind::kKid, "k1"), kNow));
  auto own_full = list.add(entry(Revocation::Kind::kKid, "k2"), kNow);
  ASSERT_FALSE(own_full.ok());
  EXPECT_EQ(own_full.error().reason, "revocation_list_full");
  // Expired feed entries make room for new ones.
  ASSERT_TRUE(*list.add(feed("f5", kNow + 5000), kNow + 1061));
  // The source survives the file.
  EXPECT_TRUE(Revocation::from_json(feed("x").to_json())->feed);
  EXPECT_FALSE(Revocation::from_json(entry(Revocation::Kind::kSubject, "y").to_json())->feed);
}

}  // namespace
}  // namespace rcan::node

// Token revocation against a real rcand (docs/SECURITY.md R7): the OWNER revokes a USER token
// over HTTP and with the CLI; the token is then refused on HTTP, and a stream it opened is
// closed at once; the revocation survives a restart; revocation by subject and by issuer key id;
// nobody below OWNER revokes; the owner token rcand writes carries a jti and lives a day.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "rcan/crypto/jwt.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "rcand_daemon.h"
#include "test_support.h"

namespace rcan {
namespace {

using test::HttpReply;
using Headers = std::vector<std::pair<std::string, std::string>>;

int64_t now_s() {
  return std::chrono::duration_cast<std::chrono::seconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

Headers bearer(const std::string& token) { return {{"Authorization", "Bearer " + token}}; }

json::Value parse(const std::string& s) {
  auto v = json::parse(s);
  return v.ok() ? *v : json::Value();
}

std::string trimmed(std::string t) {
  while (!t.empty() && (t.back() == '\n' || t.back() == '\r')) t.pop_back();
  return t;
}

std::string payload_str(const std::string& body, const char* key) {
  const json::Value v = parse(body);
  const json::Value* p = v.is_object() ? v.get("payload") : nullptr;
  const json::Value* f = p && p->is_object() ? p->get(key) : nullptr;
  return f && f->is_string() ? f->as_string() : "";
}

int64_t count_of(const std::string& body) {
  const json::Value v = parse(body);
  const json::Value* c = v.is_object() ? v.get("count") : nullptr;
  return c && c->is_int() ? c->as_int() : -1;
}

std::string write_file(const std::string& path, const std::string& text) {
  {
    std::ofstream out(path);
    out << text << "\n";
  }
  ::chmod(path.c_str(), 0600);
  return path;
}

// A token from the robot's local issuer with a jti (and a header kid when given).
std::string mint(const test::RcandDaemon& d, const std::string& role, const std::string& sub,
                 const std::string& kid = "", int64_t iat = 0) {
  auto key = jwt::SigningKey::from_file(d.dir() + "/issuer/ed25519.seed");
  EXPECT_TRUE(key.ok());
  if (iat == 0) iat = now_s() - 5;
  json::Object claims{{"iss", "rcand-local"},
                      {"sub", sub},
                      {"aud", d.ruri()},
                      {"role", role},
                      {"scope", json::Array{"status", "control", "chat"}},
                      {"jti", new_uuid_v4()},
                      {"iat", iat},
                      {"exp", now_s() + 3600}};
  auto t = jwt::issue(claims, *key, kid);
  EXPECT_TRUE(t.ok());
  return t.ok() ? *t : "";
}

// A request that needs a verified token of any role: 200 while the token is good.
HttpReply queue(const test::RcandDaemon& d, const std::string& token) {
  return test::http(d.port(), "GET", "/rcan/v1/auth/queue", "", bearer(token));
}

HttpReply revoke(const test::RcandDaemon& d, const std::string& by, const json::Object& body) {
  return test::http(d.port(), "POST", "/rcan/v1/revocations", json::dump(json::Value(body)),
                    bearer(by));
}

void expect_revoked(const HttpReply& r) {
  EXPECT_EQ(r.status, 401) << r.body;
  EXPECT_EQ(payload_str(r.body, "error_code"), "AUTH_INVALID") << r.body;
  EXPECT_EQ(payload_str(r.body, "reason"), "token_revoked") << r.body;
}

bool connect_stream(test::WsClient& ws, uint16_t port, const std::string& token) {
  if (ws.connect(port, "/rcan/v1/stream") != 101) return false;
  ws.send_text(json::dump(json::Value(json::Object{{"type", "CONNECT"}, {"token", token}})));
  auto ack = ws.recv_text(5000);
  return ack && ack->find("CONNECT_ACK") != std::string::npos;
}

// The stream's frames up to the ERROR that says its token was revoked (events may come first),
// then its close: true when that ERROR came and the stream closed 1008 within `ms`.
bool closed_as_revoked(test::WsClient& ws, int ms = 3000) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
  bool told = false;
  while (std::chrono::steady_clock::now() < until) {
    auto f = ws.recv_text(200);
    if (f && payload_str(*f, "reason") == "token_revoked") told = true;
    if (!f && ws.close_code() != 0) break;
  }
  EXPECT_TRUE(told) << "no ERROR token_revoked on the stream";
  EXPECT_EQ(ws.close_code(), 1008);
  return told && ws.close_code() == 1008;
}

TEST(Revocation, OwnerRevokesAUserTokenRefusedOnHttpStreamClosedAtOnceAndAfterRestart) {
  test::TempDir dir;
  auto d = std::make_unique<test::RcandDaemon>(dir.path() + "/node");
  ASSERT_FALSE(d->url().empty());
  const std::string owner = trimmed(test::read_file(d->owner_token_file()));
  const std::string user = mint(*d, "user", "ursula");
  const std::string other = mint(*d, "user", "ursula");  // the same principal, another jti
  ASSERT_EQ(queue(*d, user).status, 200);                // verified once: now in the token cache

  test::WsClient ws;
  ASSERT_TRUE(connect_stream(ws, d->port(), user));
  ws.send_text(R"({"type":"PING","msg_id":"p1"})");
  auto pong = ws.recv_text(5000);
  ASSERT_TRUE(pong && pong->find("PONG") != std::string::npos);

  // Below OWNER nobody revokes, not even their own token; nothing is listed either.
  HttpReply denied = revoke(*d, user, json::Object{{"token", user}});
  EXPECT_EQ(denied.status, 403) << denied.body;
  EXPECT_EQ(test::http(d->port(), "GET", "/rcan/v1/revocations", "", bearer(user)).status, 403);
  EXPECT_EQ(queue(*d, user).status, 200);

  const auto t0 = std::chrono::steady_clock::now();
  HttpReply r = revoke(*d, owner, json::Object{{"token", user}, {"reason", "laptop lost"}});
  ASSERT_EQ(r.status, 201) << r.body;
  const json::Value answer = parse(r.body);
  const json::Value* entry = answer.get("revocation");
  ASSERT_TRUE(entry && entry->is_object()) << r.body;
  EXPECT_EQ(json::dump(*entry->get("kind")), "\"jti\"") << r.body;
  EXPECT_NE(r.body.find("\"by\":{\"iss\":\"rcand-local\",\"sub\":\"local-owner\"}"),
            std::string::npos)
      << r.body;
  EXPECT_EQ(r.body.find(user), std::string::npos) << "the answer must not echo the token";

  // The open stream is told why and closed with a policy code, at once.
  EXPECT_TRUE(closed_as_revoked(ws));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(3));

  expect_revoked(queue(*d, user));          // the cached verification does not count
  EXPECT_EQ(queue(*d, other).status, 200);  // another token of the same principal
  EXPECT_EQ(queue(*d, owner).status, 200);
  test::WsClient again;
  EXPECT_FALSE(connect_stream(again, d->port(), user));
  EXPECT_EQ(revoke(*d, owner, json::Object{{"token", user}}).status, 200);  // already in force

  HttpReply list = test::http(d->port(), "GET", "/rcan/v1/revocations", "", bearer(owner));
  ASSERT_EQ(list.status, 200) << list.body;
  EXPECT_EQ(count_of(list.body), 1);
  struct stat st {};
  ASSERT_EQ(::stat((d->dir() + "/revocations.json.journal").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  const std::string audit =
      test::http(d->port(), "GET", "/api/audit?limit=200", "", bearer(owner)).body;
  EXPECT_NE(audit.find("TOKEN_REVOKED"), std::string::npos);
  EXPECT_EQ(audit.find(user), std::string::npos);

  // A restart keeps it.
  d.reset();
  d = std::make_unique<test::RcandDaemon>(dir.path() + "/node");
  ASSERT_FALSE(d->url().empty());
  expect_revoked(queue(*d, user));
  EXPECT_EQ(queue(*d, other).status, 200);
  EXPECT_EQ(queue(*d, owner).status, 200);
}

TEST(Revocation, BySubjectAndByIssuerKeyId) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_FALSE(d.url().empty());
  const std::string owner = trimmed(test::read_file(d.owner_token_file()));
  const std::string bob1 = mint(d, "user", "bob"), bob2 = mint(d, "leasee", "bob");
  const std::string carol_k = mint(d, "user", "carol", "k-2026"), carol = mint(d, "user", "carol");
  for (const auto* t : {&bob1, &bob2, &carol_k, &carol}) ASSERT_EQ(queue(d, *t).status, 200);
  test::WsClient ws;
  ASSERT_TRUE(connect_stream(ws, d.port(), bob2));

  // bob holds control; carol, same role, would only queue behind him.
  ASSERT_EQ(test::http(d.port(), "POST", "/rcan/v1/auth/claim", "{}", bearer(bob1)).status, 200);
  HttpReply r = revoke(d, owner, json::Object{{"sub", "bob"}, {"iss", "rcand-local"}});
  ASSERT_EQ(r.status, 201) << r.body;
  // A subject's revocation ends its control session: control is free for carol.
  HttpReply claimed = test::http(d.port(), "POST", "/rcan/v1/auth/claim", "{}", bearer(carol));
  EXPECT_EQ(claimed.status, 200) << claimed.body;
  EXPECT_EQ(test::http(d.port(), "DELETE", "/rcan/v1/auth/release", "", bearer(carol)).status, 200);
  expect_revoked(queue(d, bob1));
  expect_revoked(queue(d, bob2));
  EXPECT_TRUE(closed_as_revoked(ws));
  // Tokens minted for bob after the revocation are good: the owner re-admits a subject.
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  EXPECT_EQ(queue(d, mint(d, "user", "bob", "", now_s())).status, 200);

  r = revoke(d, owner, json::Object{{"kid", "k-2026"}});
  ASSERT_EQ(r.status, 201) << r.body;
  expect_revoked(queue(d, carol_k));
  expect_revoked(queue(d, mint(d, "user", "dave", "k-2026", now_s())));  // whenever issued
  EXPECT_EQ(queue(d, carol).status, 200);
  EXPECT_EQ(queue(d, owner).status, 200);

  // Requests that name nothing, or two things, are refused.
  EXPECT_EQ(revoke(d, owner, json::Object{}).status, 400);
  EXPECT_EQ(revoke(d, owner, json::Object{{"sub", "x"}, {"kid", "y"}}).status, 400);
  EXPECT_EQ(revoke(d, owner, json::Object{{"token", "not-a-jwt"}}).status, 400);
}

// A session remembers the token that claimed it: revoking that token (by jti or by its header
// kid) ends the session at once, and a queued claim made with a revoked token is dropped rather
// than promoted. Another token of the same subject, revoked, leaves the session alone.
TEST(Revocation, ATokensJtiOrKidRevocationEndsTheControlItClaimedAndItsPlaceInTheQueue) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_FALSE(d.url().empty());
  const std::string owner = trimmed(test::read_file(d.owner_token_file()));
  const std::string alice = mint(d, "user", "alice"), alice_other = mint(d, "user", "alice");
  const std::string carol = mint(d, "user", "carol"), dave = mint(d, "user", "dave", "k-dave");
  const std::string erin = mint(d, "user", "erin");
  auto claim = [&](const std::string& t) {
    return test::http(d.port(), "POST", "/rcan/v1/auth/claim", "{}", bearer(t));
  };
  auto queued = [&] {
    const json::Value v = parse(queue(d, owner).body);
    const json::Value* q = v.is_object() ? v.get("queue") : nullptr;
    std::string who;
    if (q && q->is_array())
      for (const auto& e : q->as_array())
        who += (who.empty() ? "" : ",") + e.get("user_id")->as_string();
    return who;
  };
  ASSERT_EQ(claim(alice).status, 200);
  ASSERT_EQ(claim(carol).status, 409);  // same role: queued behind alice
  ASSERT_EQ(queued(), "carol");

  // carol's token revoked by jti: her queued claim goes; she is never promoted.
  ASSERT_EQ(revoke(d, owner, json::Object{{"token", carol}}).status, 201);
  EXPECT_EQ(queued(), "");
  // Another token of alice's, revoked: the session alice's first token holds stays hers.
  ASSERT_EQ(revoke(d, owner, json::Object{{"token", alice_other}}).status, 201);
  EXPECT_EQ(claim(erin).status, 409);
  EXPECT_EQ(queued(), "erin");
  ASSERT_EQ(test::http(d.port(), "DELETE", "/rcan/v1/auth/queue", "", bearer(erin)).status, 200);
  // alice drives; the token that claimed her session, revoked by jti: the session ends now, not
  // at its deadline, and the robot stops the drive it was given.
  json::Object move{
      {"version", "1.0.0"},
      {"message_id", new_uuid_v4()},
      {"type", "COMMAND"},
      {"timestamp_ms", now_s() * 1000},
      {"payload", json::Object{{"action", "move"}, {"linear", 0.3}, {"duration_ms", 60'000}}}};
  HttpReply drive = test::http(d.port(), "POST", "/rcan/v1/command", json::dump(json::Value(move)),
                               bearer(alice));
  ASSERT_EQ(drive.status, 200) << drive.body;
  auto speed = [&] {
    const json::Value st =
        parse(test::http(d.port(), "GET", "/rcan/v1/status", "", bearer(owner)).body);
    std::string s = json::dump(st);
    const size_t at = s.find("\"linear_mps\":");
    return at == std::string::npos ? -1.0 : std::atof(s.c_str() + at + 13);
  };
  EXPECT_TRUE(test::eventually([&] { return speed() > 0.0; }, 5000)) << speed();
  auto decoded = jwt::decode(alice);
  ASSERT_TRUE(decoded.ok());
  const json::Value* jti = decoded->claims.find("jti");
  ASSERT_TRUE(jti && jti->is_string());
  ASSERT_EQ(revoke(d, owner, json::Object{{"jti", jti->as_string()}}).status, 201);
  EXPECT_TRUE(test::eventually([&] { return speed() == 0.0; }, 5000)) << speed();
  EXPECT_EQ(claim(dave).status, 200);
  // dave's token revoked by its header kid: the same.
  ASSERT_EQ(revoke(d, owner, json::Object{{"kid", "k-dave"}}).status, 201);
  EXPECT_EQ(claim(erin).status, 200);

  const std::string audit =
      test::http(d.port(), "GET", "/api/audit?limit=200", "", bearer(owner)).body;
  const json::Value records = parse(audit);
  int released = 0, dropped = 0;
  std::set<std::string> kinds;
  const json::Value* list = records.is_object() ? records.get("entries") : nullptr;
  ASSERT_TRUE(list && list->is_array()) << audit.substr(0, 400);
  for (const auto& r : list->as_array()) {
    const std::string d_json = json::dump(r);
    if (d_json.find("\"RELEASE\"") != std::string::npos &&
        d_json.find("token_revoked") != std::string::npos) {
      ++released;
      for (const char* k : {"jti", "kid"})
        if (d_json.find(std::string("\"revoked_by\":\"") + k + "\"") != std::string::npos)
          kinds.insert(k);
    }
    if (d_json.find("\"CLAIM_DROPPED\"") != std::string::npos &&
        d_json.find("token_revoked") != std::string::npos)
      ++dropped;
  }
  EXPECT_EQ(released, 2) << audit.substr(0, 2000);
  EXPECT_EQ(kinds, (std::set<std::string>{"jti", "kid"}));
  EXPECT_EQ(dropped, 1) << audit.substr(0, 2000);
}

TEST(Revocation, TheCliRevokesByTokenAndJtiAndListsWithRcanUrlAndTokenFile) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_FALSE(d.url().empty());
  const std::vector<std::string> env{"RCAN_URL=" + d.url(),
                                     "RCAN_TOKEN_FILE=" + d.owner_token_file()};
  const std::string user = mint(d, "user", "uma"), user2 = mint(d, "user", "uma2");
  ASSERT_EQ(queue(d, user).status, 200);

  auto help = test::run_cli({"token", "revoke", "--help"});
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("rcan token revoke TOKEN"), std::string::npos) << help.out;

  // A USER's token file cannot revoke.
  const std::string user_file = write_file(dir.file("user.token"), user);
  auto refused = test::run_cli({"token", "revoke", user, "--token-file", user_file}, "", env);
  EXPECT_EQ(refused.exit_code, 1) << refused.out << refused.err;
  EXPECT_EQ(queue(d, user).status, 200);

  auto ok = test::run_cli({"token", "revoke", user}, "", env);
  EXPECT_EQ(ok.exit_code, 0) << ok.out << ok.err;
  expect_revoked(queue(d, user));

  auto claims = jwt::decode(user2);
  ASSERT_TRUE(claims.ok());
  const std::string jti = claims->claims.find("jti")->as_string();
  ok = test::run_cli({"token", "revoke", "--jti", jti, "--iss", "rcand-local"}, "", env);
  EXPECT_EQ(ok.exit_code, 0) << ok.out << ok.err;
  expect_revoked(queue(d, user2));

  auto listed = test::run_cli({"token", "revocations"}, "", env);
  EXPECT_EQ(listed.exit_code, 0) << listed.err;
  EXPECT_NE(listed.out.find(jti), std::string::npos) << listed.out;
  EXPECT_EQ(count_of(listed.out), 2) << listed.out;
  EXPECT_EQ(test::run_cli({"token", "revoke"}, "", env).exit_code, 2);
  EXPECT_EQ(test::run_cli({"token", "revoke", "--sub", "a", "--kid", "b"}, "", env).exit_code, 2);
}

TEST(Revocation, OwnerTokenCarriesAJtiLivesADayAndIsRenewedOnceExpired) {
  test::TempDir dir;
  std::string first;
  {
    test::RcandDaemon d(dir.path() + "/node");
    ASSERT_FALSE(d.url().empty());
    first = trimmed(test::read_file(d.owner_token_file()));
  }
  auto tok = jwt::decode(first);
  ASSERT_TRUE(tok.ok());
  const json::Value* jti = tok->claims.find("jti");
  ASSERT_TRUE(jti && jti->is_string());
  EXPECT_TRUE(is_uuid(jti->as_string())) << jti->as_string();
  const int64_t life = tok->claims.find("exp")->as_int() - tok->claims.find("iat")->as_int();
  EXPECT_LE(life, 24 * 3600);
  EXPECT_GT(life, 3600);

  // An expired owner token is replaced at the next start (mode 0600, a new jti).
  auto key = jwt::SigningKey::from_file(dir.path() + "/node/issuer/ed25519.seed");
  ASSERT_TRUE(key.ok());
  json::Object stale = tok->claims;
  stale.set("exp", now_s() - 10);
  write_file(dir.path() + "/node/owner.token", *jwt::issue(stale, *key));
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_FALSE(d.url().empty());
  const std::string fresh = trimmed(test::read_file(d.owner_token_file()));
  auto ft = jwt::decode(fresh);
  ASSERT_TRUE(ft.ok());
  EXPECT_NE(ft->claims.find("jti")->as_string(), jti->as_string());
  EXPECT_GT(ft->claims.find("exp")->as_int(), now_s());
  EXPECT_EQ(queue(d, fresh).status, 200);
  struct stat st {};
  ASSERT_EQ(::stat(d.owner_token_file().c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
}

TEST(Revocation, AnUnreadableRevocationListStopsStartUpNamingTheFile) {
  test::TempDir dir;
  {
    test::RcandDaemon d(dir.path() + "/node");
    ASSERT_FALSE(d.url().empty());
  }
  write_file(dir.path() + "/node/revocations.json", R"({"version":1,"revocations":[{"kind":7}]})");
  test::Process p;
  ASSERT_TRUE(p.start({RCAND_PATH, "--data-dir", dir.path() + "/node", "--port", "0"}));
  auto line = p.wait_for_line("revocations.json", 15000);
  ASSERT_TRUE(line.has_value()) << p.err();
  EXPECT_NE(line->find("unreadable"), std::string::npos) << *line;
  p.stop(SIGTERM, 10000);
  EXPECT_EQ(p.err().find("\"event\":\"listening\""), std::string::npos) << p.err();
}

}  // namespace
}  // namespace rcan

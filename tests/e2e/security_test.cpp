// The security checklist (docs/SECURITY.md) against real daemons: no open mode, no default or
// shared secrets, private file modes, no token in logs, audit files, HTML, error bodies or URLs,
// no CORS, signatures verified or refused, and no caller credential in anything the node sends
// to others (brain layers, HiTL webhooks, other principals' streams). Each test starts its own
// rcand (RCAND_PATH) with a fresh data directory and talks to it over loopback.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <thread>

#include "ai_test_support.h"
#include "node/api/web_assets.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/encoding.h"
#include "rcan/json.h"
#include "rcand_daemon.h"
#include "test_support.h"

namespace rcan {
namespace {

namespace fs = std::filesystem;
using test::HttpReply;
using Headers = std::vector<std::pair<std::string, std::string>>;

int64_t now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string trim(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  return s;
}

std::string slurp(const std::string& path) { return test::read_file(path); }

// Every regular file under `dir`, concatenated (audit segments, state files, …).
std::string slurp_tree(const std::string& dir) {
  std::string all;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->is_regular_file()) all += slurp(it->path().string());
  return all;
}

std::string cmd_json(const std::string& id, const std::string& action,
                     const std::string& extra_payload = "", const std::string& extra_top = "") {
  return R"({"version":"1.0.0","message_id":")" + id + R"(","type":"COMMAND","timestamp_ms":)" +
         std::to_string(now_ms()) + R"(,"payload":{"action":")" + action + "\"" + extra_payload +
         "}" + extra_top + "}";
}

std::string code_of(const HttpReply& r) {
  auto v = json::parse(r.body);
  if (!v.ok() || !v->is_object()) return "";
  const json::Value* p = v->get("payload");
  const json::Value* c = p && p->is_object() ? p->get("error_code") : nullptr;
  return c && c->is_string() ? c->as_string() : "";
}

// The parts of a JWT worth looking for: the whole token and its signature segment.
std::vector<std::string> token_needles(const std::string& token) {
  std::vector<std::string> n{token};
  size_t dot = token.rfind('.');
  if (dot != std::string::npos && token.size() - dot > 20) n.push_back(token.substr(dot + 1));
  return n;
}

// Where `haystack` contains any needle of `token`: "" when none.
std::string leak_of(const std::string& haystack, const std::string& token) {
  for (const auto& n : token_needles(token))
    if (!n.empty() && haystack.find(n) != std::string::npos) return n.substr(0, 24) + "…";
  return "";
}

Headers bearer(const std::string& token) { return {{"Authorization", "Bearer " + token}}; }

// A token signed by a key the node has never seen, claiming its local issuer's name.
std::string forged_token(const std::string& ruri) {
  Bytes seed = ed25519::random_seed();
  auto key = jwt::SigningKey::ed25519_seed(seed);
  EXPECT_TRUE(key.ok());
  int64_t now = now_ms() / 1000;
  auto t = jwt::issue(json::Object{{"iss", "rcand-local"},
                                   {"sub", "mallory"},
                                   {"aud", ruri},
                                   {"role", "creator"},
                                   {"scope", json::Array{"status", "control", "config"}},
                                   {"iat", now},
                                   {"exp", now + 600}},
                      *key);
  EXPECT_TRUE(t.ok());
  return t.ok() ? *t : "";
}

std::string b64url(const std::string& s) {
  return base64url_encode(reinterpret_cast<const uint8_t*>(s.data()), s.size(), false);
}

// ---------------------------------------------------------------------------------------------
// 1. No open mode.

TEST(Security, NoOpenModeEveryRouteThatActsOrRevealsNeedsAVerifiedToken) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_NE(d.port(), 0);
  const std::string forged = forged_token(d.ruri());
  const std::string good = d.token("owner", {"status", "control", "config"}, "owner-1");
  // alg "none" with the claims of an OWNER.
  const std::string none_tok = b64url(R"({"alg":"none","typ":"JWT"})") + "." +
                               b64url(R"({"iss":"rcand-local","sub":"x","aud":")" + d.ruri() +
                                      R"(","role":"owner","scope":["control"],"exp":)" +
                                      std::to_string(now_ms() / 1000 + 600) + "}") +
                               ".";
  struct Route {
    const char* method;
    std::string path;
    std::function<std::string()> body;  // fresh ids each time (the replay stage runs first)
  };
  auto none = [] { return std::string(); };
  auto move = [] { return cmd_json(new_uuid_v4(), "move", R"(,"linear":0.2,"duration_ms":100)"); };
  const std::vector<Route> routes{
      {"POST", "/rcan/v1/command", move},
      {"POST", "/api/command", move},
      {"POST", "/api/stop", [] { return std::string("{}"); }},
      {"POST", "/rcan/v1/auth/claim", [] { return std::string("{}"); }},
      {"GET", "/api/audit", none},
      {"GET", "/api/v1/audit?format=jsonl", none},
      {"POST", "/rcan/v1/authorize",
       [] {
         return R"({"type":"AUTHORIZE","message_id":")" + new_uuid_v4() +
                R"(","payload":{"message_id":"x","decision":"approve"}})";
       }},
      {"GET", "/rcan/v1/pending", none},
      {"GET", "/api/thoughts/th_1", none},
  };
  for (const auto& r : routes) {
    for (const std::string& tok : {std::string(), forged, none_tok, std::string("not-a-jwt")}) {
      HttpReply a =
          test::http(d.port(), r.method, r.path, r.body(), tok.empty() ? Headers{} : bearer(tok));
      EXPECT_EQ(a.status, 401) << r.method << " " << r.path << " token " << tok.substr(0, 16)
                               << ": " << a.body;
      EXPECT_TRUE(code_of(a) == "AUTH_REQUIRED" || code_of(a) == "AUTH_INVALID")
          << r.method << " " << r.path << ": " << a.body;
    }
  }
  // The body's auth_token is a token like any other: a forged one is refused too.
  HttpReply body_forged =
      test::http(d.port(), "POST", "/rcan/v1/command",
                 cmd_json(new_uuid_v4(), "status", "", R"(,"auth_token":")" + forged + "\""));
  EXPECT_EQ(body_forged.status, 401) << body_forged.body;
  // Streams: no CONNECT token, a forged one, and the v1.1 telemetry socket without a token.
  for (const std::string& tok : {std::string(), forged}) {
    test::WsClient ws;
    ASSERT_EQ(ws.connect(d.port(), "/rcan/v1/stream"), 101);
    ws.send_text(R"({"type":"CONNECT","token":")" + tok + "\"}");
    auto f = ws.recv_text(5000);
    ASSERT_TRUE(f.has_value());
    EXPECT_NE(f->find("ConnectionRefused"), std::string::npos) << *f;
    EXPECT_FALSE(ws.recv_text(3000).has_value());
    EXPECT_EQ(ws.close_code(), 4001);
  }
  test::WsClient tel;
  EXPECT_EQ(tel.connect(d.port(), "/ws/telemetry"), 401);
  // Nothing above moved the robot or reached the audit log as a dispatched command.
  HttpReply audit = test::http(d.port(), "GET", "/api/audit?limit=1000", "", bearer(good));
  ASSERT_EQ(audit.status, 200) << audit.body;
  auto v = json::parse(audit.body, {.max_depth = 64, .max_bytes = 64u << 20});
  ASSERT_TRUE(v.ok());
  for (const auto& e : v->get("entries")->as_array()) {
    const json::Value* outcome = e.get("outcome");
    const json::Value* event = e.get("event");
    if (event && event->as_string() == "COMMAND") {
      EXPECT_NE(outcome->as_string(), "ok") << json::dump(e);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// 2. No default secrets; secrets are private; a loosened secret stops start-up.

TEST(Security, EveryNodeGeneratesItsOwnSecretsPrivateAndNotCompiledIn) {
  test::TempDir dir;
  std::string a_dir = dir.path() + "/a", b_dir = dir.path() + "/b";
  std::string a_owner, a_ruri;
  {
    test::RcandDaemon a(a_dir);
    test::RcandDaemon b(b_dir);
    ASSERT_NE(a.port(), 0);
    ASSERT_NE(b.port(), 0);
    a_owner = trim(slurp(a_dir + "/owner.token"));
    a_ruri = a.ruri();
    // Node A's OWNER token means nothing to node B, although both name their issuer rcand-local.
    HttpReply r = test::http(b.port(), "GET", "/api/audit", "", bearer(a_owner));
    EXPECT_EQ(r.status, 401) << r.body;
    // Even with B's audience, a token signed by A's issuer is refused by B.
    auto a_key = jwt::SigningKey::from_file(a_dir + "/issuer/ed25519.seed");
    ASSERT_TRUE(a_key.ok());
    int64_t now = now_ms() / 1000;
    auto cross = jwt::issue(json::Object{{"iss", "rcand-local"},
                                         {"sub", "x"},
                                         {"aud", b.ruri()},
                                         {"role", "owner"},
                                         {"scope", json::Array{"status"}},
                                         {"iat", now},
                                         {"exp", now + 600}},
                            *a_key);
    ASSERT_TRUE(cross.ok());
    EXPECT_EQ(test::http(b.port(), "GET", "/api/audit", "", bearer(*cross)).status, 401);
  }
  const std::string rcand_binary = slurp(RCAND_PATH);
  ASSERT_GT(rcand_binary.size(), 100000u);
  std::vector<std::string> secrets{"audit.secret", "issuer/ed25519.seed", "owner.token"};
  for (const auto& e : fs::directory_iterator(a_dir + "/keys")) {
    std::string name = e.path().filename().string();
    if (name.find(".pub") == std::string::npos) secrets.push_back("keys/" + name);
  }
  ASSERT_GE(secrets.size(), 4u) << "no key files under keys/";
  for (const auto& s : secrets) {
    std::string a_bytes = slurp(a_dir + "/" + s), b_bytes = slurp(b_dir + "/" + s);
    ASSERT_GE(a_bytes.size(), 16u) << s;
    EXPECT_NE(a_bytes, b_bytes) << s << " is the same on two fresh nodes";
    // Not a compiled-in value (raw bytes, or as hex).
    EXPECT_EQ(rcand_binary.find(a_bytes), std::string::npos) << s << " appears in the rcand binary";
    EXPECT_EQ(rcand_binary.find(to_hex(reinterpret_cast<const uint8_t*>(a_bytes.data()),
                                       std::min<size_t>(a_bytes.size(), 32))),
              std::string::npos)
        << s;
    // Not a degenerate value.
    EXPECT_NE(a_bytes.find_first_not_of(a_bytes[0]), std::string::npos)
        << s << " is one repeated byte";
    // Mode 0600: nothing for group or others.
    struct stat st {};
    ASSERT_EQ(::stat((a_dir + "/" + s).c_str(), &st), 0) << s;
    EXPECT_EQ(st.st_mode & 077, 0u) << s << " mode " << std::oct << (st.st_mode & 0777);
  }
  for (const std::string& d : {a_dir, a_dir + "/keys", a_dir + "/issuer"}) {
    struct stat st {};
    ASSERT_EQ(::stat(d.c_str(), &st), 0) << d;
    EXPECT_EQ(st.st_mode & 077, 0u) << d << " mode " << std::oct << (st.st_mode & 0777);
  }
  // A secret that became readable by others stops start-up, naming the file; so does a
  // world-readable issuer seed.
  for (const std::string& s : {std::string("audit.secret"), std::string("issuer/ed25519.seed")}) {
    fs::permissions(a_dir + "/" + s, fs::perms::owner_read | fs::perms::owner_write |
                                         fs::perms::group_read | fs::perms::others_read);
    test::Process p;
    ASSERT_TRUE(p.start({RCAND_PATH, "--data-dir", a_dir, "--port", "0"}));
    EXPECT_EQ(p.stop(0, 15000), 1) << s << ":\n" << p.err();
    EXPECT_NE(p.err().find(s.substr(s.rfind('/') + 1)), std::string::npos) << p.err();
    EXPECT_EQ(p.err().find("\"event\":\"listening\""), std::string::npos) << p.err();
    fs::permissions(a_dir + "/" + s, fs::perms::owner_read | fs::perms::owner_write);
  }
}

// ---------------------------------------------------------------------------------------------
// 3. No token in logs, audit files, error bodies; none accepted from a URL.

TEST(Security, TokensNeverReachTheLogTheAuditFilesOrErrorBodiesAndAreNotTakenFromUrls) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node", {"--log-level", "debug"});
  ASSERT_NE(d.port(), 0);
  const std::string owner = trim(slurp(d.owner_token_file()));
  const std::string header_tok = d.token("owner", {"status", "control", "config"}, "header-user");
  const std::string body_tok = d.token("user", {"status", "control"}, "body-user");
  const std::string ws_tok = d.token("user", {"status", "control"}, "ws-user");
  const std::string query_tok = d.token("owner", {"status", "control", "config"}, "query-user");
  const std::string url_ws_tok = d.token("user", {"status"}, "url-ws-user");
  // A token with a valid shape but a broken signature (one character changed).
  std::string broken = d.token("owner", {"status", "control"}, "broken-user");
  broken[broken.size() - 5] = broken[broken.size() - 5] == 'A' ? 'B' : 'A';
  std::vector<std::string> bodies;
  auto keep = [&](const HttpReply& r) {
    bodies.push_back(r.body);
    return r;
  };

  EXPECT_EQ(keep(test::http(d.port(), "POST", "/rcan/v1/command",
                            cmd_json(new_uuid_v4(), "move", R"(,"linear":0.1,"duration_ms":100)"),
                            bearer(header_tok)))
                .status,
            200);
  EXPECT_EQ(keep(test::http(
                     d.port(), "POST", "/rcan/v1/command",
                     cmd_json(new_uuid_v4(), "status", "", R"(,"auth_token":")" + body_tok + "\"")))
                .status,
            200);
  EXPECT_EQ(keep(test::http(d.port(), "POST", "/rcan/v1/command", cmd_json(new_uuid_v4(), "status"),
                            bearer(broken)))
                .status,
            401);
  EXPECT_EQ(keep(test::http(d.port(), "GET", "/rcan/v1/status", "", bearer(broken))).status, 401);
  // A bad message with a good token: the error names the problem, not the token.
  EXPECT_EQ(keep(test::http(d.port(), "POST", "/rcan/v1/command",
                            R"({"type":"COMMAND","payload":{"action":7}})", bearer(header_tok)))
                    .status /
                100,
            4);
  // A token in the query string is not a credential for HTTP routes.
  HttpReply q = keep(test::http(d.port(), "GET", "/api/audit?token=" + query_tok));
  EXPECT_EQ(q.status, 401) << q.body;
  HttpReply q2 = keep(test::http(d.port(), "POST", "/rcan/v1/command?token=" + query_tok,
                                 cmd_json(new_uuid_v4(), "status")));
  EXPECT_EQ(q2.status, 401) << q2.body;
  // The stream's CONNECT token, a refused CONNECT token and the v1.1 telemetry socket's query
  // token.
  {
    test::WsClient ws;
    ASSERT_EQ(ws.connect(d.port(), "/rcan/v1/stream"), 101);
    ws.send_text(R"({"type":"CONNECT","token":")" + ws_tok + "\"}");
    auto ack = ws.recv_text(5000);
    ASSERT_TRUE(ack && ack->find("CONNECT_ACK") != std::string::npos);
    std::string id = new_uuid_v4();
    ws.send_text(cmd_json(id, "status"));
    auto f = ai_test::wait_frame(ws, "", id);
    ASSERT_TRUE(f.has_value());
    bodies.push_back(json::dump(*f));
  }
  {
    test::WsClient ws;
    ASSERT_EQ(ws.connect(d.port(), "/rcan/v1/stream"), 101);
    ws.send_text(R"({"type":"CONNECT","token":")" + broken + "\"}");
    auto refused = ws.recv_text(5000);
    ASSERT_TRUE(refused.has_value());
    bodies.push_back(*refused);
  }
  {
    test::WsClient ws;
    EXPECT_EQ(ws.connect(d.port(), "/ws/telemetry?token=" + url_ws_tok), 101);
  }
  {
    test::WsClient ws;
    EXPECT_EQ(ws.connect(d.port(), "/ws/telemetry?token=" + broken), 401);
  }
  // The audit export as the owner sees it.
  HttpReply exported = test::http(d.port(), "GET", "/api/v1/audit?format=jsonl", "", bearer(owner));
  ASSERT_EQ(exported.status, 200) << exported.body;
  EXPECT_NE(exported.body.find("header-user"), std::string::npos)
      << "the export does not show the callers";
  EXPECT_NE(exported.body.find("body-user"), std::string::npos);
  EXPECT_NE(exported.body.find("ws-user"), std::string::npos);

  ASSERT_EQ(d.proc().stop(SIGTERM, 15000), 0);
  const std::string log = d.proc().err();
  ASSERT_NE(log.find("http.request"), std::string::npos) << "debug request logging was not on";
  const std::string files = slurp_tree(dir.path() + "/node/audit");
  ASSERT_FALSE(files.empty());
  std::string all_bodies;
  for (auto& b : bodies) all_bodies += b + "\n";
  for (const std::string& t :
       {owner, header_tok, body_tok, ws_tok, query_tok, url_ws_tok, broken}) {
    EXPECT_EQ(leak_of(log, t), "") << "a token in rcand's log";
    EXPECT_EQ(leak_of(files, t), "") << "a token in the audit files";
    EXPECT_EQ(leak_of(exported.body, t), "") << "a token in the audit export";
    EXPECT_EQ(leak_of(all_bodies, t), "") << "a token echoed in an answer";
  }
  // The start-up banner names the token file, never the token.
  EXPECT_NE(log.find("owner.token"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// 4. The dashboard: no token or secret in what it serves; tokens only in headers; no CORS.

TEST(Security, DashboardCarriesNoTokenOrSecretAndTheNodeSendsNoCorsGrant) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_NE(d.port(), 0);
  const std::string owner = trim(slurp(d.owner_token_file()));
  const std::string secret = slurp(dir.path() + "/node/audit.secret");
  const std::string seed_hex = [&] {
    std::string s = slurp(dir.path() + "/node/issuer/ed25519.seed");
    return to_hex(reinterpret_cast<const uint8_t*>(s.data()), s.size());
  }();
  std::vector<std::string> paths{"/", "/index.html"};
  for (const auto& a : node::web_assets()) paths.push_back(std::string("/ui") + a.path);
  ASSERT_GT(paths.size(), 4u);
  std::string scripts;
  for (const auto& p : paths) {
    // Fetched with and without the owner's token: the page is the same static file.
    for (bool with : {false, true}) {
      HttpReply r = test::http(d.port(), "GET", p, "", with ? bearer(owner) : Headers{});
      ASSERT_EQ(r.status, 200) << p;
      EXPECT_EQ(leak_of(r.body, owner), "") << p;
      EXPECT_EQ(r.body.find(secret), std::string::npos) << p;
      EXPECT_EQ(r.body.find(seed_hex), std::string::npos) << p;
      EXPECT_EQ(r.header("set-cookie"), "") << p;
      if (!with && p.size() > 3 && p.substr(p.size() - 3) == ".js") scripts += r.body + "\n";
    }
  }
  // The page keeps the token out of URLs, cookies and localStorage: the only query carrying a
  // `token` parameter is the public watermark lookup (a watermark, not a credential). What
  // localStorage holds is the approvals' two on/off preferences: its one write stores 'on' or
  // 'off', whatever the key.
  auto count = [&](const std::string& needle) {
    size_t n = 0;
    for (size_t at = scripts.find(needle); at != std::string::npos;
         at = scripts.find(needle, at + 1))
      ++n;
    return n;
  };
  EXPECT_EQ(count("localStorage.setItem("), 1u);
  EXPECT_EQ(count("localStorage.setItem(key, on ? 'on' : 'off')"), 1u);
  EXPECT_EQ(count("localStorage."),
            count("localStorage.setItem(") + count("localStorage.getItem("));
  EXPECT_EQ(count("localStorage["), 0u);
  EXPECT_EQ(scripts.find("document.cookie"), std::string::npos);
  EXPECT_EQ(scripts.find("?token="), std::string::npos);
  EXPECT_EQ(scripts.find("&token="), std::string::npos);
  EXPECT_NE(scripts.find("Authorization"), std::string::npos);
  // No CORS grant: a foreign origin gets no Access-Control-* header on the API or the page, and
  // a preflight is not answered with one either.
  const Headers evil{{"Origin", "http://evil.example"}};
  Headers evil_auth = evil;
  evil_auth.emplace_back("Authorization", "Bearer " + owner);
  std::vector<HttpReply> answers{
      test::http(d.port(), "GET", "/rcan/v1/status", "", evil),
      test::http(d.port(), "GET", "/rcan/v1/status", "", evil_auth),
      test::http(d.port(), "GET", "/", "", evil),
      test::http(d.port(), "POST", "/rcan/v1/command", cmd_json(new_uuid_v4(), "status"),
                 evil_auth),
      test::http(d.port(), "OPTIONS", "/rcan/v1/command", "",
                 {{"Origin", "http://evil.example"},
                  {"Access-Control-Request-Method", "POST"},
                  {"Access-Control-Request-Headers", "authorization,content-type"}}),
  };
  for (const auto& r : answers) {
    ASSERT_NE(r.status, 0);
    for (const auto& h : r.headers)
      EXPECT_NE(h.first.rfind("access-control-", 0), 0u) << h.first << ": " << h.second;
  }
  EXPECT_GE(answers.back().status, 400) << "a preflight must not succeed";
}

// ---------------------------------------------------------------------------------------------
// 5. Signatures: a `sig` that does not verify is refused; headers are not signatures; a claim
//    to be a robot needs a trusted robot key.

TEST(Security, SignaturesAreVerifiedNeverTakenOnTrust) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_NE(d.port(), 0);
  const std::string tok = d.token("owner", {"status", "control"}, "sig-user");
  const std::string chain =
      R"(,"delegation_chain":[{"issuer_ruri":"rcan://local.rcan/acme/peer/0a0b0c0d","human_subject":"op","timestamp":)" +
      std::to_string(now_ms() / 1000) + R"(,"scope":"control"}])";
  // A well-formed Ed25519 signature by a key the node does not trust, on a plain command and on
  // one claiming to come from a robot; then the same with the payload changed after signing.
  auto signed_by_stranger = [&](bool robot, bool tamper) {
    auto v = json::parse(cmd_json(
        new_uuid_v4(), "move", R"(,"linear":0.2,"duration_ms":100)",
        robot ? R"(,"sender_type":"robot","source_ruri":"rcan://local.rcan/acme/peer/0a0b0c0d")" +
                    chain
              : std::string()));
    json::Object m = v->as_object();
    Bytes seed = ed25519::random_seed();
    EXPECT_TRUE(msgsig::sign_ed25519(m, seed).ok());
    if (tamper) {
      json::Object payload = m.find("payload")->as_object();
      payload.set("linear", 0.5);
      m.set("payload", payload);
    }
    return json::dump(json::Value(m));
  };
  for (bool robot : {false, true}) {
    for (bool tamper : {false, true}) {
      HttpReply r = test::http(d.port(), "POST", "/rcan/v1/command",
                               signed_by_stranger(robot, tamper), bearer(tok));
      EXPECT_EQ(r.status, 401) << "robot " << robot << " tamper " << tamper << ": " << r.body;
      EXPECT_EQ(code_of(r), "SIGNATURE_INVALID") << r.body;
    }
  }
  // A sig block that is not a signature at all.
  HttpReply junk =
      test::http(d.port(), "POST", "/rcan/v1/command",
                 cmd_json(new_uuid_v4(), "status", "",
                          R"(,"sig":{"alg":"ed25519","kid":"00000000","value":"AAAA"})"),
                 bearer(tok));
  EXPECT_EQ(junk.status / 100, 4) << junk.body;
  EXPECT_NE(junk.status, 200);
  // Signature-looking headers on an unsigned robot claim: headers are never credentials.
  Headers sig_headers{{"X-RCAN-Signature", "ed25519=" + std::string(86, 'A')},
                      {"Signature", "keyId=\"peer\",signature=\"AAAA\""},
                      {"X-Robot-Key", "trusted"}};
  HttpReply no_token =
      test::http(d.port(), "POST", "/rcan/v1/command",
                 cmd_json(new_uuid_v4(), "status", "", R"(,"sender_type":"robot")"), sig_headers);
  EXPECT_EQ(no_token.status, 401) << no_token.body;
  Headers with_token = sig_headers;
  with_token.emplace_back("Authorization", "Bearer " + tok);
  HttpReply robot_claim =
      test::http(d.port(), "POST", "/rcan/v1/command",
                 cmd_json(new_uuid_v4(), "move", R"(,"linear":0.2,"duration_ms":100)",
                          R"(,"sender_type":"robot")" + chain),
                 with_token);
  EXPECT_NE(robot_claim.status, 200) << robot_claim.body;
  EXPECT_TRUE(robot_claim.status == 401 || robot_claim.status == 403) << robot_claim.body;
  // The same command without the robot claim is accepted: the refusals above were the signature's.
  HttpReply plain = test::http(
      d.port(), "POST", "/rcan/v1/command",
      cmd_json(new_uuid_v4(), "move", R"(,"linear":0.2,"duration_ms":100)"), bearer(tok));
  EXPECT_EQ(plain.status, 200) << plain.body;
}

// The role and scopes come from the verified token: whatever the message or the headers claim.
TEST(Security, TheRoleComesFromTheVerifiedTokenNeverFromTheMessageOrHeaders) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_NE(d.port(), 0);
  const std::string guest = d.token("guest", {"status"}, "guest-1");
  const std::string user = d.token("user", {"status", "control"}, "user-1");
  Headers claims{
      {"X-RCAN-Role", "owner"}, {"X-Forwarded-User", "owner-1"}, {"X-Real-IP", "127.0.0.1"}};
  const std::string self_promotion =
      R"(,"role":"creator","rcan_role":5,"principal":"owner-1","scope":["control"])";
  // A GUEST may not drive, whatever it says about itself.
  Headers g = claims;
  g.emplace_back("Authorization", "Bearer " + guest);
  HttpReply drive = test::http(
      d.port(), "POST", "/rcan/v1/command",
      cmd_json(new_uuid_v4(), "move", R"(,"linear":0.2,"duration_ms":100)", self_promotion), g);
  EXPECT_EQ(drive.status, 403) << drive.body;
  // A USER may not clear an ESTOP (LEASEE or above), whatever it says about itself.
  ASSERT_EQ(test::http(d.port(), "POST", "/api/stop", "{}", bearer(user)).status, 200);
  Headers u = claims;
  u.emplace_back("Authorization", "Bearer " + user);
  std::string resume = R"({"version":"1.0.0","message_id":")" + new_uuid_v4() +
                       R"(","type":"SAFETY","timestamp_ms":)" + std::to_string(now_ms()) +
                       R"(,"payload":{"safety_event":"RESUME","role":"owner"})" + self_promotion +
                       "}";
  HttpReply r = test::http(d.port(), "POST", "/rcan/v1/command", resume, u);
  EXPECT_EQ(r.status, 403) << r.body;
  EXPECT_EQ(code_of(r), "INSUFFICIENT_PRIVILEGES") << r.body;
  // Nor read the audit export (OWNER with `config`).
  EXPECT_EQ(test::http(d.port(), "GET", "/api/v1/audit?format=jsonl", "", u).status, 403);
  // The robot is still latched: the refused RESUME changed nothing.
  HttpReply st = test::http(d.port(), "GET", "/rcan/v1/status", "", bearer(user));
  EXPECT_NE(st.body.find("\"estop_active\":true"), std::string::npos) << st.body;
}

// Authentication comes before the replay memory: a stranger cannot burn a message_id (or fill
// the bounded memory) with a bad token; a real replay is still refused.
TEST(Security, AMessageWhoseTokenFailsUsesUpNoIdAndReplaysAreStillRefused) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_NE(d.port(), 0);
  const std::string tok = d.token("owner", {"status", "control"}, "owner-1");
  const std::string body = cmd_json(new_uuid_v4(), "status");
  for (const std::string& bad : {std::string("garbage"), forged_token(d.ruri())}) {
    HttpReply r = test::http(d.port(), "POST", "/rcan/v1/command", body, bearer(bad));
    EXPECT_EQ(r.status, 401) << r.body;
  }
  HttpReply ok = test::http(d.port(), "POST", "/rcan/v1/command", body, bearer(tok));
  EXPECT_EQ(ok.status, 200) << "the bad tokens used up the message's id: " << ok.body;
  HttpReply again = test::http(d.port(), "POST", "/rcan/v1/command", body, bearer(tok));
  EXPECT_EQ(again.status, 409) << again.body;
  EXPECT_EQ(code_of(again), "REPLAY_DETECTED");
  // A replay under a bad token is refused for its token (it learns nothing about the id).
  HttpReply bad_replay = test::http(d.port(), "POST", "/rcan/v1/command", body, bearer("garbage"));
  EXPECT_EQ(bad_replay.status, 401) << bad_replay.body;
}

// ---------------------------------------------------------------------------------------------
// Review finding R3: the replay memory is each principal's own, and it is written only after
// authorisation, the guest limits and the rate limit (docs/SECURITY.md).

// A COMMAND with its own timestamp.
std::string cmd_at(const std::string& id, const std::string& action, int64_t timestamp_ms) {
  return R"({"version":"1.0.0","message_id":")" + id + R"(","type":"COMMAND","timestamp_ms":)" +
         std::to_string(timestamp_ms) + R"(,"payload":{"action":")" + action + "\"}}";
}

// What a GUEST flooding a stream saw: answers by error code ("" for an ACK).
struct Flood {
  std::atomic<bool> stop{false};
  std::atomic<int> answered{0};
  std::atomic<bool> done{false};
  std::mutex mu;
  std::map<std::string, int> codes;
};

// Sends COMMANDs stamped `ahead_ms` in the future on one stream, 200 at a time (reading the 200
// answers before the next batch) at `per_second`, until told to stop (or a minute has passed).
void flood_stream(uint16_t port, const std::string& token, int64_t ahead_ms, int per_second,
                  Flood& f) {
  test::WsClient ws;
  if (!ai_test::connect_stream(ws, port, token)) {
    ADD_FAILURE() << "the flooding stream did not connect";
    f.done = true;
    return;
  }
  const int batch = 200;
  const auto start = std::chrono::steady_clock::now();
  const auto until = start + std::chrono::seconds(60);
  for (int64_t n = 0; !f.stop && std::chrono::steady_clock::now() < until; ++n) {
    std::this_thread::sleep_until(start +
                                  std::chrono::microseconds(n * batch * 1'000'000 / per_second));
    for (int i = 0; i < batch; ++i) {
      ws.send_text(cmd_at(new_uuid_v4(), "status", now_ms() + ahead_ms));
    }
    for (int i = 0; i < batch; ++i) {
      auto frame = ws.recv_text(10000);
      if (!frame) {
        ADD_FAILURE() << "the flooding stream stopped answering after " << f.answered;
        f.done = true;
        return;
      }
      auto v = json::parse(*frame);
      const json::Value* p = v.ok() ? v->get("payload") : nullptr;
      const json::Value* c = p && p->is_object() ? p->get("error_code") : nullptr;
      std::lock_guard<std::mutex> l(f.mu);
      ++f.codes[c && c->is_string() ? c->as_string() : ""];
      ++f.answered;
    }
  }
  f.done = true;
}

// The reproduction of the review: a GUEST floods the node with rate-limited messages stamped
// 4.9 s ahead (within the 5 s of tolerated drift). With one memory for everyone, the flood filled
// it and its evictions refused every timestamp up to 4.9 s ahead — the OWNER's next fresh
// command was 408 MESSAGE_STALE. Now the flood is refused by the rate limit before it reaches
// the replay memory, and the memory is each principal's own.
TEST(Security, AGuestFloodOfFutureStampedMessagesCannotMakeTheOwnersCommandStale) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_NE(d.port(), 0);
  const std::string owner = d.token("owner", {"status", "control"}, "owner-r3");
  const std::string guest = d.token("guest", {"status"}, "guest-r3");
  Flood f;
  auto start = std::chrono::steady_clock::now();
  // 4,000 a second (the review saw 4,500): more than 10,000 ids in 4.9 s, so that with one
  // memory of 10,000 ids for everyone the evictions, from 4.9 s on, refused every timestamp up
  // to the present.
  std::thread flood([&] { flood_stream(d.port(), guest, 4900, 4000, f); });
  // Past the node's memory (10,000 ids) and past the 4.9 s, while the flood goes on.
  while (!f.done && (f.answered < 12000 ||
                     std::chrono::steady_clock::now() - start < std::chrono::milliseconds(5500)))
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  HttpReply during = test::http(d.port(), "POST", "/rcan/v1/command",
                                cmd_at(new_uuid_v4(), "status", now_ms()), bearer(owner));
  f.stop = true;
  flood.join();
  double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("guest flood: %d messages answered in %.1f s (%.0f/s)\n", f.answered.load(), secs,
              f.answered / secs);
  ASSERT_GE(f.answered, 10000) << "the flood was too small to show anything";
  EXPECT_EQ(during.status, 200) << "the OWNER's command during the flood: " << during.body;
  HttpReply after = test::http(d.port(), "POST", "/rcan/v1/command",
                               cmd_at(new_uuid_v4(), "status", now_ms()), bearer(owner));
  EXPECT_EQ(after.status, 200) << "the OWNER's command after the flood: " << after.body;
  // The guest was answered (accepted within its budget, then rate-limited), never told stale.
  {
    std::lock_guard<std::mutex> l(f.mu);
    for (const auto& [code, n] : f.codes)
      EXPECT_TRUE(code.empty() || code == "RATE_LIMITED") << n << " answers " << code;
  }
  // A GUEST may still stop the robot (never rate-limited, never refused for memory).
  HttpReply stop = test::http(d.port(), "POST", "/api/stop", "{}", bearer(guest));
  EXPECT_EQ(stop.status, 200) << stop.body;
}

// A message_id is remembered for the principal that sent it (the token binds a message to its
// sender; another principal's message with the same id is another message, acting with that
// principal's rights only). A message refused before the replay stage — authorisation here —
// uses up nothing: sent again when it may pass, it is accepted once.
TEST(Security, MessageIdsBelongToTheirPrincipalAndARefusedMessageUsesUpNone) {
  test::TempDir dir;
  test::RcandDaemon d(dir.path() + "/node");
  ASSERT_NE(d.port(), 0);
  const std::string owner = d.token("owner", {"status", "control"}, "owner-r3");
  const std::string user = d.token("user", {"status", "control"}, "user-r3");
  const std::string guest = d.token("guest", {"status"}, "guest-r3");
  auto send = [&](const std::string& body, const std::string& tok) {
    return test::http(d.port(), "POST", "/rcan/v1/command", body, bearer(tok));
  };
  // The OWNER's id: a second copy from the OWNER is a replay…
  const std::string x = cmd_json(new_uuid_v4(), "status");
  EXPECT_EQ(send(x, owner).status, 200);
  HttpReply owner_again = send(x, owner);
  EXPECT_EQ(owner_again.status, 409) << owner_again.body;
  EXPECT_EQ(code_of(owner_again), "REPLAY_DETECTED");
  // …the same message under the USER's token is the USER's message (once).
  HttpReply user_x = send(x, user);
  EXPECT_EQ(user_x.status, 200) << "another principal's id refused: " << user_x.body;
  HttpReply user_again = send(x, user);
  EXPECT_EQ(user_again.status, 409) << user_again.body;
  EXPECT_EQ(code_of(user_again), "REPLAY_DETECTED");

  // Refused at authorisation (a GUEST may not drive): the id is not used up.
  const std::string y = cmd_json(new_uuid_v4(), "move", R"(,"linear":0.1,"duration_ms":100)");
  HttpReply guest_y = send(y, guest);
  EXPECT_EQ(guest_y.status, 403) << guest_y.body;
  HttpReply owner_y = send(y, owner);
  EXPECT_EQ(owner_y.status, 200) << "the GUEST's refused message used up the id: " << owner_y.body;

  // The same principal, refused at authorisation and then allowed: the OWNER holds control, the
  // USER's command is a CONTROL_CONFLICT; once the OWNER releases, the same message is accepted.
  HttpReply claim = test::http(d.port(), "POST", "/rcan/v1/auth/claim", "{}", bearer(owner));
  ASSERT_EQ(claim.status, 200) << claim.body;
  const std::string z = cmd_json(new_uuid_v4(), "move", R"(,"linear":0.1,"duration_ms":100)");
  HttpReply conflict = send(z, user);
  EXPECT_EQ(conflict.status, 409) << conflict.body;
  EXPECT_EQ(code_of(conflict), "CONTROL_CONFLICT");
  HttpReply release = test::http(d.port(), "DELETE", "/rcan/v1/auth/release", "{}", bearer(owner));
  ASSERT_EQ(release.status, 200) << release.body;
  HttpReply user_z = send(z, user);
  EXPECT_EQ(user_z.status, 200) << "the refused message used up its id: " << user_z.body;
  HttpReply user_z_again = send(z, user);
  EXPECT_EQ(user_z_again.status, 409) << user_z_again.body;
  EXPECT_EQ(code_of(user_z_again), "REPLAY_DETECTED");
}

// Ids are unique per principal only, so a command held for approval (§16.4) is named by an id
// that another principal may also send: that principal's command must not take the held one's
// place (an approval names the id).
TEST(Security, AnotherPrincipalsCommandCannotTakeTheIdOfAHeldOne) {
  test::TempDir dir;
  ai_test::AiNode n(dir.path(),
                    "agent:\n"
                    "  hitl_gates:\n"
                    "    - {action_types: [arm_move], require_auth: true, auth_timeout_ms: 60000,"
                    " on_timeout: block}\n");
  ASSERT_NE(n.port(), 0);
  const std::string held = new_uuid_v4();
  const std::string body = cmd_json(held, "arm_move", R"(,"joints":[0.1,0,0,0,0,0])");
  HttpReply first = n.command(n.leasee(), body);
  ASSERT_EQ(first.status, 202) << first.body;
  HttpReply other = n.command(n.owner(), body);
  EXPECT_EQ(other.status, 409) << other.body;
  EXPECT_EQ(code_of(other), "REPLAY_DETECTED");
  // The held command is still the LEASEE's: approving it runs the LEASEE's command.
  HttpReply pending = n.get("/rcan/v1/pending", n.owner());
  ASSERT_EQ(pending.status, 200);
  EXPECT_NE(pending.body.find("leasee-1 asks for arm_move"), std::string::npos) << pending.body;
  EXPECT_EQ(pending.body.find("owner-1 asks"), std::string::npos) << pending.body;
  HttpReply approve = n.authorize(n.owner(), held, "approve");
  EXPECT_EQ(approve.status, 200) << approve.body;
  json::Value ran = n.record(held, "COMMAND");
  EXPECT_EQ(json::string_field(ran, "sub"), "leasee-1") << json::dump(ran);
}

// ---------------------------------------------------------------------------------------------
// 6. Nothing the node sends to others carries the caller's credentials: brain-layer calls,
//    HiTL webhooks, PENDING_AUTH on other principals' streams, the pending file, thoughts.

// A loopback HTTP server that keeps every raw request (headers and body) and answers each POST
// like a brain layer (a valid layer reply; a webhook ignores the body).
class CaptureServer {
 public:
  CaptureServer() {
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a);
    ::listen(fd_, 16);
    socklen_t len = sizeof a;
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] { loop(); });
  }
  ~CaptureServer() {
    quit_ = true;
    thread_.join();
    ::close(fd_);
  }
  std::string url(const std::string& path) const {
    return "http://127.0.0.1:" + std::to_string(port_) + path;
  }
  std::string all() {
    std::lock_guard<std::mutex> l(mu_);
    std::string s;
    for (auto& r : requests_) s += r + "\n----\n";
    return s;
  }
  size_t count_path(const std::string& path) {
    std::lock_guard<std::mutex> l(mu_);
    size_t n = 0;
    for (auto& r : requests_)
      if (r.rfind("POST " + path + " ", 0) == 0) ++n;
    return n;
  }

 private:
  void loop() {
    const std::string reply =
        R"({"command":{"action":"move","linear":0.1,"duration_ms":100},)"
        R"("ai":{"provider":"capture","model":"capture-planner","confidence":0.99},"thought":{"reasoning":"ok"}})";
    while (!quit_) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) continue;
      int c = ::accept4(fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (c < 0) continue;
      std::string req;
      char buf[8192];
      for (int i = 0; i < 100; ++i) {
        pollfd q{c, POLLIN, 0};
        if (::poll(&q, 1, 50) <= 0) continue;
        ssize_t n = ::recv(c, buf, sizeof buf, 0);
        if (n <= 0) break;
        req.append(buf, static_cast<size_t>(n));
        size_t he = req.find("\r\n\r\n");
        if (he != std::string::npos) {
          std::string lower = req.substr(0, he);
          std::transform(lower.begin(), lower.end(), lower.begin(),
                         [](unsigned char ch) { return std::tolower(ch); });
          size_t cl = lower.find("content-length: ");
          size_t want = cl == std::string::npos ? 0 : std::stoul(lower.substr(cl + 16));
          if (req.size() >= he + 4 + want) break;
        }
      }
      std::string res = "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: " +
                        std::to_string(reply.size()) + "\r\nConnection: close\r\n\r\n" + reply;
      ::send(c, res.data(), res.size(), MSG_NOSIGNAL);
      ::close(c);
      std::lock_guard<std::mutex> l(mu_);
      requests_.push_back(req);
    }
  }
  int fd_ = -1;
  uint16_t port_ = 0;
  std::atomic<bool> quit_{false};
  std::thread thread_;
  std::mutex mu_;
  std::vector<std::string> requests_;
};

TEST(Security, LayerCallsWebhooksAndOtherStreamsNeverCarryTheCallersToken) {
  test::TempDir dir;
  CaptureServer cap;
  std::string agent =
      "agent:\n"
      "  confidence_gates:\n"
      "    - {scope: nav, min_confidence: 0.8, on_fail: escalate}\n"
      "  hitl_gates:\n"
      "    - action_types: [arm_move]\n"
      "      require_auth: true\n"
      "      auth_timeout_ms: 60000\n"
      "      on_timeout: block\n"
      "      notify: [ws, \"" +
      cap.url("/hook") +
      "\"]\n"
      "  layers:\n"
      "    planner: {url: \"" +
      cap.url("/planner") + "\", timeout_ms: 5000}\n";
  ai_test::AiNode n(dir.path(), agent);
  ASSERT_NE(n.port(), 0);
  const std::string caller = n.leasee();
  // The owner watches its stream: PENDING_AUTH for the held command comes there.
  test::WsClient owner_ws;
  ASSERT_TRUE(ai_test::connect_stream(owner_ws, n.port(), n.owner()));
  // An escalated command (header token and, again, the body's auth_token).
  std::string esc = new_uuid_v4();
  HttpReply r1 = n.command(
      caller,
      cmd_json(
          esc, "move", R"(,"linear":0.2,"duration_ms":100,"instruction":"dock")",
          R"(,"auth_token":")" + caller +
              R"(","ai":{"provider":"p","model":"m","confidence":0.2,"layer":"fast","thought_id":"th_sec_1"},"thought":{"reasoning":"maybe the dock"})"));
  ASSERT_EQ(r1.status, 200) << r1.body;
  EXPECT_EQ(cap.count_path("/planner"), 1u);
  // A held command: webhook and owner stream are told.
  std::string held = new_uuid_v4();
  HttpReply r2 = n.command(caller, cmd_json(held, "arm_move", R"(,"joints":[0.1,0,0,0,0,0])",
                                            R"(,"auth_token":")" + caller + "\""));
  ASSERT_EQ(r2.status, 202) << r2.body;
  auto pending = ai_test::wait_frame(owner_ws, "PENDING_AUTH", held);
  ASSERT_TRUE(pending.has_value());
  for (int i = 0; i < 100 && cap.count_path("/hook") == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  ASSERT_EQ(cap.count_path("/hook"), 1u) << cap.all();
  HttpReply pend = n.get("/rcan/v1/pending", n.owner());
  ASSERT_EQ(pend.status, 200);
  HttpReply thought = n.get("/api/thoughts/th_sec_1", n.owner());
  ASSERT_EQ(thought.status, 200) << thought.body;

  const std::string sent = cap.all();
  EXPECT_NE(sent.find(esc), std::string::npos) << "the layer call is not in the capture";
  EXPECT_NE(sent.find(held), std::string::npos) << "the webhook call is not in the capture";
  std::string lower = sent;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char ch) { return std::tolower(ch); });
  EXPECT_EQ(lower.find("authorization:"), std::string::npos) << sent;
  EXPECT_EQ(lower.find("bearer"), std::string::npos) << sent;
  EXPECT_EQ(leak_of(sent, caller), "") << "the caller's token went to a layer or webhook";
  EXPECT_EQ(leak_of(json::dump(*pending), caller), "")
      << "the caller's token went to the owner's stream";
  EXPECT_EQ(leak_of(pend.body, caller), "");
  EXPECT_EQ(leak_of(thought.body, caller), "");
  EXPECT_EQ(leak_of(slurp_tree(dir.path() + "/data"), caller), "")
      << "the caller's token is stored on disk";
  EXPECT_EQ(leak_of(n.log(), caller), "");
}

}  // namespace
}  // namespace rcan

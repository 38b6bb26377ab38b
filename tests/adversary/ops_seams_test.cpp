// The operational seams, tried as an attacker with only the public interfaces would
// (docs/THREATS.md): a real rcan-registry and a real rcand with a driver process, started here on
// loopback. The attackers: anyone who shares the registrant's address (every client of the
// registry behind its TLS proxy does), an admin's webhook URL that names an internal address,
// anyone who reads a command line in `ps`, and a driver program that writes to its stdout and
// stderr.
#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "configured_node.h"
#include "rcan/json.h"
#include "registry_daemon.h"
#include "test_support.h"
#include "transport/http_server.h"

namespace rcan::test {
namespace {

// A registration as rcand and `rcan registry register` make one: the challenge asked for with
// the registrant's key, fresh keys, their proof.
HttpReply register_keyed(const RegistryDaemon& reg, const std::string& key,
                         const std::string& device) {
  auto ch = reg.get("/api/v1/challenge", key);
  if (ch.status != 200) return ch;
  auto c = json::parse(ch.body);
  auto k = keys::generate();
  if (!c.ok() || !k.ok()) return ch;
  const std::string id = json::string_field(*c, "challenge_id");
  auto proof = registry::sign_proof(
      *k, id,
      registry::proof_message(id, json::string_field(*c, "nonce"), "acme", "bot", "v1", device));
  if (!proof.ok()) return ch;
  json::Object body{{"manufacturer", "acme"},
                    {"model", "bot"},
                    {"version", "v1"},
                    {"device_id", device},
                    {"metadata", json::Object{{"ruri", "rcan://local.rcan/acme/bot/" + device}}},
                    {"ed25519_public_key", base64url_encode(k->pub.ed25519_pk)},
                    {"mldsa65_public_key", base64url_encode(k->pub.mldsa65_pk)},
                    {"proof", proof->to_json()}};
  return reg.send("POST", "/api/v1/robots", json::dump(json::Value(std::move(body))), key);
}

std::string field(const std::string& body, const std::string& name) {
  auto v = json::parse(body);
  return v.ok() ? json::string_field(*v, name) : std::string();
}

// Anonymous challenges from this process's address (with `forwarded`: that X-Forwarded-For)
// until `stop`; counts the 429s.
struct Flood {
  Flood(uint16_t port, std::vector<std::pair<std::string, std::string>> headers = {})
      : thread([this, port, headers] {
          while (!stop.load())
            if (http(port, "GET", "/api/v1/challenge", "", headers, 5000).status == 429)
              refused.fetch_add(1);
        }) {}
  ~Flood() {
    stop.store(true);
    thread.join();
  }
  std::atomic<bool> stop{false};
  std::atomic<int> refused{0};
  std::thread thread;
};

// F8 (MED). Before the fix: one bucket per address for every write, anonymous challenges
// included; an anonymous flood from the address the registrant shares (behind the documented
// TLS proxy: everyone's) emptied it, and the registrant's registration and its client's token
// request got 429.
TEST(AdversaryOps, AnAnonymousFloodFromTheRegistrantsAddressLeavesItsWritesAlone) {
  TempDir dir;
  RegistryDaemon reg(dir.file("registry"));
  ASSERT_FALSE(reg.url().empty());
  auto k =
      reg.send("POST", "/api/v1/keys", R"({"role":"registrant","label":"alice"})", reg.admin_key());
  ASSERT_EQ(k.status, 201) << k.body;
  const std::string alice = field(k.body, "key");
  // Before the flood: a robot, a client of alice's with an OWNER grant on it.
  auto first = register_keyed(reg, alice, "0000aa01");
  ASSERT_EQ(first.status, 201) << first.body;
  auto c = reg.send("POST", "/api/v1/clients", R"({"name":"ops","auth":"client_secret"})", alice);
  ASSERT_EQ(c.status, 201) << c.body;
  const std::string client_id = field(c.body, "client_id");
  auto g = reg.send("POST", "/api/v1/grants",
                    R"({"principal":")" + client_id + R"(","robot":")" + field(first.body, "rrn") +
                        R"(","role":"owner","scope":["status"]})",
                    alice);
  ASSERT_EQ(g.status, 201) << g.body;
  const std::string token_form = "grant_type=client_credentials&client_id=" + client_id +
                                 "&client_secret=" + field(c.body, "client_secret") +
                                 "&resource=" + field(first.body, "rrn");

  Flood flood(reg.port());
  // The anonymous bucket still holds the flood back...
  ASSERT_TRUE(eventually([&] { return flood.refused.load() >= 20; }, 30000));
  // ...and the registrant's writes, under way while it lasts, are judged by its key.
  for (int i = 0; i < 3; ++i) {
    auto r = register_keyed(reg, alice, "0000bb0" + std::to_string(i));
    EXPECT_EQ(r.status, 201) << r.body;
    auto t = http(reg.port(), "POST", "/oauth/token", token_form,
                  {{"Content-Type", "application/x-www-form-urlencoded"}});
    EXPECT_EQ(t.status, 200) << t.body;
  }
}

// F8. Before the fix the registry had no --trusted-proxy: behind a proxy every client was one
// address. Now X-Forwarded-For separates the clients a trusted proxy forwards for, and is
// ignored from anyone else (a client cannot pick its bucket).
TEST(AdversaryOps, XForwardedForIsBelievedFromATrustedProxyOnly) {
  TempDir dir;
  // One anonymous request every 100 s after a burst of 2: a bucket, once empty, stays empty.
  RegistryDaemon behind(dir.file("behind"),
                        {"--trusted-proxy", "127.0.0.0/8", "--anonymous-rate", "0.01"});
  ASSERT_FALSE(behind.url().empty());
  auto challenge = [](const RegistryDaemon& r, const std::string& forwarded) {
    return http(r.port(), "GET", "/api/v1/challenge", "", {{"X-Forwarded-For", forwarded}}).status;
  };
  int n = 0;
  while (challenge(behind, "198.51.100.7") != 429 && ++n < 10) {
  }
  EXPECT_EQ(n, 2);  // the burst
  EXPECT_EQ(challenge(behind, "198.51.100.7"), 429);
  // Another client behind the proxy has its own bucket.
  EXPECT_EQ(challenge(behind, "198.51.100.8"), 200);
  // A client that writes its own X-Forwarded-For: the proxy appends the address it saw, and
  // that one counts (the right-most address not a trusted proxy).
  EXPECT_EQ(challenge(behind, "203.0.113.99, 198.51.100.7"), 429);
  EXPECT_EQ(challenge(behind, "198.51.100.7, 127.0.0.2"), 429);  // a chain of trusted proxies
  EXPECT_EQ(http(behind.port(), "GET", "/api/v1/challenge", "",
                 {{"X-Forwarded-For", "203.0.113.98"}, {"X-Forwarded-For", "198.51.100.7"}})
                .status,
            429);  // two header lines are one list

  // Without --trusted-proxy the header is nobody's word: every value shares the peer's bucket.
  RegistryDaemon direct(dir.file("direct"), {"--anonymous-rate", "0.01"});
  ASSERT_FALSE(direct.url().empty());
  n = 0;
  while (challenge(direct, "198.51.100.7") != 429 && ++n < 10) {
  }
  EXPECT_EQ(n, 2);
  EXPECT_EQ(challenge(direct, "198.51.100.8"), 429);
  EXPECT_EQ(http(direct.port(), "GET", "/api/v1/challenge").status, 429);
  // A made-up key proves nothing: anonymous, and refused with the rest; a valid one is judged
  // by itself.
  const std::string fake = "rcan_0123456789abcdef_" + std::string(64, 'a');
  EXPECT_EQ(direct.get("/api/v1/challenge", fake).status, 429);
  EXPECT_EQ(direct.get("/api/v1/challenge", direct.admin_key()).status, 200);
}

// A receiver for webhook deliveries on loopback: counts what arrives.
class Receiver : public transport::HttpHandler {
 public:
  void handle(transport::HttpRequest, Respond respond) override {
    received.fetch_add(1);
    transport::HttpResponse r;
    r.body = "{}";
    respond(std::move(r));
  }
  std::atomic<int> received{0};
};

class NoStreams : public transport::StreamHandler {
 public:
  std::unique_ptr<transport::StreamReceiver> open(const transport::HttpRequest&,
                                                  std::shared_ptr<transport::StreamSink>,
                                                  transport::HttpResponse& refusal) override {
    refusal.status = 404;
    return nullptr;
  }
};

std::string subscription(const std::string& url) {
  json::Object o{{"node_prefix", "RRN"}, {"webhook_url", url}, {"secret", "0123456789abcdef-s"}};
  return json::dump(json::Value(std::move(o)));
}

// F10 (LOW). Before the fix: an admin's webhook at the cloud's metadata address or at loopback
// was taken (201) and delivered to, from the registry's own network position (SSRF).
TEST(AdversaryOps, AWebhookGoesToPublicAddressesOnly) {
  Receiver receiver;
  NoStreams streams;
  transport::ServerOptions so;
  so.port = 0;
  transport::HttpServer server(so, receiver, streams);
  auto port = server.start();
  ASSERT_TRUE(port.ok());
  const std::string where = ":" + std::to_string(*port) + "/hook";

  TempDir dir;
  RegistryDaemon reg(dir.file("registry"),
                     {"--allow-http-node-urls", "--webhook-backoff-ms", "20"});
  ASSERT_FALSE(reg.url().empty());
  // A literal internal address: refused when the subscription is made.
  for (const std::string& url : std::vector<std::string>{
           "http://169.254.169.254/latest/meta-data/", "https://169.254.169.254/",
           "http://127.0.0.1" + where, "http://[::1]" + where, "http://[::ffff:127.0.0.1]" + where,
           "http://10.1.2.3/", "http://192.168.1.1/", "http://100.64.0.1/", "http://[fd00::1]:443/",
           "http://[fe80::1]:443/", "http://0.0.0.0" + where, "http://224.0.0.1/"}) {
    auto r = reg.send("POST", "/api/v1/webhooks", subscription(url), reg.admin_key());
    EXPECT_EQ(r.status, 400) << url << ": " << r.body;
    EXPECT_NE(r.body.find("public addresses only"), std::string::npos) << r.body;
  }
  // A name is judged where it resolves, when a delivery connects: localhost is loopback.
  auto named = reg.send("POST", "/api/v1/webhooks", subscription("http://localhost" + where),
                        reg.admin_key());
  ASSERT_EQ(named.status, 201) << named.body;
  auto robot = reg.send("POST", "/api/v1/robots",
                        R"({"manufacturer":"acme","model":"arm","version":"v1","device_id":"w-1"})",
                        reg.admin_key());
  ASSERT_EQ(robot.status, 201) << robot.body;
  ASSERT_TRUE(eventually(
      [&] {
        return metric_value(reg.get("/metrics").body,
                            "rcan_registry_webhook_refused_address_total") >= 1.0;
      },
      10000))
      << reg.proc().err();
  EXPECT_TRUE(reg.proc().wait_for_line("registry_webhook_refused_address", 5000));
  EXPECT_EQ(receiver.received.load(), 0);

  // The same subscription with --allow-private-webhooks is delivered: the receiver answers,
  // so the refusal above was the rule's.
  TempDir dir2;
  RegistryDaemon allowed(dir2.file("registry"),
                         {"--allow-http-node-urls", "--allow-private-webhooks"});
  ASSERT_FALSE(allowed.url().empty());
  ASSERT_EQ(allowed
                .send("POST", "/api/v1/webhooks", subscription("http://localhost" + where),
                      allowed.admin_key())
                .status,
            201);
  ASSERT_EQ(allowed
                .send("POST", "/api/v1/robots",
                      R"({"manufacturer":"acme","model":"arm","version":"v1","device_id":"w-2"})",
                      allowed.admin_key())
                .status,
            201);
  EXPECT_TRUE(eventually([&] { return receiver.received.load() >= 1; }, 10000));
  server.stop(500);
}

// F12 (LOW). Before the fix the first start's banner suggested
// curl -H "Authorization: Bearer $(cat admin.key)": the admin key in curl's argv, which every
// local user reads in ps. Its usage now names the key file; what it shows works as shown.
TEST(AdversaryOps, TheFirstStartBannerKeepsTheAdminKeyOffEveryCommandLine) {
  TempDir dir;
  RegistryDaemon reg(dir.file("registry"));
  ASSERT_FALSE(reg.url().empty());
  const std::string banner = reg.proc().err();
  EXPECT_EQ(banner.find("$(cat"), std::string::npos) << banner;
  // "  RCAN_REGISTRY=<url> RCAN_REGISTRY_KEY_FILE=<file> \" then "  rcan registry register …".
  std::istringstream lines(banner);
  std::string line, env_line, command_line;
  while (std::getline(lines, line)) {
    if (line.find("RCAN_REGISTRY_KEY_FILE=") != std::string::npos) {
      env_line = line;
      std::getline(lines, command_line);
      break;
    }
  }
  ASSERT_FALSE(env_line.empty()) << banner;
  std::vector<std::string> env, args;
  {
    std::istringstream words(env_line);
    for (std::string w; words >> w;)
      if (w != "\\") env.push_back(w);
    std::istringstream cmd(command_line);
    for (std::string w; cmd >> w;) args.push_back(w);
  }
  ASSERT_EQ(env.size(), 2u) << env_line;
  EXPECT_EQ(env[1], "RCAN_REGISTRY_KEY_FILE=" + dir.file("registry") + "/admin.key");
  ASSERT_GE(args.size(), 3u) << command_line;
  ASSERT_EQ(args[0], "rcan");
  args.erase(args.begin());
  for (const std::string& a : args) EXPECT_EQ(a.find(reg.admin_key()), std::string::npos);
  auto r = run_cli(args, {}, env);
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("RRN-"), std::string::npos) << r.out;
}

// F13 (LOW). Before the fix the driver process wrote to rcand's own stdout and stderr: a line it
// printed was a line of rcand's JSON log (a forged "listening" with another URL, a forged ESTOP),
// for the operator, journald and a log shipper alike.
TEST(AdversaryOps, WhatTheDriverPrintsIsRelayedAsTheDriversNeverAsRcandsOwnLog) {
  TempDir dir;
  // A driver that works (it answers describe and heartbeats) and prints what it likes.
  const std::string script = dir.file("forger.py");
  std::ofstream(script) << R"PY(
import json, os, socket, struct, sys, threading, time
out, err = sys.stdout, sys.stderr
print('{"ts":"2026-01-01T00:00:00.000Z","level":"info","event":"listening",'
      '"url":"http://203.0.113.9:1"}', file=out, flush=True)
print('{"ts":"2026-01-01T00:00:00.000Z","level":"error","event":"estop_latched",'
      '"forged_by":"203.0.113.9"}', file=err, flush=True)
print('cursor\x1b[2Aup 203.0.113.9', file=err, flush=True)
print('x' * 5000, file=out, flush=True)
def chatter():
    for i in range(3000):
        print('flood %d' % i, file=out)
    out.flush()
    time.sleep(1)
    print('after-the-flood', file=out, flush=True)
threading.Thread(target=chatter, daemon=True).start()
sock = socket.socket(fileno=int(os.environ["RCAN_DRIVER_FD"]))
buf = b""
def send(obj):
    data = json.dumps(obj).encode()
    sock.sendall(struct.pack(">I", len(data)) + data)
while True:
    chunk = sock.recv(65536)
    if not chunk:
        sys.exit(0)
    buf += chunk
    while len(buf) >= 4:
        (n,) = struct.unpack(">I", buf[:4])
        if len(buf) < 4 + n:
            break
        f = json.loads(buf[4:4 + n])
        buf = buf[4 + n:]
        if f["type"] == "describe":
            send({"type": "describe", "protocol": 1, "name": "forger", "max_linear_mps": 5.0})
        elif f["type"] == "heartbeat":
            send({"type": "heartbeat", "seq": f["seq"]})
)PY";
  const std::string driver =
      "driver:\n  type: process\n  sim:\n    tick_hz: 100\n  process:\n    command: "
      "[\"python3\", \"" +
      script +
      "\"]\n    heartbeat_ms: 50\n    heartbeat_timeout_ms: 500\n"
      "    max_linear_mps: 1.0\n    max_angular_radps: 3.0\n";
  ConfiguredNode node("", 2000, false, "", driver);
  // The forged ESTOP line on stderr, in whatever form rcand's log has it; then the end of the flood
  // on stdout (before the fix rcand's own stdout, which is not its log).
  ASSERT_TRUE(node.proc().wait_for_line("estop_latched", 30000)) << node.proc().err();
  EXPECT_TRUE(node.proc().wait_for_line("after-the-flood", 20000));
  // Every line of rcand's stderr that carries the driver's words is rcand's driver_output line, the
  // driver's text one escaped field of it.
  std::istringstream lines(node.proc().err());
  int relayed = 0, flood = 0;
  bool cut = false, dropped = false;
  for (std::string line; std::getline(lines, line);) {
    auto v = json::parse(line);
    const bool driver_words = line.find("203.0.113.9") != std::string::npos ||
                              line.find("flood ") != std::string::npos ||
                              line.find("xxxxxxxx") != std::string::npos;
    if (!v.ok()) {
      EXPECT_FALSE(driver_words) << "a raw line in rcand's log: " << line;
      continue;
    }
    const std::string event = json::string_field(*v, "event");
    if (event == "driver_output_dropped") dropped = true;
    if (!driver_words) continue;
    EXPECT_EQ(event, "driver_output") << line;
    if (event != "driver_output") continue;
    ++relayed;
    const std::string text = json::string_field(*v, "line");
    EXPECT_LE(text.size(), 1024u) << line;
    if (text.rfind("flood ", 0) == 0) ++flood;
    if (const json::Value* t = v->get("truncated"); t != nullptr && t->is_bool() && t->as_bool())
      cut = true;
    if (text.find("estop_latched") != std::string::npos) {
      EXPECT_EQ(json::string_field(*v, "stream"), "stderr");
    }
  }
  EXPECT_GE(relayed, 4);
  EXPECT_TRUE(cut);  // the 5,000-byte line
  // The flood is bounded: not every line reaches the log, and the drop is said.
  EXPECT_GT(flood, 0);
  EXPECT_LT(flood, 3000);
  EXPECT_TRUE(dropped);
  // The fixture itself found rcand's own "listening" line, not the driver's forgery.
  EXPECT_EQ(node.get("/healthz", "").status, 200);
}

}  // namespace
}  // namespace rcan::test

// The seam between two registries (docs/THREATS.md T2): a root delegates the prefix BD to a
// peer and pulls its records. The peer is hostile: a small script serving GET /api/v1/sync with
// whatever records it likes (a real peer runs rcan-registry, but it is the peer's to change).
// The root is the real rcan-registry, started here.
#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "joining_robot.h"
#include "rcan/json.h"
#include "registry_daemon.h"
#include "test_support.h"

namespace rcan::test {
namespace {

// The hostile peer: answers every /api/v1/sync with the records in records.json.
constexpr const char* kPeer = R"PY(
import json, sys, http.server
port, path = int(sys.argv[1]), sys.argv[2]
class H(http.server.BaseHTTPRequestHandler):
    def log_message(self, *a):
        pass
    def do_GET(self):
        recs = json.load(open(path)) if self.path.startswith('/api/v1/sync') else None
        body = json.dumps({'protocol': 'rcan-sync/1.0', 'from_node': 'peer', 'records': recs,
                           'count': len(recs), 'has_more': False,
                           'next_since': '2026-01-01T00:00:00.000Z'} if recs is not None else {})
        self.send_response(200 if recs is not None else 404)
        self.send_header('Content-Type', 'application/json')
        self.send_header('Content-Length', str(len(body)))
        self.end_headers()
        self.wfile.write(body.encode())
http.server.ThreadingHTTPServer.allow_reuse_address = True
s = http.server.ThreadingHTTPServer(('127.0.0.1', port), H)
print('peer serving', file=sys.stderr, flush=True)
s.serve_forever()
)PY";

json::Value record(const std::string& rrn, const std::string& device, const std::string& uri,
                   const std::string& tier) {
  return json::Object{{"rrn", rrn},
                      {"manufacturer", "acme"},
                      {"model", "arm"},
                      {"version", "v1"},
                      {"device_id", device},
                      {"rcan_uri", uri},
                      {"verification_tier", tier},
                      {"description", "peer's"},
                      {"ed25519_public_key", std::string(43, 'A')},
                      {"endpoints", json::Array{json::Object{{"url", "https://evil.example"}}}},
                      {"registered_at", "2001-01-01T00:00:00.000Z"},
                      {"updated_at", "2026-01-01T00:00:00.000Z"}};
}

// T2 (review finding F2). Before the fix: a record under the delegated prefix was taken
// whatever URI it named; after one pull, GET /api/v1/resolve?uri= of a root robot returned the
// peer's record (its key, its endpoint, tier "verified"), and token requests by RURI resolved
// to it too.
TEST(AdversaryRegistryToRegistry, ADelegatedPeerCannotTakeOverNamesOrJudgeItsOwnRecords) {
  TempDir dir;
  RegistryDaemon root(dir.file("root"),
                      {"--allow-http-node-urls", "--sync-delegations", "--sync-interval", "0.3"});
  ASSERT_FALSE(root.url().empty());
  auto k =
      root.send("POST", "/api/v1/keys", R"({"role":"registrant","label":"ops"})", root.admin_key());
  ASSERT_EQ(k.status, 201) << k.body;
  auto mine = root.register_proven(str(json_of(k.body), "key"), "acme", "arm", "v1", "a1b2c3d4");
  ASSERT_EQ(mine.status, 201) << mine.body;
  const std::string local_rrn = str(json_of(mine.body), "rrn");
  const std::string local_uri = str(json_of(mine.body), "rcan_uri");
  ASSERT_EQ(local_uri, "rcan://127.0.0.1/acme/arm/v1/a1b2c3d4");  // the peer's host too, here

  const uint16_t peer_port = free_port();
  const std::string peer_url = "http://127.0.0.1:" + std::to_string(peer_port);
  json::Array recs{
      // The root robot's own URI and names, under the peer's prefix.
      record("RRN-BD-000000000001", "a1b2c3d4", local_uri, "verified"),
      // Another registry's host.
      record("RRN-BD-000000000003", "c1b2c3d4", "rcan://registry.example/acme/arm/v1/c1b2c3d4",
             "verified"),
      // Its own robot, under its own host, judged by itself.
      record("RRN-BD-000000000002", "b1b2c3d4", "rcan://127.0.0.1/acme/arm/v1/b1b2c3d4",
             "certified"),
  };
  std::ofstream(dir.file("records.json")) << json::dump(json::Value(std::move(recs)));
  std::ofstream(dir.file("peer.py")) << kPeer;
  Process peer;
  ASSERT_TRUE(peer.start({"/usr/bin/env", "python3", dir.file("peer.py"), std::to_string(peer_port),
                          dir.file("records.json")}));
  ASSERT_TRUE(peer.wait_for_line("peer serving", 15000)) << peer.err();
  auto n = root.send("POST", "/api/v1/nodes",
                     R"({"prefix":"BD","operator":"BD Robotics","node_url":")" + peer_url + "\"}",
                     root.admin_key());
  ASSERT_EQ(n.status, 201) << n.body;

  // Its own robot is taken, with the root's judgement: community, the root's times.
  auto own = [&] { return root.get("/api/v1/resolve/RRN-BD-000000000002"); };
  ASSERT_TRUE(eventually([&] { return own().status == 200; }, 15000)) << own().body;
  const json::Value copy = *json_of(own().body).get("record");
  EXPECT_EQ(str(copy, "verification_tier"), "community");
  EXPECT_NE(str(copy, "registered_at"), "2001-01-01T00:00:00.000Z");
  EXPECT_NE(str(copy, "updated_at"), "2026-01-01T00:00:00.000Z");

  // The root robot's URI still resolves to the root robot, and the hijacking copy is not kept.
  auto by_uri = root.get("/api/v1/resolve?uri=" + local_uri);
  ASSERT_EQ(by_uri.status, 200) << by_uri.body;
  EXPECT_EQ(str(json_of(by_uri.body), "rrn"), local_rrn);
  // (307: the root holds no copy and sends the client to the delegated node, which answers for
  // its own prefix alone.)
  EXPECT_EQ(root.get("/api/v1/resolve/RRN-BD-000000000001").status, 307);
  EXPECT_EQ(root.get("/api/v1/resolve/RRN-BD-000000000003").status, 307);
  // Refused, counted and logged with the reason.
  EXPECT_GE(metric_value(root.get("/metrics").body, "rcan_registry_sync_refused_total"), 2);
  EXPECT_TRUE(root.proc().wait_for_line("\"reason\":\"uri_taken\"", 5000)) << root.proc().err();
  EXPECT_TRUE(root.proc().wait_for_line("\"reason\":\"uri_not_under_node\"", 5000));
}

}  // namespace
}  // namespace rcan::test

// The registry's storage (src/registry/store.h) against every backend: robots and RRN minting,
// listing and search, soft deletes, federation sync, API keys, delegations, webhooks,
// challenges, SQL metacharacters, and concurrent registration (store_fixture.h).
#include <sys/stat.h>

#include <atomic>
#include <map>
#include <regex>
#include <set>
#include <thread>

#include "postgres.h"
#include "store_fixture.h"

namespace rcan::registry::testing {

namespace {
// One PostgreSQL server for the suite, started by the first PostgreSQL test.
std::unique_ptr<test::Postgres>& pg_server() {
  static std::unique_ptr<test::Postgres> server;
  return server;
}
int pg_databases = 0;
}  // namespace

std::string StoreTest::spec() {
  if (!postgres()) return tmp_.file("registry.db");
  auto& pg = pg_server();
  if (!pg) pg = std::make_unique<test::Postgres>();
  if (pg_database_.empty()) {
    pg_database_ = "registry_" + std::to_string(++pg_databases);
    auto r = pg->sql("CREATE DATABASE " + pg_database_);
    EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  }
  return pg->url(pg_database_);
}
std::string StoreTest::fresh_spec(const std::string& name) {
  if (!postgres()) return tmp_.file(name + ".db");
  spec();  // the server
  std::string db = "registry_" + std::to_string(++pg_databases) + "_" + name;
  auto r = pg_server()->sql("CREATE DATABASE " + db);
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  return pg_server()->url(db);
}
Result<std::unique_ptr<Store>> StoreTest::open(const StoreOptions& o) {
  return open_store(spec(), o);
}
void StoreTest::TearDownTestSuite() { pg_server().reset(); }

namespace {

template <typename T>
T must(Result<T> r) {
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  if (!r.ok()) return T{};
  return std::move(r).value();
}

TEST_P(StoreTest, RegistersAndResolvesARobot) {
  NewRobot n = new_robot("unit-1");
  n.contact_email = "ops@example.com";
  n.metadata_json = R"({"arms":2})";
  Registered reg = must(store_->register_robot(n));
  EXPECT_TRUE(reg.created);
  const Robot& r = reg.robot;
  EXPECT_TRUE(std::regex_match(r.rrn, std::regex("RRN-[0-9]{12}"))) << r.rrn;
  EXPECT_EQ(r.rcan_uri, "rcan://registry.example/acme/rover/v1/unit-1");
  EXPECT_EQ(r.verification_tier, "community");
  EXPECT_EQ(r.registered_at, at(0));
  EXPECT_EQ(r.updated_at, at(0));
  EXPECT_FALSE(r.deleted);

  auto got = must(store_->get_robot(r.rrn));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->rrn, r.rrn);
  EXPECT_EQ(got->manufacturer, "acme");
  EXPECT_EQ(got->model, "rover");
  EXPECT_EQ(got->version, "v1");
  EXPECT_EQ(got->device_id, "unit-1");
  EXPECT_EQ(got->contact_email, "ops@example.com");
  EXPECT_EQ(got->metadata_json, R"({"arms":2})");
  EXPECT_EQ(got->endpoints_json, "[]");
  EXPECT_EQ(got->owner_key_id, "0123456789abcdef");
  // RRNs compare case-insensitively.
  std::string lower = r.rrn;
  lower[0] = 'r';
  lower[2] = 'n';
  ASSERT_TRUE(must(store_->get_robot(lower)).has_value());
  EXPECT_FALSE(must(store_->get_robot("RRN-999999999999")).has_value());

  auto by_uri = must(store_->find_robot_by_uri(r.rcan_uri));
  ASSERT_TRUE(by_uri.has_value());
  EXPECT_EQ(by_uri->rrn, r.rrn);
  EXPECT_FALSE(must(store_->find_robot_by_uri("rcan://registry.example/acme/rover/v1/nope")));
}

TEST_P(StoreTest, RegisteringTheSameRobotAgainReturnsIt) {
  Registered a = must(store_->register_robot(new_robot("unit-1")));
  Registered b = must(store_->register_robot(new_robot("unit-1", at(5))));
  EXPECT_TRUE(a.created);
  EXPECT_FALSE(b.created);
  EXPECT_EQ(a.robot.rrn, b.robot.rrn);
  EXPECT_EQ(b.robot.registered_at, at(0));
  NewRobot other = new_robot("unit-1");
  other.version = "v2";
  Registered c = must(store_->register_robot(other));
  EXPECT_TRUE(c.created);
  EXPECT_NE(c.robot.rrn, a.robot.rrn);
}

TEST_P(StoreTest, RrnsAreNumberedWithAndWithoutAPrefix) {
  Registered a = must(store_->register_robot(new_robot("unit-1")));
  Registered b = must(store_->register_robot(new_robot("unit-2")));
  EXPECT_TRUE(std::regex_match(a.robot.rrn, std::regex("RRN-[0-9]{12}"))) << a.robot.rrn;
  EXPECT_GT(b.robot.rrn, a.robot.rrn);  // zero-padded: string order is number order
  auto prefixed = open(StoreOptions{"ACME"});
  ASSERT_TRUE(prefixed.ok()) << prefixed.error().message;
  Registered c = must((*prefixed)->register_robot(new_robot("unit-3")));
  EXPECT_TRUE(std::regex_match(c.robot.rrn, std::regex("RRN-ACME-[0-9]{12}"))) << c.robot.rrn;
  auto got = must(store_->get_robot("rrn-acme-" + c.robot.rrn.substr(9)));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->rrn, c.robot.rrn);
}

TEST_P(StoreTest, ListsNewestFirstWithFiltersAndPages) {
  std::vector<std::string> rrns;
  for (int i = 0; i < 25; ++i) {
    NewRobot n = new_robot("unit-" + std::to_string(i), at(i), i % 5 == 0 ? "globex" : "acme",
                           i % 2 == 0 ? "rover" : "arm-x2");
    rrns.push_back(must(store_->register_robot(n)).robot.rrn);
  }
  RobotPage all = must(store_->list_robots(RobotQuery{}));
  EXPECT_EQ(all.total, 25);
  ASSERT_EQ(all.robots.size(), 20u);
  for (int i = 0; i < 20; ++i) EXPECT_EQ(all.robots[i].rrn, rrns[24 - i]) << i;
  RobotQuery q;
  q.offset = 20;
  RobotPage rest = must(store_->list_robots(q));
  EXPECT_EQ(rest.total, 25);
  ASSERT_EQ(rest.robots.size(), 5u);
  EXPECT_EQ(rest.robots.back().rrn, rrns[0]);
  q.offset = 100;
  EXPECT_EQ(must(store_->list_robots(q)).robots.size(), 0u);

  RobotQuery by_maker;
  by_maker.manufacturer = "globex";
  by_maker.limit = 2;
  RobotPage g = must(store_->list_robots(by_maker));
  EXPECT_EQ(g.total, 5);
  ASSERT_EQ(g.robots.size(), 2u);
  EXPECT_EQ(g.robots[0].rrn, rrns[20]);
  EXPECT_EQ(g.robots[1].rrn, rrns[15]);
  RobotQuery by_model;
  by_model.model = "arm-x2";
  by_model.limit = 100;
  EXPECT_EQ(must(store_->list_robots(by_model)).total, 12);
  by_model.manufacturer = "globex";
  EXPECT_EQ(must(store_->list_robots(by_model)).total, 2);  // 5 and 15

  RobotUpdate up;
  up.verification_tier = "verified";
  up.now = at(100);
  ASSERT_TRUE(must(store_->update_robot(rrns[3], up)).has_value());
  RobotQuery by_tier;
  by_tier.tier = "verified";
  RobotPage v = must(store_->list_robots(by_tier));
  ASSERT_EQ(v.total, 1);
  EXPECT_EQ(v.robots[0].rrn, rrns[3]);

  RobotQuery text;
  text.q = "ARM-X";  // case-insensitive substring of the model
  EXPECT_EQ(must(store_->list_robots(text)).total, 12);
  text.q = "lobe";  // of the manufacturer
  EXPECT_EQ(must(store_->list_robots(text)).total, 5);
  text.q = rrns[7].substr(8);  // of the RRN
  RobotPage by_rrn = must(store_->list_robots(text));
  ASSERT_GE(by_rrn.total, 1);
  EXPECT_EQ(by_rrn.robots.back().rrn, rrns[7]);

  ASSERT_TRUE(must(store_->delete_robot(rrns[24], at(200))));
  EXPECT_EQ(must(store_->list_robots(RobotQuery{})).total, 24);
  EXPECT_EQ(must(store_->list_robots(RobotQuery{})).robots[0].rrn, rrns[23]);
}

TEST_P(StoreTest, QueryMetacharactersAreLiteral) {
  ASSERT_TRUE(store_->register_robot(new_robot("unit-1", at(0), "acme", "rover")).ok());
  ASSERT_TRUE(store_->register_robot(new_robot("unit-2", at(1), "a-b", "x2")).ok());
  for (const char* q : {"%", "_", "'", ";--", "' OR '1'='1", "\\", "a%e", "a_me",
                        "%'; DROP "
                        "TABLE robots;--"}) {
    RobotQuery rq;
    rq.q = q;
    auto page = store_->list_robots(rq);
    ASSERT_TRUE(page.ok()) << q << ": " << page.error().message;
    EXPECT_EQ(page->total, 0) << q;
    EXPECT_TRUE(page->robots.empty()) << q;
  }
  RobotQuery rq;
  rq.q = "-b";
  EXPECT_EQ(must(store_->list_robots(rq)).total, 1);
  rq.q = "";
  EXPECT_EQ(must(store_->list_robots(rq)).total, 2);  // the table is still there
}

TEST_P(StoreTest, UpdatesOnlyTheGivenFields) {
  NewRobot n = new_robot("unit-1");
  n.contact_email = "ops@example.com";
  n.ed25519_pub = "ed-key";
  Robot r = must(store_->register_robot(n)).robot;
  RobotUpdate u;
  u.description = "repainted";
  u.endpoints_json = R"([{"url":"https://r.example","last_seen":"2026-11-27T05:20:01.000Z"}])";
  u.now = at(10);
  auto got = must(store_->update_robot(r.rrn, u));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->description, "repainted");
  EXPECT_EQ(got->endpoints_json, *u.endpoints_json);
  EXPECT_EQ(got->contact_email, "ops@example.com");
  EXPECT_EQ(got->ed25519_pub, "ed-key");
  EXPECT_EQ(got->metadata_json, "{}");
  EXPECT_EQ(got->verification_tier, "community");
  EXPECT_EQ(got->registered_at, at(0));
  EXPECT_EQ(got->updated_at, at(10));
  RobotUpdate keys;
  keys.ed25519_pub = "ed-key-2";
  keys.mldsa65_pub = "ml-key";
  keys.contact_email = "";  // a value, even empty, changes the field
  keys.now = at(11);
  got = must(store_->update_robot(r.rrn, keys));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->ed25519_pub, "ed-key-2");
  EXPECT_EQ(got->mldsa65_pub, "ml-key");
  EXPECT_EQ(got->contact_email, "");
  EXPECT_EQ(got->description, "repainted");
  auto again = must(store_->get_robot(r.rrn));
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->updated_at, at(11));
  EXPECT_EQ(again->ed25519_pub, "ed-key-2");
  EXPECT_FALSE(must(store_->update_robot("RRN-999999999999", u)).has_value());
}

TEST_P(StoreTest, DeleteIsSoftAndTheRrnIsNeverMintedAgain) {
  Robot r = must(store_->register_robot(new_robot("unit-1"))).robot;
  EXPECT_TRUE(must(store_->delete_robot(r.rrn, at(5))));
  EXPECT_FALSE(must(store_->get_robot(r.rrn)).has_value());
  EXPECT_FALSE(must(store_->find_robot_by_uri(r.rcan_uri)).has_value());
  EXPECT_FALSE(must(store_->delete_robot(r.rrn, at(6))));
  RobotUpdate u;
  u.description = "x";
  u.now = at(7);
  EXPECT_FALSE(must(store_->update_robot(r.rrn, u)).has_value());
  // The same slugs register again as a new robot, with a new RRN.
  Registered again = must(store_->register_robot(new_robot("unit-1", at(8))));
  EXPECT_TRUE(again.created);
  EXPECT_NE(again.robot.rrn, r.rrn);
  EXPECT_EQ(must(store_->find_robot_by_uri(r.rcan_uri))->rrn, again.robot.rrn);
  // A restart does not reuse numbers either.
  store_.reset();
  auto reopened = open();
  ASSERT_TRUE(reopened.ok()) << reopened.error().message;
  store_ = std::move(*reopened);
  Robot third = must(store_->register_robot(new_robot("unit-2", at(9)))).robot;
  EXPECT_GT(third.rrn, again.robot.rrn);
  auto changed = must(store_->robots_changed_since(at(0), 10));
  ASSERT_EQ(changed.size(), 3u);
  EXPECT_EQ(changed[0].rrn, r.rrn);
  EXPECT_TRUE(changed[0].deleted);
  EXPECT_EQ(changed[0].updated_at, at(5));
}

TEST_P(StoreTest, ChangesSinceAndSyncedRobots) {
  std::vector<std::string> rrns;
  for (int i = 0; i < 5; ++i)
    rrns.push_back(
        must(store_->register_robot(new_robot("u" + std::to_string(i), at(i)))).robot.rrn);
  RobotUpdate u;
  u.description = "moved";
  u.now = at(50);
  ASSERT_TRUE(must(store_->update_robot(rrns[1], u)).has_value());
  auto since = must(store_->robots_changed_since(at(2), 100));  // strictly after
  ASSERT_EQ(since.size(), 3u);
  EXPECT_EQ(since[0].rrn, rrns[3]);
  EXPECT_EQ(since[1].rrn, rrns[4]);
  EXPECT_EQ(since[2].rrn, rrns[1]);  // oldest change first
  EXPECT_EQ(must(store_->robots_changed_since(at(2), 2)).size(), 2u);
  EXPECT_EQ(must(store_->robots_changed_since("", 100)).size(), 5u);

  Robot s;
  s.rrn = "rrn-xy-000000000007";
  s.manufacturer = "acme";
  s.model = "rover";
  s.version = "v1";
  s.device_id = "u0";  // the same slugs as a local robot: a different registry's robot
  s.rcan_uri = "rcan://xy.example/acme/rover/v1/u0";
  s.verification_tier = "verified";
  s.description = "from XY";
  s.registered_at = at(60);
  s.updated_at = at(60);
  ASSERT_TRUE(store_->upsert_synced_robot(s).ok());
  auto got = must(store_->get_robot("RRN-XY-000000000007"));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->rrn, "RRN-XY-000000000007");
  EXPECT_EQ(got->description, "from XY");
  EXPECT_EQ(got->verification_tier, "verified");
  s.description = "from XY, updated";
  s.updated_at = at(61);
  ASSERT_TRUE(store_->upsert_synced_robot(s).ok());
  got = must(store_->get_robot(s.rrn));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->description, "from XY, updated");
  EXPECT_EQ(got->updated_at, at(61));
  s.deleted = true;
  s.updated_at = at(62);
  ASSERT_TRUE(store_->upsert_synced_robot(s).ok());
  EXPECT_FALSE(must(store_->get_robot(s.rrn)).has_value());
  // The local robot with the same slugs is untouched and still registers idempotently.
  Registered local = must(store_->register_robot(new_robot("u0", at(70))));
  EXPECT_FALSE(local.created);
  EXPECT_EQ(local.robot.rrn, rrns[0]);
}

// The first admin key is made once per database: only while it holds no live admin key, one
// insert among concurrent callers (on PostgreSQL, each on a connection of its own).
TEST_P(StoreTest, FirstAdminKeyOnlyWhileNoLiveAdminKey) {
  auto key = [&](int i, const std::string& role) {
    std::string id = "00000000000000" + std::to_string(10 + i);
    return ApiKey{id, std::string(32, 'a'), std::string(64, 'b'), role, "", "k", at(i), ""};
  };
  ASSERT_TRUE(store_->put_api_key(key(0, "registrant")).ok());
  std::vector<std::thread> threads;
  std::atomic<int> inserted{0};
  for (int i = 1; i <= 8; ++i)
    threads.emplace_back([&, i] {
      auto r = store_->put_first_admin_key(key(i, "admin"));
      EXPECT_TRUE(r.ok()) << r.error().message;
      if (r.ok() && *r) inserted.fetch_add(1);
    });
  for (auto& t : threads) t.join();
  EXPECT_EQ(inserted.load(), 1);
  auto admins = [&] {
    int n = 0;
    for (const ApiKey& k : must(store_->list_api_keys())) n += k.role == "admin";
    return n;
  };
  EXPECT_EQ(admins(), 1);
  // With every admin key revoked, a first admin key is made again.
  for (const ApiKey& k : must(store_->list_api_keys()))
    if (k.role == "admin") {
      EXPECT_TRUE(must(store_->revoke_api_key(k.id, at(20))));
    }
  EXPECT_TRUE(must(store_->put_first_admin_key(key(30, "admin"))));
  EXPECT_FALSE(must(store_->put_first_admin_key(key(31, "admin"))));
  EXPECT_EQ(admins(), 2);
}

TEST_P(StoreTest, ApiKeys) {
  ApiKey k{"0123456789abcdef",
           std::string(32, 'a'),
           std::string(64, 'b'),
           "admin",
           "",
           "ops",
           at(0),
           ""};
  ApiKey r{"fedcba9876543210",
           std::string(32, 'c'),
           std::string(64, 'd'),
           "robot",
           "RRN-000000000001",
           "robot one",
           at(1),
           ""};
  ASSERT_TRUE(store_->put_api_key(k).ok());
  ASSERT_TRUE(store_->put_api_key(r).ok());
  Status dup = store_->put_api_key(k);  // the id must be new
  EXPECT_FALSE(dup.ok());
  EXPECT_EQ(dup.error().reason, "unique_violation") << dup.error().message;
  auto got = must(store_->get_api_key(r.id));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->salt, r.salt);
  EXPECT_EQ(got->hash, r.hash);
  EXPECT_EQ(got->role, "robot");
  EXPECT_EQ(got->rrn, "RRN-000000000001");
  EXPECT_EQ(got->label, "robot one");
  EXPECT_EQ(got->created_at, at(1));
  EXPECT_EQ(got->revoked_at, "");
  EXPECT_FALSE(must(store_->get_api_key("0000000000000000")).has_value());
  EXPECT_TRUE(must(store_->revoke_api_key(k.id, at(9))));
  EXPECT_FALSE(must(store_->revoke_api_key(k.id, at(10))));  // already revoked
  EXPECT_FALSE(must(store_->revoke_api_key("0000000000000000", at(9))));
  EXPECT_EQ(must(store_->get_api_key(k.id))->revoked_at, at(9));
  auto all = must(store_->list_api_keys());
  ASSERT_EQ(all.size(), 2u);
  EXPECT_EQ(all[0].id, k.id);
  EXPECT_EQ(all[1].id, r.id);
}

TEST_P(StoreTest, Delegations) {
  Delegation d{"XY", "XY Robotics", "https://xy.example", "pubkey-b64", "ops@xy.example", at(0),
               ""};
  EXPECT_TRUE(must(store_->add_delegation(d)));
  Delegation dup = d;
  dup.operator_name = "someone else";
  EXPECT_FALSE(must(store_->add_delegation(dup)));
  Delegation e{"AB12", "AB", "https://ab.example", "k2", "", at(1), at(1000)};
  EXPECT_TRUE(must(store_->add_delegation(e)));
  auto got = must(store_->get_delegation("XY"));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->operator_name, "XY Robotics");
  EXPECT_EQ(got->node_url, "https://xy.example");
  EXPECT_EQ(got->node_pubkey, "pubkey-b64");
  EXPECT_EQ(got->contact, "ops@xy.example");
  EXPECT_EQ(got->delegated_at, at(0));
  EXPECT_EQ(got->expires_at, "");
  EXPECT_FALSE(must(store_->get_delegation("ZZ")).has_value());
  auto all = must(store_->list_delegations());
  ASSERT_EQ(all.size(), 2u);
  EXPECT_EQ(all[0].prefix, "AB12");
  EXPECT_EQ(all[0].expires_at, at(1000));
  EXPECT_EQ(all[1].prefix, "XY");
}

TEST_P(StoreTest, Webhooks) {
  Webhook w;
  w.prefix = "RRN";
  w.url = "https://hooks.example/a";
  w.secret = "s3cret";
  w.created_at = at(0);
  int64_t a = must(store_->add_webhook(w));
  w.url = "https://hooks.example/b";
  int64_t b = must(store_->add_webhook(w));
  w.prefix = "XY";
  int64_t c = must(store_->add_webhook(w));
  EXPECT_NE(a, b);
  EXPECT_NE(b, c);
  auto root = must(store_->webhooks_for("RRN"));
  ASSERT_EQ(root.size(), 2u);
  EXPECT_EQ(root[0].id, a);
  EXPECT_EQ(root[0].url, "https://hooks.example/a");
  EXPECT_EQ(root[0].secret, "s3cret");
  EXPECT_EQ(root[0].created_at, at(0));
  EXPECT_EQ(root[0].failure_count, 0);
  EXPECT_EQ(root[0].last_delivered_at, "");
  EXPECT_EQ(must(store_->webhooks_for("XY")).size(), 1u);
  EXPECT_TRUE(must(store_->webhooks_for("ZZ")).empty());

  ASSERT_TRUE(store_->record_delivery(a, false, at(1)).ok());
  ASSERT_TRUE(store_->record_delivery(a, false, at(2)).ok());
  EXPECT_EQ(must(store_->webhooks_for("RRN"))[0].failure_count, 2);
  EXPECT_EQ(must(store_->webhooks_for("RRN"))[0].last_delivered_at, "");
  ASSERT_TRUE(store_->record_delivery(a, true, at(3)).ok());
  auto after = must(store_->webhooks_for("RRN"));
  EXPECT_EQ(after[0].failure_count, 0);
  EXPECT_EQ(after[0].last_delivered_at, at(3));
  EXPECT_EQ(after[1].failure_count, 0);

  EXPECT_TRUE(must(store_->delete_webhook(b)));
  EXPECT_FALSE(must(store_->delete_webhook(b)));
  EXPECT_EQ(must(store_->webhooks_for("RRN")).size(), 1u);
}

TEST_P(StoreTest, ChallengesAreTakenOnceAndExpire) {
  Challenge c{std::string(32, 'a'), "bm9uY2U", "register", at(100)};
  Challenge old{std::string(32, 'b'), "b2xk", "update", at(10)};
  ASSERT_TRUE(store_->put_challenge(c).ok());
  ASSERT_TRUE(store_->put_challenge(old).ok());
  Status dup = store_->put_challenge(c);  // ids are unique
  EXPECT_FALSE(dup.ok());
  EXPECT_EQ(dup.error().reason, "unique_violation") << dup.error().message;
  auto taken = must(store_->take_challenge(c.id));
  ASSERT_TRUE(taken.has_value());
  EXPECT_EQ(taken->nonce, "bm9uY2U");
  EXPECT_EQ(taken->purpose, "register");
  EXPECT_EQ(taken->expires_at, at(100));
  EXPECT_FALSE(must(store_->take_challenge(c.id)).has_value());
  ASSERT_TRUE(store_->put_challenge(c).ok());
  EXPECT_EQ(must(store_->expire_challenges(at(50))), 1);
  EXPECT_FALSE(must(store_->take_challenge(old.id)).has_value());
  EXPECT_TRUE(must(store_->take_challenge(c.id)).has_value());
  EXPECT_EQ(must(store_->expire_challenges(at(500))), 0);
}

TEST_P(StoreTest, SqlMetacharactersRoundTripInEveryField) {
  const std::string evil = "x'); DROP TABLE robots;-- \"q\" \\ %_ $1 ? :a @b ü\t\n\x01 end";
  NewRobot n = new_robot("unit-1");
  n.rcan_uri_base = "rcan://" + evil;
  n.description = evil + "d";
  n.contact_email = evil + "c";
  n.source = evil + "s";
  n.metadata_json = evil + "m";
  n.ed25519_pub = evil + "e";
  n.mldsa65_pub = evil + "l";
  n.endpoints_json = evil + "p";
  n.owner_key_id = evil + "o";
  n.now = evil + "t";
  Robot r = must(store_->register_robot(n)).robot;
  auto got = must(store_->find_robot_by_uri("rcan://" + evil + "/acme/rover/v1/unit-1"));
  ASSERT_TRUE(got.has_value());
  for (auto [field, want] :
       std::vector<std::pair<std::string, std::string>>{{got->description, n.description},
                                                        {got->contact_email, n.contact_email},
                                                        {got->source, n.source},
                                                        {got->metadata_json, n.metadata_json},
                                                        {got->ed25519_pub, n.ed25519_pub},
                                                        {got->mldsa65_pub, n.mldsa65_pub},
                                                        {got->endpoints_json, n.endpoints_json},
                                                        {got->owner_key_id, n.owner_key_id},
                                                        {got->registered_at, n.now}})
    EXPECT_EQ(field, want);
  RobotUpdate u;
  u.description = evil + "u";
  u.verification_tier = evil;
  u.now = evil + "t2";
  got = must(store_->update_robot(r.rrn, u));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->description, evil + "u");
  EXPECT_EQ(got->verification_tier, evil);
  RobotQuery tq;
  tq.tier = evil;
  EXPECT_EQ(must(store_->list_robots(tq)).total, 1);

  ASSERT_TRUE(store_
                  ->put_api_key(ApiKey{evil, evil + "1", evil + "2", evil + "3", evil + "4",
                                       evil + "5", evil + "6", ""})
                  .ok());
  auto k = must(store_->get_api_key(evil));
  ASSERT_TRUE(k.has_value());
  EXPECT_EQ(k->label, evil + "5");
  EXPECT_EQ(k->rrn, evil + "4");
  EXPECT_TRUE(must(store_->revoke_api_key(evil, evil + "r")));
  EXPECT_EQ(must(store_->get_api_key(evil))->revoked_at, evil + "r");

  Delegation d{"QQ", evil + "o", evil + "u", evil + "k", evil + "c", evil + "d", evil + "e"};
  ASSERT_TRUE(must(store_->add_delegation(d)));
  auto dg = must(store_->get_delegation("QQ"));
  ASSERT_TRUE(dg.has_value());
  EXPECT_EQ(dg->operator_name, d.operator_name);
  EXPECT_EQ(dg->node_url, d.node_url);
  EXPECT_EQ(dg->node_pubkey, d.node_pubkey);
  EXPECT_EQ(dg->contact, d.contact);
  EXPECT_EQ(dg->expires_at, d.expires_at);

  Webhook w;
  w.prefix = evil;
  w.url = evil + "u";
  w.secret = evil + "s";
  w.created_at = evil + "c";
  int64_t id = must(store_->add_webhook(w));
  ASSERT_TRUE(store_->record_delivery(id, true, evil + "n").ok());
  auto hooks = must(store_->webhooks_for(evil));
  ASSERT_EQ(hooks.size(), 1u);
  EXPECT_EQ(hooks[0].url, w.url);
  EXPECT_EQ(hooks[0].secret, w.secret);
  EXPECT_EQ(hooks[0].last_delivered_at, evil + "n");

  Challenge c{evil, evil + "n", evil + "p", evil + "e"};
  ASSERT_TRUE(store_->put_challenge(c).ok());
  auto taken = must(store_->take_challenge(evil));
  ASSERT_TRUE(taken.has_value());
  EXPECT_EQ(taken->nonce, c.nonce);
  EXPECT_EQ(taken->purpose, c.purpose);
  EXPECT_EQ(taken->expires_at, c.expires_at);
  EXPECT_EQ(must(store_->list_robots(RobotQuery{})).total, 1);
}

TEST_P(StoreTest, SqliteFileIsPrivate) {
  if (postgres()) GTEST_SKIP() << "PostgreSQL has no file of ours";
  ASSERT_TRUE(store_->register_robot(new_robot("unit-1")).ok());
  for (const std::string& f : {spec(), spec() + "-wal"}) {
    struct stat st {};
    ASSERT_EQ(::stat(f.c_str(), &st), 0) << f;
    EXPECT_EQ(st.st_mode & 0777, 0600u) << f;
  }
}

TEST_P(StoreTest, ConcurrentRegistrationsMintDistinctRrns) {
  constexpr int kThreads = 8, kEach = 50;
  std::vector<std::vector<std::string>> minted(kThreads);
  std::atomic<bool> go{false};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      while (!go.load()) std::this_thread::yield();
      for (int i = 0; i < kEach; ++i) {
        auto r = store_->register_robot(
            new_robot("t" + std::to_string(t) + "-" + std::to_string(i), at(t * kEach + i)));
        EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
        if (r.ok()) {
          EXPECT_TRUE(r->created);
          minted[t].push_back(r->robot.rrn);
        }
      }
    });
  go = true;
  for (auto& th : threads) th.join();
  std::set<std::string> all;
  for (const auto& v : minted) all.insert(v.begin(), v.end());
  EXPECT_EQ(all.size(), size_t{kThreads * kEach});
  EXPECT_EQ(must(store_->list_robots(RobotQuery{})).total, kThreads * kEach);
}

TEST_P(StoreTest, ConcurrentRegistrationsOfOneRobotMintOneRrn) {
  constexpr int kThreads = 8;
  std::vector<Registered> results(kThreads);
  std::atomic<bool> go{false};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      while (!go.load()) std::this_thread::yield();
      auto r = store_->register_robot(new_robot("the-one", at(t)));
      EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
      if (r.ok()) results[t] = *r;
    });
  go = true;
  for (auto& th : threads) th.join();
  int created = 0;
  for (const auto& r : results) {
    created += r.created ? 1 : 0;
    EXPECT_EQ(r.robot.rrn, results[0].robot.rrn);
  }
  EXPECT_EQ(created, 1);
  EXPECT_EQ(must(store_->list_robots(RobotQuery{})).total, 1);
}

TEST_P(StoreTest, TwoInstancesRegisteringAtOnceNeverShareAnRrn) {
  // Two Store objects on one database stand for two registry processes.
  auto other = open();
  ASSERT_TRUE(other.ok()) << other.error().message;
  std::vector<Store*> stores{store_.get(), other->get()};
  constexpr int kEach = 100;
  std::vector<std::vector<Registered>> got(4);
  std::atomic<bool> go{false};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      while (!go.load()) std::this_thread::yield();
      for (int i = 0; i < kEach; ++i) {
        // Distinct robots, and one robot every thread of both instances registers.
        auto r = stores[t % 2]->register_robot(
            new_robot(i % 10 == 0 ? "shared-" + std::to_string(i)
                                  : "t" + std::to_string(t) + "-" + std::to_string(i),
                      at(i)));
        EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
        if (r.ok()) got[t].push_back(*r);
      }
    });
  go = true;
  for (auto& th : threads) th.join();
  std::map<std::string, std::string> device_of;  // rrn -> device
  std::map<std::string, int> created;            // device -> creations
  for (const auto& v : got)
    for (const auto& r : v) {
      auto [it, fresh] = device_of.emplace(r.robot.rrn, r.robot.device_id);
      EXPECT_EQ(it->second, r.robot.device_id) << r.robot.rrn << " minted twice";
      created[r.robot.device_id] += r.created ? 1 : 0;
    }
  EXPECT_EQ(device_of.size(), 4u * 90 + 10);
  for (const auto& [device, n] : created) EXPECT_EQ(n, 1) << device;
  EXPECT_EQ(must(store_->list_robots(RobotQuery{})).total, 4 * 90 + 10);
}

TEST_P(StoreTest, TwoInstancesOpeningAFreshDatabaseAtOnceBothSucceed) {
  for (int round = 0; round < 3; ++round) {
    std::string where = fresh_spec("fresh" + std::to_string(round));
    std::vector<Result<std::unique_ptr<Store>>> opened;
    for (int i = 0; i < 2; ++i) opened.emplace_back(Error());
    std::atomic<bool> go{false};
    std::vector<std::thread> threads;
    for (int i = 0; i < 2; ++i)
      threads.emplace_back([&, i] {
        while (!go.load()) std::this_thread::yield();
        opened[i] = open_store(where);
      });
    go = true;
    for (auto& th : threads) th.join();
    for (auto& o : opened) {
      ASSERT_TRUE(o.ok()) << o.error().message;
      Registered r = must((*o)->register_robot(new_robot("unit-1")));
      EXPECT_EQ(r.robot.rrn.size(), 16u);
    }
  }
}

TEST_P(StoreTest, OpenStoreChoosesTheBackend) {
  auto s = open_store(fresh_spec("chosen"));
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ((*s)->backend(), GetParam());
  if (postgres()) {
    // libpq's key=value form works through open_postgres directly.
    auto kv = open_postgres(pg_server()->conninfo(pg_database_));
    ASSERT_TRUE(kv.ok()) << kv.error().message;
    EXPECT_FALSE(open_store("postgresql://rcan@127.0.0.1:1/nothing").ok());
  } else {
    EXPECT_FALSE(open_store(tmp_.file("no/such/dir/registry.db")).ok());
  }
}

TEST_P(StoreTest, ReconnectsWhenTheServerDropsTheConnections) {
  if (!postgres()) GTEST_SKIP() << "SQLite has no connection to lose";
  Robot r = must(store_->register_robot(new_robot("unit-1"))).robot;
  // Several pooled connections, all idle, then all killed by the server.
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&] {
      for (int i = 0; i < 20; ++i) EXPECT_TRUE(must(store_->get_robot(r.rrn)).has_value());
    });
  for (auto& th : threads) th.join();
  auto killed = pg_server()->sql(
      "SELECT count(pg_terminate_backend(pid)) FROM pg_stat_activity WHERE datname = '" +
      pg_database_ + "'");
  ASSERT_EQ(killed.exit_code, 0) << killed.err;
  EXPECT_NE(killed.out, "0\n");
  auto got = must(store_->get_robot(r.rrn));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->rrn, r.rrn);
  EXPECT_TRUE(must(store_->register_robot(new_robot("unit-2"))).created);
}

// ---- the token authority (authority_store.cpp, over both backends)

TEST_P(StoreTest, AuthoritySigningKeys) {
  auto none = store_->signing_keys();
  ASSERT_TRUE(none.ok()) << none.error().message;
  EXPECT_TRUE(none->empty());
  ASSERT_TRUE(store_->put_signing_key({"k2", "seed-2", 2000, 5000}).ok());
  ASSERT_TRUE(store_->put_signing_key({"k1", "seed-1", 1000, 1000}).ok());
  auto dup = store_->put_signing_key({"k1", "x", 1, 1});
  ASSERT_FALSE(dup.ok());
  EXPECT_EQ(dup.error().reason, "unique_violation");
  auto keys = store_->signing_keys();
  ASSERT_TRUE(keys.ok());
  ASSERT_EQ(keys->size(), 2u);
  EXPECT_EQ((*keys)[0].kid, "k1");  // by sign_from
  EXPECT_EQ((*keys)[1].seed, "seed-2");
  EXPECT_EQ((*keys)[1].sign_from_ms, 5000);
  EXPECT_TRUE(*store_->delete_signing_key("k1"));
  EXPECT_FALSE(*store_->delete_signing_key("k1"));
  // Another instance on the same database sees them.
  auto other = open();
  ASSERT_TRUE(other.ok());
  EXPECT_EQ((*other)->signing_keys()->size(), 1u);
}

TEST_P(StoreTest, AuthorityClientsAndGrants) {
  Client c{"rcc_1", "ops'; DROP TABLE robots;--", "client_secret", "salt", "hash", "", "key1",
           at(1)};
  ASSERT_TRUE(store_->put_client(c).ok());
  auto got = store_->get_client("rcc_1");
  ASSERT_TRUE(got.ok() && got->has_value());
  EXPECT_EQ((*got)->name, c.name);
  EXPECT_EQ((*got)->owner_key_id, "key1");
  EXPECT_FALSE(store_->get_client("rcc_2")->has_value());
  EXPECT_EQ(store_->list_clients()->size(), 1u);
  Grant g;
  g.principal = "rcc_1";
  g.rrn = "rrn-000000000001";
  g.role = "user";
  g.scope = "status teleop";
  g.max_ttl_s = 600;
  g.created_by = "apikey:key1";
  g.created_at = at(2);
  auto id1 = store_->add_grant(g);
  ASSERT_TRUE(id1.ok()) << id1.error().message;
  g.principal = "user:key9";
  g.fleet = "yard";
  auto id2 = store_->add_grant(g);
  ASSERT_TRUE(id2.ok());
  EXPECT_GT(*id2, *id1);
  auto of = store_->grants_of("rcc_1");
  ASSERT_TRUE(of.ok());
  ASSERT_EQ(of->size(), 1u);
  EXPECT_EQ((*of)[0].rrn, "RRN-000000000001");
  EXPECT_EQ((*of)[0].scope, "status teleop");
  EXPECT_EQ((*of)[0].max_ttl_s, 600);
  EXPECT_EQ((*store_->get_grant(*id2))->fleet, "yard");
  EXPECT_EQ(store_->list_grants()->size(), 2u);
  EXPECT_TRUE(*store_->delete_grant(*id1));
  EXPECT_FALSE(*store_->delete_grant(*id1));
  EXPECT_TRUE(store_->grants_of("rcc_1")->empty());
  EXPECT_TRUE(*store_->delete_client("rcc_1"));
  EXPECT_FALSE(store_->get_client("rcc_1")->has_value());
}

TEST_P(StoreTest, AuthorityRevocationsAndUsedJtis) {
  Revocation r;
  r.jti = "j1";
  r.exp = 1800000000;
  r.revoked_at = at(1);
  r.revoked_ms = 5000;
  r.reason = "lost";
  r.revoked_by = "apikey:a";
  auto s1 = store_->add_revocation(r);
  ASSERT_TRUE(s1.ok()) << s1.error().message;
  Revocation by_sub;
  by_sub.sub = "rcc_9";
  by_sub.revoked_at = at(2);
  by_sub.revoked_ms = 9000;
  auto s2 = store_->add_revocation(by_sub);
  ASSERT_TRUE(s2.ok());
  EXPECT_GT(*s2, *s1);
  auto other = open();  // a second instance continues the sequence
  ASSERT_TRUE(other.ok());
  auto s3 = (*other)->add_revocation(by_sub);
  ASSERT_TRUE(s3.ok());
  EXPECT_GT(*s3, *s2);
  auto all = store_->revocations_since(0, 500);
  ASSERT_TRUE(all.ok()) << all.error().message;
  ASSERT_EQ(all->size(), 3u);
  EXPECT_EQ((*all)[0].jti, "j1");
  ASSERT_TRUE((*all)[0].exp.has_value());
  EXPECT_EQ(*(*all)[0].exp, 1800000000);
  EXPECT_FALSE((*all)[1].exp.has_value());
  EXPECT_EQ(store_->revocations_since(*s1, 500)->size(), 2u);
  EXPECT_EQ(store_->revocations_since(*s1, 1)->size(), 1u);
  EXPECT_TRUE(store_->revocations_since(*s3, 500)->empty());
  EXPECT_TRUE(*store_->is_revoked("j1", "anyone", 0));
  EXPECT_FALSE(*store_->is_revoked("j2", "anyone", 0));
  EXPECT_TRUE(*store_->is_revoked("j2", "rcc_9", 8000));    // issued before the sub revocation
  EXPECT_FALSE(*store_->is_revoked("j2", "rcc_9", 10000));  // issued after

  EXPECT_TRUE(*store_->use_jti("c:a", 2000, 1000));
  EXPECT_FALSE(*store_->use_jti("c:a", 2000, 1500));  // replay
  EXPECT_TRUE(*store_->use_jti("c:a", 9000, 3000));   // expired entry dropped
}

TEST_P(StoreTest, AuthorityDeviceCodes) {
  DeviceCode d;
  d.device_hash = "h1";
  d.user_code = "BCDF-GHJK";
  d.client_id = "rcc_1";
  d.resource = "RRN-000000000001";
  d.scope = "status";
  d.expires_ms = 600000;
  ASSERT_TRUE(store_->put_device_code(d).ok());
  auto dup = d;
  dup.device_hash = "h2";
  EXPECT_FALSE(store_->put_device_code(dup).ok());  // user codes are unique
  auto got = store_->device_by_user_code("BCDF-GHJK");
  ASSERT_TRUE(got.ok() && got->has_value());
  EXPECT_EQ((*got)->status, "pending");
  ASSERT_TRUE(store_->touch_device("h1", 1234, 10).ok());
  EXPECT_EQ((*store_->device_by_hash("h1"))->interval_s, 10);
  EXPECT_EQ((*store_->device_by_hash("h1"))->last_poll_ms, 1234);
  EXPECT_TRUE(*store_->decide_device("BCDF-GHJK", "approved", "user:k"));
  EXPECT_FALSE(*store_->decide_device("BCDF-GHJK", "denied", "user:x"));  // decided once
  EXPECT_EQ((*store_->device_by_hash("h1"))->subject, "user:k");
  EXPECT_TRUE(*store_->delete_device("h1"));
  EXPECT_FALSE(*store_->delete_device("h1"));
}

INSTANTIATE_TEST_SUITE_P(Backends, StoreTest, ::testing::Values("sqlite", "postgresql"),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param; });

}  // namespace
}  // namespace rcan::registry::testing

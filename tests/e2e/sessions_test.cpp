// Control sessions: the state machines as units (SessionTable, Ownership, PartitionMonitor,
// consent notifications) with explicit clocks, the diagrams in docs/SESSIONS.md checked against
// the code's transition tables, and the claim / release / handoff / queue / pre-emption /
// expiry / guest-limit transitions and races against a real rcand over HTTP and WebSocket.
#include "node/control/sessions.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <sstream>
#include <thread>

#include "config/config.h"
#include "node/control/consent.h"
#include "node/control/control_machine.h"
#include "node/control/ownership.h"
#include "node/control/partition.h"
#include "node/vocabulary/refusal_ledger.h"
#include "node_fixture.h"
#include "rcan/errors.h"
#include "runtime/http_client.h"

namespace rcan {
namespace {

using node::ClaimOutcome;
using node::ControlState;
using node::Principal;
using node::PrincipalId;
using node::SessionTable;
using test::ControlNode;
using test::HttpReply;
using test::parse_json;

Principal who(const std::string& sub, Role role) {
  Principal p;
  p.authenticated = true;
  p.issuer = "ops.example";
  p.sub = sub;
  p.role = role;
  p.scopes = {"control", "config"};
  return p;
}

// A principal named in a request: issuer and subject.
PrincipalId named(const std::string& sub) { return PrincipalId{"ops.example", sub}; }

constexpr int64_t kWall = 1'750'000'000'000;

std::vector<std::string> mermaid_blocks(const std::string& text) {
  std::vector<std::string> out;
  size_t pos = 0;
  while ((pos = text.find("```mermaid\n", pos)) != std::string::npos) {
    pos += 11;
    size_t end = text.find("```", pos);
    if (end == std::string::npos) break;
    out.push_back(text.substr(pos, end - pos));
    pos = end + 3;
  }
  return out;
}

TEST(SessionMachine, DiagramsInTheDocsAreTheCodesTransitionTables) {
  std::ifstream in(std::string(RCAN_TESTDATA_DIR) + "/../../docs/SESSIONS.md");
  ASSERT_TRUE(in.good());
  std::stringstream ss;
  ss << in.rdbuf();
  auto blocks = mermaid_blocks(ss.str());
  ASSERT_EQ(blocks.size(), 2u);
  EXPECT_EQ(blocks[0], node::mermaid(node::control_transitions()));
  EXPECT_EQ(blocks[1], node::mermaid(node::ownership_transitions()));
}

TEST(SessionMachine, SameRoleQueuesFifoAndTheHeadIsPromotedOnRelease) {
  SessionTable t;
  int64_t now = 1000;
  auto a = t.claim(who("a", Role::kUser), std::nullopt, now, kWall);
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->outcome, ClaimOutcome::kGranted);
  auto b = t.claim(who("b", Role::kUser), std::nullopt, now, kWall);
  auto c = t.claim(who("c", Role::kUser), std::nullopt, now, kWall);
  ASSERT_TRUE(b.ok() && c.ok());
  EXPECT_EQ(b->outcome, ClaimOutcome::kQueued);
  EXPECT_EQ(b->queue_position, 1u);
  EXPECT_EQ(c->queue_position, 2u);
  EXPECT_EQ(t.claim(who("b", Role::kUser), std::nullopt, now, kWall)->queue_position,
            1u);  // unchanged on re-ask
  // A lower role is denied outright; it does not queue.
  auto g = t.claim(who("g", Role::kGuest), std::nullopt, now, kWall);
  ASSERT_FALSE(g.ok());
  EXPECT_EQ(g.error().code, ErrorCode::kControlConflict);
  ASSERT_TRUE(t.release(a->session.id, who("a", Role::kUser), now + 1, kWall).ok());
  auto changes = t.take_changes();
  ASSERT_EQ(changes.size(), 1u);
  EXPECT_EQ(changes[0].event, node::ControlEvent::kPromote);
  EXPECT_EQ(changes[0].session.sub, "b");
  EXPECT_EQ(t.controller(now + 1)->sub, "b");
  EXPECT_EQ(t.claim(who("c", Role::kUser), std::nullopt, now + 1, kWall)->queue_position, 1u);
  EXPECT_EQ(t.state(now + 1), ControlState::kHeld);
  EXPECT_EQ(t.transition_violations(), 0u);
}

TEST(SessionMachine, HigherRolePreemptsAndTheBodyOnlyLowers) {
  SessionTable t;
  auto u = t.claim(who("u", Role::kUser), std::nullopt, 1000, kWall);
  ASSERT_TRUE(u.ok());
  // An owner asking for USER is a USER: same role, so it queues.
  auto low = t.claim(who("o", Role::kOwner), Role::kUser, 1000, kWall);
  ASSERT_TRUE(low.ok());
  EXPECT_EQ(low->outcome, ClaimOutcome::kQueued);
  auto o = t.claim(who("o", Role::kOwner), std::nullopt, 1000, kWall);
  ASSERT_TRUE(o.ok());
  EXPECT_EQ(o->outcome, ClaimOutcome::kGranted);
  ASSERT_TRUE(o->preempted.has_value());
  EXPECT_EQ(o->preempted->id, u->session.id);
  EXPECT_EQ(o->session.role, Role::kOwner);
  EXPECT_FALSE(t.live(u->session.id, 1000));
  // A USER token asking for OWNER stays USER.
  SessionTable t2;
  EXPECT_EQ(t2.claim(who("x", Role::kUser), Role::kOwner, 1000, kWall)->session.role, Role::kUser);
  EXPECT_EQ(t.transition_violations(), 0u);
}

TEST(SessionMachine, ExpiryNeedsAnExplicitRenewal) {
  SessionTable t;
  Principal a = who("a", Role::kUser);
  auto s = t.claim(a, std::nullopt, 0, kWall);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->session.expires_mono_ms, 3600 * 1000);  // PROFILE.md §5: USER 1 h
  auto r = t.renew(s->session.id, a, 1800 * 1000, kWall);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->expires_mono_ms, (1800 + 3600) * 1000);
  EXPECT_FALSE(t.renew(s->session.id, who("b", Role::kUser), 1900 * 1000, kWall).ok());
  t.tick((1800 + 3600) * 1000, kWall);
  auto changes = t.take_changes();
  ASSERT_EQ(changes.size(), 1u);
  EXPECT_EQ(changes[0].event, node::ControlEvent::kExpire);
  EXPECT_EQ(t.expired_session_of(a.key()), s->session.id);
  auto late = t.renew(s->session.id, a, (1800 + 3601) * 1000, kWall);
  ASSERT_FALSE(late.ok());
  EXPECT_EQ(late.error().code, ErrorCode::kSessionExpired);
  ASSERT_TRUE(t.claim(a, std::nullopt, (1800 + 3602) * 1000, kWall).ok());
  EXPECT_FALSE(t.expired_session_of(a.key()).has_value());
  EXPECT_EQ(t.transition_violations(), 0u);
}

TEST(SessionMachine, HandoffReservesTheWindowUntilItCloses) {
  SessionTable t;
  auto s = t.claim(who("a", Role::kUser), std::nullopt, 0, kWall);
  ASSERT_TRUE(
      t.handoff(s->session.id, who("a", Role::kUser), named("b"), Role::kUser, 30000, 10).ok());
  EXPECT_EQ(t.state(10), ControlState::kReserved);
  EXPECT_FALSE(t.claim(who("c", Role::kCreator), std::nullopt, 20, kWall).ok());
  t.tick(30010, kWall);
  auto ch = t.take_changes();
  ASSERT_EQ(ch.size(), 1u);
  EXPECT_EQ(ch[0].event, node::ControlEvent::kWindowClose);
  EXPECT_EQ(t.state(30010), ControlState::kAvailable);
  EXPECT_TRUE(t.claim(who("c", Role::kUser), std::nullopt, 30011, kWall).ok());
  // The named target claims inside the window, capped at the handoff's role.
  SessionTable t2;
  auto s2 = t2.claim(who("a", Role::kUser), std::nullopt, 0, kWall);
  ASSERT_TRUE(
      t2.handoff(s2->session.id, who("a", Role::kUser), named("b"), Role::kUser, 30000, 0).ok());
  auto b = t2.claim(who("b", Role::kOwner), std::nullopt, 100, kWall);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->session.role, Role::kUser);
  EXPECT_EQ(t.transition_violations() + t2.transition_violations(), 0u);
}

TEST(SessionMachine, FleetPolicyDecidesSameRoleFleetAgainstIndividual) {
  for (auto policy : {node::FleetPolicy::kRole, node::FleetPolicy::kFleetWins,
                      node::FleetPolicy::kIndividualWins}) {
    SessionTable t;
    node::ControlOptions o;
    o.fleet_policy = policy;
    t.set_options(o);
    ASSERT_TRUE(t.claim(who("ind", Role::kUser), std::nullopt, false, 0, kWall).ok());
    auto f = t.claim(who("fleet", Role::kUser), std::nullopt, true, 1, kWall);
    ASSERT_TRUE(f.ok());
    EXPECT_EQ(f->outcome, policy == node::FleetPolicy::kFleetWins ? ClaimOutcome::kGranted
                                                                  : ClaimOutcome::kQueued)
        << node::fleet_policy_name(policy);
    SessionTable t2;
    t2.set_options(o);
    ASSERT_TRUE(t2.claim(who("fleet", Role::kUser), std::nullopt, true, 0, kWall).ok());
    auto i = t2.claim(who("ind", Role::kUser), std::nullopt, false, 1, kWall);
    EXPECT_EQ(i->outcome, policy == node::FleetPolicy::kIndividualWins ? ClaimOutcome::kGranted
                                                                       : ClaimOutcome::kQueued);
  }
}

TEST(SessionMachine, LeaseBoundsSessionsAndItsEndRevokesEverythingDerived) {
  SessionTable t;
  Principal owner = who("owner", Role::kOwner), leasee = who("lee", Role::kLeasee),
            user = who("u", Role::kUser), outsider = who("out", Role::kUser);
  EXPECT_FALSE(t.grant_lease(user, named("lee"), 10000, kWall).ok());
  auto l = t.grant_lease(owner, named("lee"), 10000, kWall);
  ASSERT_TRUE(l.ok());
  EXPECT_FALSE(t.grant_lease(owner, named("other"), 10000, kWall).ok());  // one at a time
  EXPECT_FALSE(t.grant_within_lease(outsider, l->id, named("u"), Role::kUser, 5000, kWall).ok());
  EXPECT_FALSE(t.grant_within_lease(leasee, l->id, named("u"), Role::kOwner, 5000, kWall).ok());
  ASSERT_TRUE(t.grant_within_lease(leasee, l->id, named("u"), Role::kUser, 5000, kWall).ok());
  auto denied = t.claim(outsider, std::nullopt, 0, kWall);
  ASSERT_FALSE(denied.ok());
  EXPECT_EQ(denied.error().field, "lease");
  auto us = t.claim(user, std::nullopt, 0, kWall);
  ASSERT_TRUE(us.ok());
  EXPECT_EQ(us->session.lease_id, l->id);
  EXPECT_EQ(us->session.expires_mono_ms, 5000);  // the grant's end, not USER's hour
  // Persistence round trip keeps the lease and its grant.
  SessionTable copy;
  copy.load_json(t.persist_json(), kWall);
  ASSERT_EQ(copy.leases(kWall).size(), 1u);
  EXPECT_EQ(copy.leases(kWall)[0].grants.size(), 1u);
  t.tick(5000, kWall + 5000);
  auto ch = t.take_changes();
  ASSERT_FALSE(ch.empty());
  EXPECT_EQ(ch[0].event, node::ControlEvent::kRevoke);
  EXPECT_EQ(ch[0].reason, "the grant within lease " + l->id + " ended");
  auto ls = t.claim(leasee, std::nullopt, 5001, kWall + 5001);
  ASSERT_TRUE(ls.ok());
  EXPECT_EQ(ls->session.lease_id, l->id);
  // The two clocks are read one after the other: the session's monotonic end can come a
  // moment before the wall clock reaches the lease's end. It is still the lease that ended it.
  t.tick(10000, kWall + 9999);
  ch = t.take_changes();
  ASSERT_EQ(ch.size(), 1u);
  EXPECT_EQ(ch[0].event, node::ControlEvent::kRevoke);
  EXPECT_EQ(ch[0].session.sub, "lee");
  EXPECT_EQ(ch[0].reason, "the lease " + l->id + " ended");
  t.tick(10000, kWall + 10000);
  ch = t.take_changes();
  ASSERT_EQ(ch.size(), 1u);
  EXPECT_EQ(ch[0].event, node::ControlEvent::kLeaseEnd);
  EXPECT_TRUE(t.leases(kWall + 10000).empty());
  EXPECT_TRUE(t.claim(outsider, std::nullopt, 10001, kWall + 10001).ok());
  EXPECT_EQ(t.transition_violations(), 0u);
}

TEST(OwnershipMachine, RequestAcceptCancelExpireAndFormerOwnersAreCapped) {
  node::Ownership o;
  o.set_window_ms(1000);
  Principal owner = who("alice", Role::kOwner), bob = who("bob", Role::kUser),
            eve = who("eve", Role::kOwner);
  EXPECT_FALSE(o.request(bob, named("bob"), "", kWall).ok());
  auto r = o.request(owner, named("bob"), "sale", kWall);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(o.state(kWall), node::OwnershipState::kTransferPending);
  EXPECT_EQ(o.request(owner, named("carol"), "", kWall).error().code, ErrorCode::kControlConflict);
  EXPECT_EQ(o.accept(eve, r->id, "x", kWall).error().code, ErrorCode::kInsufficientPrivileges);
  EXPECT_EQ(o.accept(bob, r->id, "", kWall).error().code, ErrorCode::kSchemaValidationFailed);
  ASSERT_TRUE(o.cancel(owner, kWall).ok());
  EXPECT_EQ(o.state(kWall), node::OwnershipState::kOwned);
  // Expiry path: accepting after the window fails; expire() records it once.
  auto r2 = o.request(owner, named("bob"), "", kWall);
  ASSERT_TRUE(r2.ok());
  EXPECT_EQ(o.accept(bob, r2->id, "paid", kWall + 1000).error().code, ErrorCode::kSessionExpired);
  EXPECT_TRUE(o.expire(kWall + 1000).has_value());
  EXPECT_FALSE(o.expire(kWall + 1000).has_value());
  // Accept path.
  auto r3 = o.request(owner, named("bob"), "", kWall + 2000);
  ASSERT_TRUE(r3.ok());
  o.note_user("someone");
  int cleared = 0;
  o.on_clear([&] { ++cleared; });
  ASSERT_TRUE(o.accept(bob, r3->id, "invoice-7", kWall + 2001).ok());
  o.run_clear_hooks();
  EXPECT_EQ(cleared, 1);
  EXPECT_EQ(o.owner(), named("bob"));
  Principal old = owner;
  o.cap(old);
  EXPECT_EQ(old.role, Role::kGuest);
  EXPECT_FALSE(o.request(eve, named("eve"), "", kWall + 3000)
                   .ok());  // another OWNER token is not the owner now
  node::Ownership copy;
  copy.load_json(o.persist_json());
  EXPECT_EQ(copy.owner(), named("bob"));
  Principal old2 = owner;
  copy.cap(old2);
  EXPECT_EQ(old2.role, Role::kGuest);
  EXPECT_EQ(o.transition_violations(), 0u);
}

// The node's control tick sleeps while nothing waits for a time (Node::pump): each piece of
// timed control state says when it is quiet, and calls its change hook on every change, so that
// the tick wakes when something timed begins.
TEST(ControlTick, EveryTimedStateSaysWhenItIsQuietAndCallsItsHookWhenItChanges) {
  int calls = 0;
  auto hook = [&] { ++calls; };

  SessionTable t;
  t.on_change(hook);
  EXPECT_TRUE(t.quiet());
  int64_t now = 1000;
  auto a = t.claim(who("a", Role::kUser), std::nullopt, now, kWall);
  ASSERT_TRUE(a.ok());
  EXPECT_GT(calls, 0);
  EXPECT_FALSE(t.quiet());  // a holder: its expiry is timed
  ASSERT_TRUE(t.release(a->session.id, who("a", Role::kUser), now, kWall).ok());
  (void)t.take_changes();
  EXPECT_TRUE(t.quiet());

  calls = 0;
  node::Ownership o;
  o.on_change(hook);
  EXPECT_TRUE(o.quiet());
  ASSERT_TRUE(o.request(who("alice", Role::kOwner), named("bob"), "", kWall).ok());
  EXPECT_GT(calls, 0);
  EXPECT_FALSE(o.quiet());  // a pending transfer: its window is timed
  ASSERT_TRUE(o.expire(kWall + 25 * 3600 * 1000LL).has_value());
  EXPECT_TRUE(o.quiet());

  calls = 0;
  node::ConsentBook c;
  c.on_change(hook);
  EXPECT_TRUE(c.quiet());
  node::ConsentRequest r;
  r.requester_sub = "someone";
  r.scopes = {"control"};
  ASSERT_TRUE(c.add(r, kWall).ok());
  EXPECT_GT(calls, 0);
  EXPECT_FALSE(c.quiet());  // a pending request: its expiry is timed
  EXPECT_EQ(c.expire(kWall + 25 * 3600 * 1000LL).size(), 1u);
  EXPECT_TRUE(c.quiet());

  calls = 0;
  node::RefusalLedger l;
  l.on_change(hook);
  EXPECT_TRUE(l.quiet());
  EXPECT_TRUE(l.admit({"192.0.2.1", "AUTH_FAILED", "AUTH_INVALID", "/x"}, kWall));
  EXPECT_EQ(calls, 1);
  EXPECT_FALSE(l.admit({"192.0.2.1", "AUTH_FAILED", "AUTH_INVALID", "/x"}, kWall + 1));
  EXPECT_EQ(calls, 1);      // the same window: nothing new is timed
  EXPECT_FALSE(l.quiet());  // an open window: its summary is due when it closes
  EXPECT_EQ(l.due(kWall + 3600 * 1000LL).size(), 1u);
  EXPECT_TRUE(l.quiet());

  t.on_change({});  // removed: changes no longer call it
  calls = 0;
  ASSERT_TRUE(t.claim(who("b", Role::kUser), std::nullopt, now, kWall).ok());
  EXPECT_EQ(calls, 0);
}

TEST(ConsentNotification, CloudFunctionIdentityIsInTitleBodyAndHighlight) {
  node::ConsentRequest r;
  r.requester_sub = "firebase-cloud-functions";
  r.sender_type = "cloud_function";
  r.cloud_provider = "firebase";
  r.function_name = "castor-bridge-v2";
  r.on_behalf_of = "Craig";
  r.scopes = {"control"};
  json::Value n = node::consent_notification(r, "Robot B");
  EXPECT_EQ(n.get("title")->as_string(), "\xE2\x9A\xA0\xEF\xB8\x8F Service Consent Request");
  EXPECT_EQ(n.get("body")->as_string(),
            "Firebase function 'castor-bridge-v2' (on behalf of Craig) is requesting\naccess to "
            "Robot B with scope: [control]");
  EXPECT_EQ(n.get("highlight")->as_string(), "cloud_function: castor-bridge-v2 via firebase");
  node::ConsentRequest h;
  h.requester_sub = "Craig";
  h.scopes = {"control"};
  json::Value hn = node::consent_notification(h, "Robot B");
  EXPECT_EQ(hn.get("title")->as_string(), "Consent Request");
  EXPECT_EQ(hn.get("body")->as_string(),
            "Craig is requesting access to Robot B with scope: [control]");
  EXPECT_EQ(hn.get("highlight"), nullptr);
}

TEST(PartitionMachine, ModesFollowReachabilityAndTheCache) {
  node::PartitionMonitor m;
  EXPECT_EQ(m.record(false, kWall).second,
            node::NetMode::kNormal);  // nothing configured: nothing to reach
  node::PartitionOptions o;
  o.issuer_url = "http://127.0.0.1:9/jwks";
  o.key_ttl_ms = 10000;
  m.configure(o);
  EXPECT_EQ(m.record(false, kWall).second, node::NetMode::kLockdown);  // never reached
  EXPECT_EQ(m.record(true, kWall + 1).second, node::NetMode::kNormal);
  Principal a = who("a", Role::kUser);
  a.token_exp = (kWall + 60000) / 1000;
  m.note_validated(a, kWall + 1);
  EXPECT_EQ(m.record(false, kWall + 2).second, node::NetMode::kOfflineAutonomous);
  EXPECT_TRUE(m.cached(a, kWall + 3));
  EXPECT_FALSE(m.cached(who("b", Role::kUser), kWall + 3));
  EXPECT_EQ(m.record(false, kWall + 10001).second, node::NetMode::kLockdown);
  EXPECT_FALSE(m.cached(a, kWall + 10001));
  node::PartitionMonitor copy;
  copy.configure(o);
  copy.load_json(m.persist_json(), kWall + 5);
  EXPECT_TRUE(copy.cached(a, kWall + 5));
}

TEST(HttpFetch, UrlsAndStatusLines) {
  auto u = rcan::parse_http_url("http://127.0.0.1:8080/jwks.json");
  ASSERT_TRUE(u.ok());
  EXPECT_EQ(u->host, "127.0.0.1");
  EXPECT_EQ(u->port, 8080);
  EXPECT_EQ(u->path, "/jwks.json");
  EXPECT_FALSE(rcan::parse_http_url("https://x/").ok());
  EXPECT_FALSE(rcan::parse_http_url("http://:80/").ok());
  EXPECT_FALSE(rcan::parse_http_url("http://h:99999999/").ok());
  EXPECT_FALSE(rcan::parse_http_url("http://h/a b").ok());
  EXPECT_EQ(rcan::parse_status_line("HTTP/1.1 204 No Content"), 204);
  EXPECT_EQ(rcan::parse_status_line("HTTP/1.0 200"), 200);
  EXPECT_EQ(rcan::parse_status_line("HTTP/1.1 2x0 OK"), 0);
  EXPECT_EQ(rcan::parse_status_line("SSH-2.0-x"), 0);
}

TEST(ControlConfig, TheControlBlockAndTheIssuerProbeAreValidated) {
  config::ConfigOptions o;
  o.device_id = "0a1b2c3d";
  std::string base(config::default_config_yaml());
  auto ok = config::parse_config_text(
      base +
          "control:\n  fleet_policy: fleet_wins\n  handoff_window_s: 5\n"
          "  consent_webhook: http://127.0.0.1:9000/hook\n"
          "offline:\n  issuer_url: http://issuer.local/jwks.json\n  issuer_poll_ms: 250\n",
      o);
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_EQ(ok->control.fleet_policy, "fleet_wins");
  EXPECT_EQ(ok->control.handoff_window_s, 5u);
  EXPECT_EQ(ok->control.transfer_window_s, 86400u);
  EXPECT_EQ(ok->offline.issuer_poll_ms, 250u);
  auto bad_policy = config::parse_config_text(base + "control:\n  fleet_policy: loudest\n", o);
  ASSERT_FALSE(bad_policy.ok());
  EXPECT_EQ(bad_policy.error().field, "control.fleet_policy");
  auto bad_url = config::parse_config_text(base + "control:\n  consent_webhook: https://x/\n", o);
  ASSERT_FALSE(bad_url.ok());
  EXPECT_EQ(bad_url.error().field, "control.consent_webhook");
  auto unknown = config::parse_config_text(base + "control:\n  queue_size: 3\n", o);
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.error().reason, "unknown_key");
}

// ------------------------------------------------------------------------------------------
// Against a real rcand.

std::string session_of(const HttpReply& r) {
  json::Value v = parse_json(r.body);
  const json::Value* p = v.get("payload");
  const json::Value* s = p ? p->get("session_id") : nullptr;
  return s && s->is_string() ? s->as_string() : "";
}

class SessionsE2E : public ::testing::Test {
 protected:
  void start(const std::string& yaml = "") {
    node_ = std::make_unique<ControlNode>(dir_.path() + "/n", yaml);
    ASSERT_TRUE(node_->start());
    owner_ = node_->token("owner", "owner-1", {"control", "config", "status"});
  }
  ControlNode& n() { return *node_; }
  test::TempDir dir_;
  std::unique_ptr<ControlNode> node_;
  std::string owner_;
};

TEST_F(SessionsE2E, TwoClaimsAtOnceGrantOneAndQueueTheOtherWhichIsPromotedOnRelease) {
  start();
  std::string a = n().token("user", "racer-a"), b = n().token("user", "racer-b");
  test::Stream sa(n().port(), a), sb(n().port(), b);
  HttpReply ra, rb;
  std::atomic<int> ready{0};
  auto go = [&](const std::string& tok, HttpReply& out) {
    ready.fetch_add(1);
    while (ready.load() < 2) std::this_thread::yield();
    out = n().post("/rcan/v1/auth/claim", "{}", tok);
  };
  std::thread t1(go, std::cref(a), std::ref(ra)), t2(go, std::cref(b), std::ref(rb));
  t1.join();
  t2.join();
  ASSERT_TRUE((ra.status == 200) != (rb.status == 200)) << ra.body << "\n" << rb.body;
  HttpReply& won = ra.status == 200 ? ra : rb;
  HttpReply& lost = ra.status == 200 ? rb : ra;
  const std::string& winner = ra.status == 200 ? a : b;
  test::Stream& waiting = ra.status == 200 ? sb : sa;
  EXPECT_EQ(lost.status, 409);
  EXPECT_EQ(test::error_code_of(lost), "CONTROL_CONFLICT");
  json::Value lv = parse_json(lost.body);
  EXPECT_TRUE(lv.get("payload")->get("queued")->as_bool());
  EXPECT_EQ(lv.get("payload")->get("queue_position")->as_int(), 1);
  json::Value q = parse_json(n().get("/rcan/v1/auth/queue", owner_).body);
  ASSERT_EQ(q.get("queue")->as_array().size(), 1u);
  // The holder releases: the queued claimant is promoted and told on its stream.
  HttpReply rel = n().call("DELETE", "/rcan/v1/auth/release",
                           "{\"session_id\":\"" + session_of(won) + "\"}", winner);
  ASSERT_EQ(rel.status, 200) << rel.body;
  auto promoted = waiting.wait_for("PROMOTED");
  ASSERT_TRUE(promoted.has_value());
  EXPECT_EQ(promoted->get("type")->as_string(), "GRANTED");
  std::string sid = promoted->get("session_id")->as_string();
  json::Value st = parse_json(n().get("/rcan/v1/status", owner_).body);
  EXPECT_EQ(st.get("control")->as_string(), "HELD");
  EXPECT_EQ(st.get("sessions")->as_array()[0].get("session_id")->as_string(), sid);
  EXPECT_FALSE(n().audit_eventually("CLAIM_QUEUED", owner_).empty());
  EXPECT_FALSE(n().audit_eventually("CLAIM_PROMOTED", owner_).empty());
}

// A closed tab leaves the queue: the claimant's last stream closes and no other opens within
// control.queue_stream_grace_s. A claimant that never had a stream (the CLI) keeps its place.
TEST_F(SessionsE2E, AQueuedClaimantWhoseLastStreamClosesLeavesTheQueue) {
  start("control:\n  queue_stream_grace_s: 1\n");
  std::string holder = n().token("user", "holder"), tab = n().token("user", "tab-user"),
              cli = n().token("user", "cli-user");
  ASSERT_EQ(n().post("/rcan/v1/auth/claim", "{}", holder).status, 200);
  auto first = std::make_unique<test::Stream>(n().port(), tab);
  auto second = std::make_unique<test::Stream>(n().port(), tab);
  HttpReply qt = n().post("/rcan/v1/auth/claim", "{}", tab);
  HttpReply qc = n().post("/rcan/v1/auth/claim", "{}", cli);
  ASSERT_EQ(qt.status, 409) << qt.body;
  ASSERT_EQ(qc.status, 409) << qc.body;
  auto queued = [&] {
    std::vector<std::string> subs;
    json::Value q = parse_json(n().get("/rcan/v1/auth/queue", owner_).body);
    for (const auto& e : q.get("queue")->as_array())
      if (const json::Value* u = e.get("user_id"); u && u->is_string())
        subs.push_back(u->as_string());
    return subs;
  };
  ASSERT_EQ(queued(), (std::vector<std::string>{"tab-user", "cli-user"}));
  // One of two tabs closes: the other still streams, so the claim stays past the grace.
  first.reset();
  std::this_thread::sleep_for(std::chrono::milliseconds(1800));
  EXPECT_EQ(queued(), (std::vector<std::string>{"tab-user", "cli-user"}));
  // The last one closes: the claim is dropped, audited and the CLI claimant moves up.
  second.reset();
  ASSERT_TRUE(ControlNode::eventually([&] { return queued().size() == 1; }, 5000));
  EXPECT_EQ(queued(), (std::vector<std::string>{"cli-user"}));
  auto dropped = n().audit_eventually("CLAIM_DROPPED", owner_);
  ASSERT_EQ(dropped.size(), 1u);
  EXPECT_EQ(dropped[0].get("reason")->as_string(), "stream_closed");
  EXPECT_EQ(dropped[0].get("sub")->as_string(), "tab-user");
  // The CLI claimant, which never had a stream, keeps its place.
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  EXPECT_EQ(queued(), (std::vector<std::string>{"cli-user"}));
}

TEST_F(SessionsE2E, ClaimDuringTheHandoffWindowIsDeniedUntilItCloses) {
  start("control:\n  handoff_window_s: 1\n");
  std::string alice = n().token("user", "alice"),
              carol = n().token("owner", "carol", {"control", "config"});
  test::Stream watcher(n().port(), owner_);
  HttpReply c = n().post("/rcan/v1/auth/claim", "{}", alice);
  ASSERT_EQ(c.status, 200);
  HttpReply h =
      n().post("/rcan/v1/handoff",
               "{\"session_id\":\"" + session_of(c) + "\",\"target_user_id\":\"bob\"}", alice);
  ASSERT_EQ(h.status, 200) << h.body;
  auto avail = watcher.wait_for("AVAILABLE");
  ASSERT_TRUE(avail.has_value());
  EXPECT_EQ(avail->get("reserved_for")->as_string(), "bob");
  EXPECT_EQ(n().post("/rcan/v1/auth/claim", "{}", carol).status, 409);  // even a higher role waits
  EXPECT_EQ(parse_json(n().get("/rcan/v1/status").body).get("control")->as_string(), "RESERVED");
  // Nobody came: the window closes and the first claim wins again.
  ASSERT_TRUE(ControlNode::eventually(
      [&] {
        return parse_json(n().get("/rcan/v1/status").body).get("control")->as_string() ==
               "AVAILABLE";
      },
      4000));
  EXPECT_EQ(n().post("/rcan/v1/auth/claim", "{}", carol).status, 200);
  EXPECT_FALSE(n().audit_eventually("HANDOFF_WINDOW_CLOSED", owner_).empty());
}

TEST_F(SessionsE2E, PreemptionWhileCommandsAreInFlightDropsThemAndTellsTheHolder) {
  start();
  std::string user = n().token("user", "driver");
  test::Stream us(n().port(), user);
  HttpReply c = n().post("/rcan/v1/auth/claim", "{}", user);
  ASSERT_EQ(c.status, 200);
  ASSERT_EQ(n().post("/rcan/v1/command",
                     test::command_msg("move", {{"linear", 0.3}, {"duration_ms", 5000}}), user)
                .status,
            200);
  // A burst of the holder's commands races the owner's pre-emption: ten before the claim, the
  // rest (up to 60 in all: the USER rate limit is 100 per minute) while and after it is
  // granted. The burst pauses after ten until the claim is on its way, so that on a fast
  // machine it cannot finish before the claim even starts.
  std::atomic<bool> stop{false};
  std::atomic<bool> claiming{false};
  std::vector<int> statuses;
  std::mutex mu;
  std::atomic<int> sent{0};
  std::atomic<int> conflicts{0};
  std::thread burst([&] {
    while (!stop.load() && sent.load() < 60) {
      if (sent.load() >= 10 && !claiming.load()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
        continue;
      }
      sent.fetch_add(1);
      HttpReply r =
          n().post("/rcan/v1/command",
                   test::command_msg("move", {{"linear", 0.2}, {"duration_ms", 5000}}), user);
      std::lock_guard<std::mutex> lock(mu);
      statuses.push_back(r.status);
      if (r.status != 200) {
        EXPECT_EQ(test::error_code_of(r), "CONTROL_CONFLICT") << r.body;
        ++conflicts;
      }
    }
  });
  ControlNode::eventually([&] { return sent.load() >= 10; });
  claiming = true;
  HttpReply o = n().post("/rcan/v1/auth/claim", "{}", owner_);
  ASSERT_EQ(o.status, 200) << o.body;
  ControlNode::eventually([&] { return conflicts.load() >= 1 || sent.load() >= 60; });
  stop = true;
  burst.join();
  auto pre = us.wait_for("PREEMPTED");
  ASSERT_TRUE(pre.has_value());
  EXPECT_EQ(pre->get("session_id")->as_string(), session_of(c));
  EXPECT_EQ(pre->get("by_role")->as_string(), "OWNER");
  // After the grant, the former holder cannot drive, and the robot is not driving its command.
  EXPECT_EQ(n().post("/rcan/v1/command", test::command_msg("move", {{"linear", 0.2}}), user).status,
            409);
  json::Value st = parse_json(n().get("/rcan/v1/status", owner_).body);
  json::Value robot = *st.get("robot");
  std::string dump = json::dump(robot);
  ASSERT_TRUE(ControlNode::eventually([&] {
    json::Value r = *parse_json(n().get("/rcan/v1/status", owner_).body).get("robot");
    const json::Value* inner = r.get("robot");
    const json::Value* base = inner ? inner->get("base") : nullptr;
    const json::Value* v = base ? base->get("linear_mps") : nullptr;
    return v && v->to_double() == 0.0;
  })) << dump;
  auto preempted = n().audit("SESSION_PREEMPTED", owner_);
  ASSERT_EQ(preempted.size(), 1u);
  EXPECT_EQ(preempted[0].get("message_id")->as_string(), session_of(c));
  size_t refused = 0;
  for (int s : statuses) refused += s == 409;
  EXPECT_GE(refused, 1u);
  EXPECT_GE(statuses.size(), refused);
}

// An idle node's control tick sleeps up to 5 s (Node::pump); a session granted meanwhile wakes
// it, so the session still ends at its TTL. No stream is open (a stream keeps the pump at 10 ms).
TEST_F(SessionsE2E, ASessionGrantedToAnIdleNodeStillExpiresOnTime) {
  start("control:\n  max_session_s: 1\n");
  std::this_thread::sleep_for(std::chrono::milliseconds(700));  // the tick is asleep by now
  std::string user = n().token("user", "idle");
  HttpReply c = n().post("/rcan/v1/auth/claim", "{}", user);
  ASSERT_EQ(c.status, 200) << c.body;
  // Recorded by the control tick, 1 s after the grant; a tick that slept on would record it
  // only at its 5 s wake-up, more than 4 s after the grant.
  auto expired = n().audit_eventually("SESSION_EXPIRED", owner_, 1, 3000);
  ASSERT_EQ(expired.size(), 1u);
  EXPECT_EQ(expired[0].get("message_id")->as_string(), session_of(c));
}

TEST_F(SessionsE2E, ExpiredSessionGetsSessionExpiredUntilItClaimsAgainAndRenewalIsExplicit) {
  start("control:\n  max_session_s: 1\n");
  std::string user = n().token("user", "slow");
  test::Stream us(n().port(), user);
  HttpReply c = n().post("/rcan/v1/auth/claim", "{}", user);
  ASSERT_EQ(c.status, 200);
  EXPECT_LE(parse_json(c.body).get("payload")->get("expires_in")->as_int(), 1);
  // Commands do not renew: the session expires on time even while the holder drives.
  ASSERT_EQ(n().post("/rcan/v1/command",
                     test::command_msg("move", {{"linear", 0.1}, {"duration_ms", 100}}), user)
                .status,
            200);
  auto ev = us.wait_for("SESSION_EXPIRED", 4000);
  ASSERT_TRUE(ev.has_value());
  HttpReply late = n().post("/rcan/v1/command", test::command_msg("move", {{"linear", 0.1}}), user);
  EXPECT_EQ(late.status, 401);
  EXPECT_EQ(test::error_code_of(late), "SESSION_EXPIRED");
  HttpReply renew =
      n().post("/rcan/v1/auth/renew", "{\"session_id\":\"" + session_of(c) + "\"}", user);
  EXPECT_EQ(renew.status, 401);
  EXPECT_EQ(test::error_code_of(renew), "SESSION_EXPIRED");
  HttpReply again = n().post("/rcan/v1/auth/claim", "{}", user);
  ASSERT_EQ(again.status, 200);
  HttpReply r2 =
      n().post("/rcan/v1/auth/renew", "{\"session_id\":\"" + session_of(again) + "\"}", user);
  EXPECT_EQ(r2.status, 200) << r2.body;
  EXPECT_EQ(n().post("/rcan/v1/command",
                     test::command_msg("move", {{"linear", 0.1}, {"duration_ms", 100}}), user)
                .status,
            200);
  EXPECT_FALSE(n().audit_eventually("SESSION_EXPIRED", owner_).empty());
}

TEST_F(SessionsE2E, SafetyConflictStopsAndAlertsEverySession) {
  start();
  std::string user = n().token("user", "holder"),
              other = n().token("guest", "bystander", {"status"});
  test::Stream hs(n().port(), user), os(n().port(), other);
  ASSERT_EQ(n().post("/rcan/v1/auth/claim", "{}", user).status, 200);
  HttpReply stop = n().post("/api/stop", "{\"reason\":\"person in the way\"}", other);
  ASSERT_EQ(stop.status, 200) << stop.body;
  EXPECT_TRUE(hs.wait_for("SAFETY_CONFLICT").has_value());
  EXPECT_TRUE(os.wait_for("SAFETY_CONFLICT").has_value());
  auto es = n().audit_eventually("ESTOP", owner_);
  ASSERT_FALSE(es.empty());
  EXPECT_TRUE(es.back().get("detail")->get("safety_conflict")->as_bool());
}

TEST_F(SessionsE2E, GuestLimitsFromConfig) {
  start(
      "guest_limits:\n  chat_rate: 2/minute\n  query_rate: 30/minute\n  session_duration: 15min\n"
      "  concurrent_sessions: 2\n  capabilities: [status_read, chat_text]\n  blocked: [control]\n");
  std::string g1 = n().token("guest", "g1", {"status", "chat"}),
              g2 = n().token("guest", "g2", {"status", "chat"}),
              g3 = n().token("guest", "g3", {"status", "chat"});
  auto chat = [&](const std::string& t) {
    return n().post("/rcan/v1/command", test::command_msg("chat", {{"text", "hello"}}), t);
  };
  EXPECT_EQ(chat(g1).status, 200);
  EXPECT_EQ(chat(g1).status, 200);
  HttpReply third = chat(g1);
  EXPECT_EQ(third.status, 429);
  EXPECT_NE(third.body.find("chat rate"), std::string::npos) << third.body;
  EXPECT_EQ(chat(g2).status, 200);
  HttpReply full = chat(g3);
  EXPECT_EQ(full.status, 429);
  EXPECT_NE(full.body.find("guest_sessions_full"), std::string::npos) << full.body;
  // basic_info is not among this config's capabilities.
  HttpReply q = n().post("/rcan/v1/command", test::command_msg("query"), g2);
  EXPECT_EQ(q.status, 403);
  EXPECT_NE(q.body.find("guest_blocked"), std::string::npos) << q.body;
  // Stops are never limited.
  EXPECT_EQ(n().post("/api/stop", "{}", g3).status, 200);
}

TEST_F(SessionsE2E, HostileInputOnTheControlRoutesGetsTheErrorBody) {
  start();
  struct Case {
    std::string method, path, body;
    int status;
    std::string code;
  };
  std::vector<Case> cases{
      {"POST", "/rcan/v1/auth/claim", "[1,2]", 400, "SCHEMA_VALIDATION_FAILED"},
      {"POST", "/rcan/v1/auth/claim", "{\"role\":\"king\"}", 400, "SCHEMA_VALIDATION_FAILED"},
      {"POST", "/rcan/v1/auth/claim", "{not json", 400, "MALFORMED_JSON"},
      {"GET", "/rcan/v1/auth/claim", "", 405, "METHOD_NOT_ALLOWED"},
      {"POST", "/rcan/v1/auth/renew", "{}", 400, "SCHEMA_VALIDATION_FAILED"},
      {"POST", "/rcan/v1/auth/renew", "{\"session_id\":\"nope\"}", 404, "NOT_FOUND"},
      {"POST", "/rcan/v1/leases", "{\"leasee\":\"x\",\"duration_s\":-5}", 400,
       "SCHEMA_VALIDATION_FAILED"},
      {"POST", "/rcan/v1/leases", "{\"leasee\":\"x\",\"duration_s\":99999999999}", 400,
       "SCHEMA_VALIDATION_FAILED"},
      {"POST", "/rcan/v1/leases", "{\"duration_s\":60}", 400, "SCHEMA_VALIDATION_FAILED"},
      {"DELETE", "/rcan/v1/leases/no-such-lease", "", 404, "NOT_FOUND"},
      {"POST", "/rcan/v1/leases/x/other", "{}", 404, "NOT_FOUND"},
      {"PUT", "/rcan/v1/leases", "{}", 405, "METHOD_NOT_ALLOWED"},
      {"POST", "/rcan/v1/transfer", "{\"action\":\"steal\"}", 400, "SCHEMA_VALIDATION_FAILED"},
      {"POST", "/rcan/v1/transfer", "{\"action\":\"request\"}", 400, "SCHEMA_VALIDATION_FAILED"},
      {"POST", "/rcan/v1/transfer", "{\"action\":\"accept\",\"agreement\":\"x\"}", 404,
       "NOT_FOUND"},
      {"POST", "/rcan/v1/consent", "{\"payload\":{\"scopes\":[\"root\"]}}", 400,
       "SCHEMA_VALIDATION_FAILED"},
      {"POST", "/rcan/v1/consent", "{\"payload\":{}}", 400, "SCHEMA_VALIDATION_FAILED"},
      {"POST", "/rcan/v1/consent", "{\"type\":\"COMMAND\",\"payload\":{\"scopes\":[\"control\"]}}",
       400, "SCHEMA_VALIDATION_FAILED"},
      {"POST", "/rcan/v1/consent/unknown/grant", "{}", 404, "NOT_FOUND"},
      {"POST", "/rcan/v1/consent/unknown/steal", "{}", 404, "NOT_FOUND"},
  };
  for (const auto& c : cases) {
    HttpReply r = n().call(c.method, c.path, c.body, owner_);
    EXPECT_EQ(r.status, c.status) << c.method << " " << c.path << " " << c.body << " -> " << r.body;
    EXPECT_EQ(test::error_code_of(r), c.code) << c.method << " " << c.path << " " << c.body;
  }
  // No token, a bad token, a guest: refused and audited.
  EXPECT_EQ(n().post("/rcan/v1/leases", "{\"leasee\":\"x\"}", "").status, 401);
  EXPECT_EQ(n().post("/rcan/v1/leases", "{\"leasee\":\"x\"}", "garbage").status, 401);
  EXPECT_EQ(
      n().post("/rcan/v1/leases", "{\"leasee\":\"x\"}", n().token("guest", "g", {"status"})).status,
      403);
  EXPECT_EQ(n().audit_eventually("LEASE_DENIED", owner_, 3).size(), 3u);
  EXPECT_EQ(n().get("/healthz").status, 200);
}

}  // namespace
}  // namespace rcan

// The event bus's audiences (node/vocabulary/event_bus.h): who may receive an event is decided by
// the publisher, once, and each subscriber sees the audience beside the body.
#include "node/vocabulary/event_bus.h"

#include <gtest/gtest.h>

#include <vector>

using namespace rcan;
using namespace rcan::node;

namespace {

Principal principal(const std::string& sub, Role role) {
  Principal p;
  p.authenticated = true;
  p.issuer = "issuer";
  p.sub = sub;
  p.role = role;
  return p;
}

TEST(Audience, EveryoneIsForEveryStreamAndSharedChannels) {
  Audience a = Audience::everyone();
  EXPECT_TRUE(a.is_everyone());
  EXPECT_TRUE(a.admits(nullptr));
  Principal g = principal("g", Role::kGuest);
  EXPECT_TRUE(a.admits(&g));
}

TEST(Audience, OnePrincipalIsForThatPrincipalsStreamsOnly) {
  Principal alice = principal("alice", Role::kUser);
  Principal bob = principal("bob", Role::kUser);
  Principal owner = principal("owner", Role::kCreator);
  Audience a = Audience::principal(alice.key());
  EXPECT_FALSE(a.is_everyone());
  EXPECT_TRUE(a.admits(&alice));
  EXPECT_FALSE(a.admits(&bob));
  EXPECT_FALSE(a.admits(&owner)) << "a higher role is not the addressee";
  EXPECT_FALSE(a.admits(nullptr));
  // The same subject from another issuer is another principal.
  Principal other_issuer = alice;
  other_issuer.issuer = "elsewhere";
  EXPECT_FALSE(a.admits(&other_issuer));
}

TEST(Audience, MinimumRoleAdmitsThatRoleAndAbove) {
  Audience a = Audience::at_least(Role::kOwner);
  EXPECT_FALSE(a.is_everyone());
  for (Role r : {Role::kGuest, Role::kUser, Role::kLeasee}) {
    Principal p = principal("p", r);
    EXPECT_FALSE(a.admits(&p)) << role_name(r);
  }
  for (Role r : {Role::kOwner, Role::kCreator}) {
    Principal p = principal("p", r);
    EXPECT_TRUE(a.admits(&p)) << role_name(r);
  }
  EXPECT_FALSE(a.admits(nullptr));
}

TEST(EventBus, SubscribersGetTheBodyUntouchedWithItsAudience) {
  EventBus bus;
  std::vector<Event> seen;
  uint64_t id = bus.subscribe([&](const Event& e) { seen.push_back(e); });
  Principal alice = principal("alice", Role::kUser);
  bus.publish(json::Object{{"type", "EVENT"}, {"event", "ESTOP"}});
  bus.publish(json::Object{{"type", "EVENT"}, {"event", "PROMOTED"}},
              Audience::principal(alice.key()));
  ASSERT_EQ(seen.size(), 2u);
  EXPECT_TRUE(seen[0].audience.is_everyone());
  EXPECT_EQ(json::dump(seen[1].body), R"({"type":"EVENT","event":"PROMOTED"})")
      << "the body carries no addressing keys";
  EXPECT_TRUE(seen[1].audience.admits(&alice));
  bus.unsubscribe(id);
  bus.publish(json::Object{{"type", "EVENT"}});
  EXPECT_EQ(seen.size(), 2u);
  EXPECT_EQ(bus.size(), 0u);
}

}  // namespace

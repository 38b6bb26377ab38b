// The swarm agent's leader election on a manual clock, its members wired through an in-memory
// bus (tests/e2e/fleet_mqtt_test.cpp runs the same over a broker, with rcand).
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "in_process_node.h"
#include "node/fleet/swarm.h"
#include "rcan/mqtt_topics.h"

namespace rcan::node {
namespace {

constexpr const char* kPrefix = "rcan";
constexpr const char* kSwarm = "s1";

class SwarmAgentTest : public test_node::InProcessNode {
 protected:
  // A member of the swarm {robot-a, robot-b, robot-c} led by robot-a; what it publishes reaches
  // every other member that is connected and hears, as a broker would deliver it (after the
  // publisher's call has returned: deliver()).
  SwarmAgent& member(const std::string& id, const std::string& state_file = "") {
    config::SwarmConfig cfg;
    cfg.swarm_id = kSwarm;
    cfg.member_id = id;
    cfg.members = {"robot-a", "robot-b", "robot-c"};
    cfg.leader = "robot-a";
    cfg.heartbeat_ms = 100;
    cfg.leader_timeout_ms = 1000;
    auto agent = std::make_unique<SwarmAgent>(
        *services_, cfg, std::string(40, 'k'), kPrefix,
        [this, id](const std::string& topic, const json::Value& body, int, bool) {
          queued_.push_back({id, topic, body});
          published_.push_back({id, topic, body});
        },
        true, state_file);
    connected_[id] = false;
    hearing_[id] = true;
    return *(agents_[id] = std::move(agent));
  }

  void deliver() {
    while (!queued_.empty()) {
      Sent m = std::move(queued_.front());
      queued_.erase(queued_.begin());
      mqtt::InboundTopic t = mqtt::parse_topic(kPrefix, m.topic);
      for (auto& [other, a] : agents_)
        if (other != m.from && connected_[other] && hearing_[other])
          a->on_message(t, m.body, clock_.mono_ms());
    }
  }

  void connect(const std::string& id) {
    connected_[id] = true;
    agents_[id]->on_connected(clock_.mono_ms());
    deliver();
  }

  // Each connected member ticks, then the clock moves on by `ms`; `steps` times.
  void run(int steps, int64_t ms) {
    for (int i = 0; i < steps; ++i) {
      for (auto& [id, a] : agents_) {
        if (connected_[id]) a->tick(clock_.mono_ms(), hearing_[id]);
        deliver();
      }
      clock_.advance(ms);
    }
  }

  struct Sent {
    std::string from, topic;
    json::Value body;
  };
  std::map<std::string, std::unique_ptr<SwarmAgent>> agents_;
  std::map<std::string, bool> connected_;
  std::map<std::string, bool> hearing_;  // its subscriptions are granted
  std::vector<Sent> queued_;
  std::vector<Sent> published_;  // everything, in order
};

// The MQTT client reports its connection up before its connection callback has run, and the
// node's loop ticks the swarm whenever the client says connected. A member ticked in that
// window had no silence clock for the leader and took the lead at once, deposing a live one
// (the swarm tests' failures on a loaded machine: the last member to start announced itself
// leader at epoch 1).
TEST_F(SwarmAgentTest, AMemberTickedBeforeItsConnectionCallbackDoesNotTakeTheLead) {
  SwarmAgent& a = member("robot-a");
  SwarmAgent& c = member("robot-c");
  connect("robot-a");
  run(20, 50);  // robot-a leads and beats for a second

  connected_["robot-c"] = true;  // the client says connected; the callback has not run yet
  c.tick(clock_.mono_ms(), true);
  deliver();
  EXPECT_EQ(c.leader(), "robot-a");
  connect("robot-c");
  run(40, 50);  // two leader timeouts, with robot-a beating
  EXPECT_EQ(c.leader(), "robot-a");
  EXPECT_EQ(a.leader(), "robot-a");
  EXPECT_EQ(c.state().get("payload")->get("epoch")->as_int(), 0);
}

TEST_F(SwarmAgentTest, AfterALostConnectionTheSilenceClockWaitsForTheNextOne) {
  SwarmAgent& a = member("robot-a");
  SwarmAgent& c = member("robot-c");
  for (const char* id : {"robot-a", "robot-c"}) connect(id);
  run(20, 50);
  EXPECT_EQ(c.leader(), "robot-a");

  connected_["robot-c"] = false;  // robot-c is cut off for 5 s, while robot-a goes on leading
  c.on_disconnected();
  run(100, 50);
  connected_["robot-c"] = true;  // back: ticked before the callback, then after it
  c.tick(clock_.mono_ms(), true);
  deliver();
  EXPECT_EQ(c.leader(), "robot-a");
  connect("robot-c");
  run(40, 50);
  EXPECT_EQ(c.leader(), "robot-a");
  EXPECT_EQ(a.leader(), "robot-a");
}

// Connected but not yet subscribed (a clustered broker refuses subscriptions for a while after a
// failover): the member hears nobody, beats, and does not judge the leader until it can hear;
// then its silence clocks start from there.
TEST_F(SwarmAgentTest, AMemberThatCannotHearYetDoesNotJudgeTheLeader) {
  SwarmAgent& a = member("robot-a");
  SwarmAgent& c = member("robot-c");
  connect("robot-a");
  hearing_["robot-c"] = false;
  connect("robot-c");
  run(80, 50);  // four leader timeouts, deaf
  EXPECT_EQ(c.leader(), "robot-a");
  hearing_["robot-c"] = true;
  run(40, 50);
  EXPECT_EQ(c.leader(), "robot-a");
  EXPECT_EQ(a.leader(), "robot-a");
  EXPECT_EQ(c.state().get("payload")->get("epoch")->as_int(), 0);
}

// Deaf while its leader dies: it takes over one leader timeout after it can hear, not before,
// and its state says whether it hears.
TEST_F(SwarmAgentTest, AMemberThatHearsAgainReplacesADeadLeaderOneTimeoutLater) {
  member("robot-a");
  SwarmAgent& c = member("robot-c");
  connect("robot-a");
  hearing_["robot-c"] = false;
  connect("robot-c");
  run(10, 50);
  connected_["robot-a"] = false;  // the leader dies while robot-c cannot hear
  agents_["robot-a"]->on_disconnected();
  run(80, 50);
  EXPECT_EQ(c.leader(), "robot-a");
  EXPECT_FALSE(c.state().get("payload")->get("hearing")->as_bool());
  hearing_["robot-c"] = true;
  run(18, 50);  // 0.9 s of the 1 s timeout: still waiting
  EXPECT_EQ(c.leader(), "robot-a");
  EXPECT_TRUE(c.state().get("payload")->get("hearing")->as_bool());
  run(6, 50);
  EXPECT_EQ(c.leader(), "robot-c");
  EXPECT_EQ(c.state().get("payload")->get("epoch")->as_int(), 1);
}

// The clocks still do their work: a leader silent for longer than the timeout is replaced by
// the first live member in byte order, which announces a new epoch that the others follow.
TEST_F(SwarmAgentTest, ASilentLeaderIsReplacedByTheFirstLiveMember) {
  for (const char* id : {"robot-a", "robot-b", "robot-c"}) member(id);
  for (const char* id : {"robot-a", "robot-b", "robot-c"}) connect(id);
  run(20, 50);
  for (const char* id : {"robot-a", "robot-b", "robot-c"})
    EXPECT_EQ(agents_[id]->leader(), "robot-a") << id;

  connected_["robot-a"] = false;  // the leader falls silent
  agents_["robot-a"]->on_disconnected();
  run(10, 50);  // half a timeout: still robot-a
  EXPECT_EQ(agents_["robot-c"]->leader(), "robot-a");
  run(30, 50);
  EXPECT_EQ(agents_["robot-b"]->leader(), "robot-b");
  EXPECT_EQ(agents_["robot-c"]->leader(), "robot-b");
  EXPECT_EQ(agents_["robot-c"]->state().get("payload")->get("epoch")->as_int(), 1);
}

// A member that cannot hear still beats (its leader, if it is one, is alive), but says so: the
// others do not count it when they choose a new leader. Counted, it was chosen (robot-b is first
// in byte order), and being deaf it never took over: robot-c followed a leader that never
// announced, and the swarm had none until robot-b could hear again.
TEST_F(SwarmAgentTest, AMemberThatCannotHearIsNotChosenToLead) {
  for (const char* id : {"robot-a", "robot-b", "robot-c"}) member(id);
  for (const char* id : {"robot-a", "robot-b", "robot-c"}) connect(id);
  run(20, 50);
  hearing_["robot-b"] = false;  // its subscriptions refused (a broker node failed over)
  run(10, 50);
  connected_["robot-a"] = false;  // then the leader dies
  agents_["robot-a"]->on_disconnected();
  run(60, 50);  // three leader timeouts
  EXPECT_EQ(agents_["robot-c"]->leader(), "robot-c");
  EXPECT_EQ(agents_["robot-c"]->state().get("payload")->get("epoch")->as_int(), 1);
  EXPECT_EQ(agents_["robot-b"]->leader(), "robot-a");  // deaf: it has heard nothing of it
  // Able to hear again, robot-b judges too, one timeout later; the swarm ends with one leader
  // that both follow (ties of epoch go to the smaller id).
  hearing_["robot-b"] = true;
  run(60, 50);
  EXPECT_EQ(agents_["robot-b"]->leader(), agents_["robot-c"]->leader());
  EXPECT_NE(agents_["robot-c"]->leader(), "robot-a");
}

// A member that restarts keeps the swarm's state it knew (its state file, rcand's
// <data_dir>/swarm.json): an announce of an earlier epoch — a captured one replayed once the
// broker no longer holds the retained announce — is still stale, not taken. Without it the
// member came back at epoch 0 under the configured leader and took the replay.
TEST_F(SwarmAgentTest, ARestartedMemberKeepsItsEpochAndTakesNoEarlierAnnounce) {
  const std::string file = dir_.file("swarm-c.json");
  member("robot-a");
  member("robot-b");
  member("robot-c", file);
  for (const char* id : {"robot-a", "robot-b", "robot-c"}) connect(id);
  run(20, 50);
  const Sent first = published_.front();  // robot-a's announce at epoch 0
  ASSERT_EQ(first.from, "robot-a");
  ASSERT_EQ(first.body.get("type")->as_string(), "SWARM_ANNOUNCE");
  connected_["robot-a"] = false;
  agents_["robot-a"]->on_disconnected();
  run(40, 50);
  ASSERT_EQ(agents_["robot-c"]->leader(), "robot-b");

  agents_.erase("robot-c");  // restarted
  SwarmAgent& c = member("robot-c", file);
  EXPECT_EQ(c.leader(), "robot-b");
  EXPECT_EQ(c.state().get("payload")->get("epoch")->as_int(), 1);
  c.on_connected(clock_.mono_ms());
  c.on_message(mqtt::parse_topic(kPrefix, first.topic), first.body, clock_.mono_ms());
  EXPECT_EQ(c.leader(), "robot-b");
  EXPECT_EQ(c.state().get("payload")->get("epoch")->as_int(), 1);

  // Another member's state, or a file that does not parse, is not taken: the configured start.
  const std::string other = dir_.file("swarm-b.json");
  agents_.erase("robot-b");
  member("robot-b", other);
  agents_.erase("robot-c");
  EXPECT_EQ(member("robot-c", other).state().get("payload")->get("epoch")->as_int(), 0);
  { std::ofstream(other, std::ios::trunc) << "{not json"; }
  agents_.erase("robot-c");
  EXPECT_EQ(member("robot-c", other).leader(), "robot-a");
}

}  // namespace
}  // namespace rcan::node

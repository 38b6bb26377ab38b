// The seams between a fleet's coordinator and its robots through a broker, tried as an attacker
// with only the broker's topics would (docs/THREATS.md): real rcand members, a real Mosquitto and
// the real `rcan fleet` CLI on loopback. The attacker can read and write every topic of the
// fleet (a client with the broker's credentials, another fleet's robot on a permissive ACL, a
// broker operator); it holds no robot's key and no coordinator's key.
//
// The fleet's robots' public keys reach the CLI as the operator configures them
// (RCAN_FLEET_MEMBERS_DIR, the same as --members-dir).
#include <signal.h>

#include <atomic>
#include <thread>

#include "fleet_fixture.h"

namespace rcan::fleet_test {
namespace {

const std::string kEstopTopic = "rcan/fleet/alpha/estop";
std::string reply_topic(const std::string& m) { return "rcan/fleet/alpha/robot/" + m + "/reply"; }
std::string status_topic(const std::string& m) { return "rcan/fleet/alpha/robot/" + m + "/status"; }

class FleetSeamsTest : public FleetTest {
 protected:
  // `rcan fleet …` as the operator runs it: the fleet's members directory from the environment.
  test::RunResult cli(std::vector<std::string> args) {
    args.insert(args.begin(), "fleet");
    args.insert(args.end(), {"--broker", broker_->url(), "--token", tmp_.file("fleet.token"),
                             "--key-dir", key_dir_});
    return test::run_cli(args, {}, {"RCAN_FLEET_MEMBERS_DIR=" + members_dir()});
  }
  bool latched(const std::string& name) {
    return json::dump(robots_[name]->status(fleet_token_)).find("\"estop_active\":true") !=
           std::string::npos;
  }
  // An ACK as a robot would send it for `id`, in `member`'s name.
  json::Object ack_for(const std::string& id, const std::string& member) {
    return json::Object{{"version", "1.0.0"},
                        {"message_id", new_uuid_v4()},
                        {"source_ruri", robots_[member]->ruri()},
                        {"type", "ACK"},
                        {"message_type", "ACK"},
                        {"reply_to", id},
                        {"timestamp_ms", wall_ms()},
                        {"payload", json::Object{{"status", "ok"}}},
                        {"fleet_id", "alpha"},
                        {"member", member}};
  }
};

// The n-th message on `topic` that answers `id` (n from 1).
std::function<bool(const Watcher::Msg&)> nth_answer(const std::string& topic, const std::string& id,
                                                    int n) {
  auto seen = std::make_shared<int>(0);
  return [=](const Watcher::Msg& m) {
    return m.topic == topic && str_of(m.body, "reply_to") == id && ++*seen == n;
  };
}

// F5: a topic writer answers for a robot that is frozen (SIGSTOP: connected, silent, never
// latched). Unsigned, signed by the writer's own key, a genuine earlier reply of that robot
// pointed at the new ESTOP, another robot's genuine reply to this ESTOP copied onto its topic:
// none is believed, and the CLI names the robot (before: "ok":true, exit 0).
TEST_F(FleetSeamsTest, AForgedAckForAFrozenRobotIsNotBelieved) {
  add_robot("robot-a", "0000000a");
  add_robot("robot-b", "0000000b");
  Watcher writer(broker_->url(), {kEstopTopic, reply_topic("robot-a"), reply_topic("robot-b")});
  // The genuine round first: both robots' signed ACKs verify.
  auto first = cli({"estop", "alpha", "--members", "robot-a,robot-b"});
  ASSERT_EQ(first.exit_code, 0) << first.out << first.err;
  const std::string first_id = str_at(parse(first.out), {"message_id"});
  auto genuine_b = writer.wait(nth_answer(reply_topic("robot-b"), first_id, 1));
  ASSERT_TRUE(genuine_b);
  EXPECT_TRUE(genuine_b->body.get("sig") != nullptr) << json::dump(genuine_b->body);
  auto resumed = cli({"resume", "alpha", "--members", "robot-a,robot-b"});
  ASSERT_EQ(resumed.exit_code, 0) << resumed.out << resumed.err;
  ASSERT_FALSE(latched("robot-b"));

  const pid_t b = robots_["robot-b"]->proc().pid();
  ASSERT_EQ(::kill(b, SIGSTOP), 0);
  auto attacker_keys = keys::generate();
  ASSERT_TRUE(attacker_keys.ok());
  std::atomic<int> forged{0};
  std::thread forger([&] {
    auto estop = writer.wait(
        [&](const Watcher::Msg& m) {
          return m.topic == kEstopTopic && payload_str(m.body, "safety_event") == "ESTOP" &&
                 str_of(m.body, "message_id") != first_id;
        },
        15000);
    if (!estop) return;
    const std::string id = str_of(estop->body, "message_id");
    writer.publish(reply_topic("robot-b"), json::Value(ack_for(id, "robot-b")));  // unsigned
    json::Object theirs = ack_for(id, "robot-b");
    EXPECT_TRUE(msgsig::sign_ed25519(theirs, attacker_keys->ed25519_seed.span()).ok());
    writer.publish(reply_topic("robot-b"), json::Value(std::move(theirs)));
    json::Value old = genuine_b->body;  // robot-b's own words, about another ESTOP
    old.as_object().set("reply_to", id);
    writer.publish(reply_topic("robot-b"), old);
    forged = 3;
    // robot-a's genuine answer to this very ESTOP, on robot-b's topic.
    auto a = writer.wait(nth_answer(reply_topic("robot-a"), id, 1), 10000);
    if (!a) return;
    writer.publish(reply_topic("robot-b"), a->body);
    forged = 4;
  });
  auto r = cli({"estop", "alpha", "--members", "robot-a,robot-b", "--timeout-ms", "4000"});
  forger.join();
  ASSERT_EQ(::kill(b, SIGCONT), 0);
  EXPECT_EQ(forged.load(), 4);
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  json::Value out = parse(r.out);
  EXPECT_EQ(bool_at(out, {"ok"}), "false") << r.out;
  EXPECT_EQ(str_at(out, {"members", "robot-a", "result"}), "acknowledged") << r.out;
  EXPECT_EQ(str_at(out, {"members", "robot-b", "result"}), "timeout") << r.out;
  EXPECT_EQ(int_at(out, {"members", "robot-b", "unverified_replies"}), 4) << r.out;
  EXPECT_NE(r.err.find("robot-b (timeout"), std::string::npos) << r.err;
  EXPECT_TRUE(latched("robot-a"));
}

// F5: a topic writer erases a frozen robot's retained status (an empty retained message). The
// members come from the operator's configuration, so it is still waited for and named (before:
// not waited for at all, "ok":true, exit 0).
TEST_F(FleetSeamsTest, AnErasedStatusDoesNotTakeARobotOffTheFleet) {
  add_robot("robot-a", "0000000a");
  add_robot("robot-b", "0000000b");
  const pid_t b = robots_["robot-b"]->proc().pid();
  ASSERT_EQ(::kill(b, SIGSTOP), 0);
  {
    transport::MqttOptions o;
    o.url = broker_->url();
    transport::MqttClient writer(o);
    ASSERT_TRUE(writer.start().ok());
    for (int i = 0; i < 500 && !writer.connected(); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    ASSERT_TRUE(writer.publish_confirmed(status_topic("robot-b"), "", 1, true, 5000).ok());
  }
  // The broker holds no status for robot-b any more; robot-a's is there.
  Watcher look(broker_->url(), {"rcan/fleet/alpha/robot/+/status"});
  ASSERT_TRUE(look.wait([](const Watcher::Msg& m) { return m.retained; }, 5000));
  for (const auto& m : look.all()) EXPECT_NE(m.topic, status_topic("robot-b"));
  auto r = cli({"estop", "alpha", "--timeout-ms", "2000"});
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  json::Value out = parse(r.out);
  EXPECT_EQ(str_at(out, {"members", "robot-a", "result"}), "acknowledged") << r.out;
  EXPECT_EQ(str_at(out, {"members", "robot-b", "result"}), "timeout") << r.out;
  EXPECT_NE(r.err.find("robot-b (timeout)"), std::string::npos) << r.err;
  // Nor is a status robot-b did not sign shown as its status (still frozen: the broker has not
  // given up on its connection, so its own will has not replaced this).
  Watcher writer(broker_->url(), {});
  writer.publish(status_topic("robot-b"),
                 json::Value(json::Object{{"online", true},
                                          {"member", "robot-b"},
                                          {"fleet_id", "alpha"},
                                          {"estop_active", true},
                                          {"reason", "connected"},
                                          {"timestamp_ms", wall_ms()}}),
                 true);
  auto s = cli({"status", "alpha"});
  ASSERT_EQ(::kill(b, SIGCONT), 0);
  EXPECT_EQ(s.exit_code, 0) << s.out << s.err;
  json::Value st = parse(s.out);
  EXPECT_EQ(path_of(st, {"members", "robot-b"}), nullptr) << s.out;
  EXPECT_EQ(int_at(st, {"unverified", "robot-b", "count"}), 1) << s.out;
  EXPECT_EQ(bool_at(st, {"members", "robot-a", "online"}), "true") << s.out;
}

// F6: a topic writer puts a captured, genuine fleet ESTOP back on the estop topic (retained)
// after the operator's RESUME, then takes over the robot's MQTT client id so that it reconnects
// and is handed the retained copy. The robot stays resumed — live, after the reconnect and after
// a restart (before: latched again each time) — and a new ESTOP still latches it.
TEST_F(FleetSeamsTest, AReplayedStandingEstopAfterTheResumeDoesNotLatchAgain) {
  add_robot("robot-a", "0000000a");
  Watcher writer(broker_->url(), {kEstopTopic, reply_topic("robot-a")});
  auto e = cli({"estop", "alpha", "--members", "robot-a"});
  ASSERT_EQ(e.exit_code, 0) << e.out << e.err;
  const std::string id = str_at(parse(e.out), {"message_id"});
  auto captured = writer.wait([&](const Watcher::Msg& m) {
    return m.topic == kEstopTopic && str_of(m.body, "message_id") == id;
  });
  ASSERT_TRUE(captured);
  ASSERT_TRUE(latched("robot-a"));
  auto r = cli({"resume", "alpha", "--members", "robot-a"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  ASSERT_FALSE(latched("robot-a"));
  const std::string reply = reply_topic("robot-a");
  ASSERT_TRUE(writer.wait(nth_answer(reply, id, 1)));

  // The replay, retained: robot-a hears it live at once.
  writer.publish(kEstopTopic, captured->body, true);
  auto live = writer.wait(nth_answer(reply, id, 2));
  ASSERT_TRUE(live);
  EXPECT_EQ(payload_str(live->body, "error_code"), "MESSAGE_STALE") << json::dump(live->body);
  EXPECT_FALSE(latched("robot-a"));

  // The writer takes robot-a's client id: the broker drops robot-a, which reconnects,
  // subscribes again and is handed the retained replay.
  {
    transport::MqttOptions o;
    o.url = broker_->url();
    o.client_id = "rcand-0000000a";
    transport::MqttClient thief(o);
    ASSERT_TRUE(thief.start().ok());
    for (int i = 0; i < 500 && !thief.connected(); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    ASSERT_TRUE(thief.connected());
  }
  auto again = writer.wait(nth_answer(reply, id, 3), 15000);
  ASSERT_TRUE(again);
  EXPECT_EQ(payload_str(again->body, "error_code"), "MESSAGE_STALE") << json::dump(again->body);
  EXPECT_FALSE(latched("robot-a"));

  // After a restart (the replay memory is gone; the ledger is not).
  robots_["robot-a"]->restart();
  auto restarted = writer.wait(nth_answer(reply, id, 4), 15000);
  ASSERT_TRUE(restarted);
  EXPECT_EQ(payload_str(restarted->body, "error_code"), "MESSAGE_STALE")
      << json::dump(restarted->body);
  EXPECT_FALSE(latched("robot-a"));
  std::error_code ec;
  auto perms = fs::status(robots_["robot-a"]->dir() + "/fleet_estops.json", ec).permissions();
  EXPECT_FALSE(ec);
  EXPECT_EQ(perms & fs::perms::all, fs::perms::owner_read | fs::perms::owner_write);
  // Each refusal is audited.
  int refused = 0;
  for (const auto& rec : audit_events(*robots_["robot-a"], fleet_token_, "MESSAGE_STALE"))
    if (json::dump(rec).find("superseded_by_fleet_resume") != std::string::npos) ++refused;
  EXPECT_GE(refused, 1);

  // Safety first: a new ESTOP latches the robot.
  auto fresh = cli({"estop", "alpha", "--members", "robot-a"});
  EXPECT_EQ(fresh.exit_code, 0) << fresh.out << fresh.err;
  EXPECT_TRUE(latched("robot-a"));
}

}  // namespace
}  // namespace rcan::fleet_test

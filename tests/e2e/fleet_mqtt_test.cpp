// Fleets and swarms over MQTT, end to end: a real Mosquitto broker on a free loopback port,
// real rcand processes as fleet members, the real `rcan fleet` CLI, and an MQTT client in the
// test that watches the topics (docs/FLEET.md).
#include <gtest/gtest.h>

#include <atomic>

#include "fleet_fixture.h"
#include "node/bindings/mqtt_node.h"
#include "postgres.h"

namespace rcan {
namespace {

using namespace fleet_test;  // NOLINT(google-build-using-namespace)
namespace fs = std::filesystem;

using test::Postgres;  // tests/support/postgres.h

TEST_F(FleetTest, FleetCommandReachesEveryMemberAndCompletes) {
  three_robots();
  auto r = fleet({"command", "alpha", "move", "--params", R"({"linear":0.2,"duration_ms":200})",
                  "--members", "robot-a,robot-b,robot-c", "--wait-complete"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  json::Value out = parse(r.out);
  for (const char* m : {"robot-a", "robot-b", "robot-c"}) {
    const json::Value* res = out.get("members")->get(m);
    ASSERT_NE(res, nullptr) << m;
    EXPECT_EQ(str_of(*res, "result"), "completed") << m;
  }
  // Every robot audited the fleet command with its fleet context.
  std::string id = str_of(out, "message_id");
  for (auto& [name, robot] : robots_) {
    std::string audit = robot->audit(fleet_token_);
    EXPECT_NE(audit.find(id), std::string::npos) << name;
    EXPECT_NE(audit.find("\"fleet_mode\":\"broadcast\""), std::string::npos) << name;
  }
}

TEST_F(FleetTest, SequentialChoreographyHonoursWaitFor) {
  three_robots();
  Watcher w(broker_->url(), {"rcan/fleet/alpha/robot/+/reply"});
  write_file(
      tmp_.file("seq.json"),
      R"({"command":"COORDINATED_MOVE","fleet_id":"alpha","targets":["robot-a","robot-b","robot-c"],
    "choreography":{"type":"sequential","steps":[
      {"robot":"robot-a","action":"move","params":{"linear":0.2,"duration_ms":300}},
      {"robot":"robot-b","action":"move","params":{"x":0,"linear":0.1,"duration_ms":200},"wait_for":"robot-a"},
      {"robot":"robot-c","action":"turn_left","params":{"angular":0.3,"duration_ms":100},"wait_for":["robot-a","robot-b"]}]}})");
  auto r = fleet({"run", tmp_.file("seq.json")});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  json::Value out = parse(r.out);
  EXPECT_TRUE(out.get("ok")->as_bool());
  // Causality on the wire: each robot's ACK comes after the previous robot's COMPLETED.
  auto msgs = w.all();
  auto index_of = [&](const std::string& robot, const std::string& what) {
    for (size_t i = 0; i < msgs.size(); ++i) {
      if (msgs[i].topic != "rcan/fleet/alpha/robot/" + robot + "/reply") continue;
      std::string t = str_of(msgs[i].body, "type");
      if ((what == "ACK" && t == "ACK") ||
          (what == "COMPLETED" && payload_str(msgs[i].body, "event") == "COMPLETED"))
        return static_cast<long>(i);
    }
    return -1L;
  };
  long a_done = index_of("robot-a", "COMPLETED"), b_ack = index_of("robot-b", "ACK");
  long b_done = index_of("robot-b", "COMPLETED"), c_ack = index_of("robot-c", "ACK");
  ASSERT_GE(a_done, 0);
  ASSERT_GE(b_done, 0);
  EXPECT_LT(a_done, b_ack);
  EXPECT_LT(b_done, c_ack);
}

TEST_F(FleetTest, FailingStepStopsEveryRobotTheRunMoved) {
  three_robots();
  write_file(tmp_.file("par.json"), R"({"command":"COORDINATED_MOVE","fleet_id":"alpha",
    "choreography":{"type":"parallel","steps":[
      {"robot":"robot-a","action":"move","params":{"linear":0.2,"duration_ms":30000}},
      {"robot":"robot-b","action":"move","params":{"linear":0.2,"duration_ms":30000}},
      {"robot":"robot-c","action":"move","params":{"linear":0.1,"duration_ms":100}},
      {"robot":"robot-c","action":"fly_to_the_moon","wait_for":"robot-c"}]}})");
  auto r = fleet({"run", tmp_.file("par.json")});
  ASSERT_EQ(r.exit_code, 1) << r.out << r.err;
  json::Value out = parse(r.out);
  EXPECT_FALSE(out.get("ok")->as_bool());
  EXPECT_EQ(out.get("failed_step")->as_int(), 3);
  EXPECT_EQ(str_of(out, "failed_robot"), "robot-c");
  EXPECT_NE(str_of(out, "reason").find("COMMAND_REJECTED"), std::string::npos);
  for (const char* m : {"robot-a", "robot-b", "robot-c"})
    EXPECT_EQ(str_of(*out.get("stopped")->get(m), "result"), "acknowledged") << m;
  // The 30 s drives were stopped, not left running.
  for (const char* m : {"robot-a", "robot-b"}) EXPECT_TRUE(comes_to_rest(*robots_[m])) << m;
}

TEST_F(FleetTest, StepTimeoutIsAFailure) {
  add_robot("robot-a", "0000000a");
  // robot-b is in the fleet (the operator has its key) but not running: its step never
  // acknowledges.
  member_keys(tmp_.path(), "robot-b");
  write_file(tmp_.file("to.json"), R"({"command":"COORDINATED_MOVE","fleet_id":"alpha",
    "choreography":{"type":"parallel","steps":[
      {"robot":"robot-a","action":"move","params":{"linear":0.2,"duration_ms":30000}},
      {"robot":"robot-b","action":"move","params":{"linear":0.2,"duration_ms":100},"timeout_ms":500}]}})");
  auto r = fleet({"run", tmp_.file("to.json"), "--timeout-ms", "2000"});
  ASSERT_EQ(r.exit_code, 1) << r.out << r.err;
  json::Value out = parse(r.out);
  EXPECT_EQ(out.get("failed_step")->as_int(), 1);
  EXPECT_NE(str_of(out, "reason").find("timeout"), std::string::npos);
  EXPECT_EQ(str_of(*out.get("stopped")->get("robot-a"), "result"), "acknowledged");
  EXPECT_EQ(str_of(*out.get("stopped")->get("robot-b"), "result"), "timeout");  // it never answered
  EXPECT_FALSE(out.get("all_stops_acknowledged")->as_bool());
  EXPECT_TRUE(comes_to_rest(*robots_["robot-a"]));
}

TEST_F(FleetTest, RetainedFleetEstopIsObeyedByALateJoiner) {
  add_robot("robot-a", "0000000a");
  add_robot("robot-b", "0000000b");
  auto r = fleet({"estop", "alpha", "--members", "robot-a,robot-b", "--reason", "test"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  for (const char* m : {"robot-a", "robot-b"})
    EXPECT_NE(json::dump(robots_[m]->status(fleet_token_)).find("\"estop_active\":true"),
              std::string::npos)
        << m;
  // robot-c starts after the ESTOP was published: the retained message latches it too, also
  // through a subscription at QoS 0 (mqtt.estop_qos: 0 takes the retained copy like any other).
  Watcher w(broker_->url(), {"rcan/fleet/alpha/robot/robot-c/reply"});
  add_robot("robot-c", "0000000c", "", ", estop_qos: 0");
  auto ack = w.wait([](const Watcher::Msg& m) { return str_of(m.body, "type") == "ACK"; });
  ASSERT_TRUE(ack);
  EXPECT_NE(json::dump(robots_["robot-c"]->status(fleet_token_)).find("\"estop_active\":true"),
            std::string::npos);
  auto late = audit_events(*robots_["robot-c"], fleet_token_, "ESTOP");
  ASSERT_FALSE(late.empty());
  EXPECT_EQ(int_at(late.front(), {"detail", "mqtt_qos"}), 0);  // the retained copy, at QoS 0
  // A command is refused while latched.
  auto c = fleet({"command", "alpha", "move", "--params", R"({"linear":0.1,"duration_ms":100})",
                  "--members", "robot-c"});
  EXPECT_EQ(c.exit_code, 1);
  EXPECT_NE(c.out.find("estop_active"), std::string::npos) << c.out;
  // RESUME replaces the retained ESTOP; a robot joining after that is not stopped.
  auto res = fleet({"resume", "alpha", "--members", "robot-a,robot-b,robot-c"});
  ASSERT_EQ(res.exit_code, 0) << res.out << res.err;
  robots_["robot-c"]->restart();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_NE(json::dump(robots_["robot-c"]->status(fleet_token_)).find("\"estop_active\":false"),
            std::string::npos);
}

// A fleet ESTOP subscription at QoS 1 (the default: act on the first copy) may see the same
// ESTOP twice — a redelivery after a reconnect, a publisher's retry. A stop is idempotent and
// a fresh SAFETY stop is never refused as a replay (src/node/admission/replay.h): the second copy
// stops the (already stopped) robot again, is answered, and its record says it was a duplicate
// (`duplicate_safety_message`). The same at QoS 2 (mqtt.estop_qos: 2) and at QoS 0.
TEST_F(FleetTest, FleetEstopDeliveredTwiceIsHarmlessAtEveryQos) {
  add_robot("robot-a", "0000000a");
  add_robot("robot-b", "0000000b", "", ", estop_qos: 2");
  add_robot("robot-c", "0000000c", "", ", estop_qos: 0");
  std::string id = new_uuid_v4();
  json::Value msg =
      command_msg("SAFETY", json::Object{{"safety_event", "ESTOP"}}, fleet_token_, id);
  Watcher w(broker_->url(), {"rcan/fleet/alpha/robot/+/reply"});
  w.publish("rcan/fleet/alpha/estop", msg);
  w.publish("rcan/fleet/alpha/estop", msg);  // exactly what an at-least-once redelivery looks like
  for (const char* m : {"robot-a", "robot-b", "robot-c"}) {
    const std::string reply = std::string("rcan/fleet/alpha/robot/") + m + "/reply";
    int acks = 0;
    for (int attempt = 0; attempt < 100 && acks < 2; ++attempt) {
      if (attempt > 0) std::this_thread::sleep_for(std::chrono::milliseconds(50));
      auto seen = w.all();
      acks = static_cast<int>(std::count_if(seen.begin(), seen.end(), [&](const Watcher::Msg& x) {
        return x.topic == reply && str_of(x.body, "reply_to") == id &&
               str_of(x.body, "type") == "ACK";
      }));
    }
    EXPECT_EQ(acks, 2) << m;
    EXPECT_NE(json::dump(robots_[m]->status(fleet_token_)).find("\"estop_active\":true"),
              std::string::npos)
        << m;
    int first = 0, duplicates = 0;
    json::Value entries = parse(robots_[m]->audit(fleet_token_));
    for (const auto& e : entries.get("entries")->as_array()) {
      if (str_of(e, "message_id") != id || str_of(e, "event") != "ESTOP") continue;
      // Published at QoS 1: delivered at 1 to robot-a (subscribed at 1) and robot-b (2), at 0
      // to robot-c — its subscription is at QoS 0, not raised.
      EXPECT_EQ(int_at(e, {"detail", "mqtt_qos"}), std::string(m) == "robot-c" ? 0 : 1) << m;
      const json::Value* detail = e.get("detail");
      const json::Value* dup =
          detail != nullptr ? detail->get("duplicate_safety_message") : nullptr;
      if (dup != nullptr && dup->is_bool() && dup->as_bool())
        ++duplicates;
      else
        ++first;
    }
    EXPECT_EQ(first, 1) << m;
    EXPECT_EQ(duplicates, 1) << m;
  }
}

// mqtt.reply_qos: 0 (docs/FLEET.md §Replies at QoS 0) sends the answers at QoS 0; the default
// at QoS 1. `rcan fleet estop` is confirmed by either. The first message answering the command
// is its ACK: the `status` command's COMPLETED, published by the robot's MQTT loop as soon as it
// sees the command pending, once overtook it (seen under TSan), and `rcan fleet command` then
// counted the member as failed.
TEST_F(FleetTest, RepliesGoOutAtTheConfiguredQos) {
  add_robot("robot-a", "0000000a");
  add_robot("robot-b", "0000000b", "", ", reply_qos: 0");
  Watcher w(broker_->url(), {"rcan/fleet/alpha/robot/+/reply"});  // subscribed at QoS 1
  std::string id = new_uuid_v4();
  w.publish("rcan/fleet/alpha/cmd",
            command_msg("FLEET_COMMAND", json::Object{{"command", "status"}, {"fleet_id", "alpha"}},
                        fleet_token_, id));
  for (const auto& [member, qos] : {std::pair<std::string, int>{"robot-a", 1}, {"robot-b", 0}}) {
    auto ack = w.wait([&](const Watcher::Msg& m) {
      return m.topic == "rcan/fleet/alpha/robot/" + member + "/reply" &&
             str_of(m.body, "reply_to") == id;
    });
    ASSERT_TRUE(ack.has_value()) << member;
    EXPECT_EQ(str_of(ack->body, "type"), "ACK") << member;
    EXPECT_EQ(ack->qos, qos) << member;
  }
  auto r = fleet({"estop", "alpha", "--members", "robot-a,robot-b"});
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  for (const char* m : {"robot-a", "robot-b"})
    EXPECT_NE(json::dump(robots_[m]->status(fleet_token_)).find("\"estop_active\":true"),
              std::string::npos)
        << m;
}

// Without --members, `rcan fleet estop` waits for every member of the fleet's members directory
// (--members-dir), reports each silent one's last signed status (here the will) and names each
// one that did not confirm (exit 1); --no-wait only needs the broker's acknowledgement. Mosquitto
// does QoS 2: the ESTOP goes out at QoS 2.
TEST_F(FleetTest, FleetEstopWaitsForTheRosterAndNamesWhoDidNotConfirm) {
  three_robots();
  Watcher w(broker_->url(), {"rcan/fleet/alpha/robot/robot-c/status"});
  robots_["robot-c"]->kill9();  // its will says it is offline: still a member
  ASSERT_TRUE(w.wait([](const Watcher::Msg& m) {
    return m.body.get("online") && !m.body.get("online")->as_bool();
  }));
  auto r = fleet({"estop", "alpha", "--timeout-ms", "3000"});
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(r.err.find("1 of 3 robots did not confirm"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("robot-c (timeout)"), std::string::npos) << r.err;
  json::Value out = parse(r.out);
  EXPECT_EQ(bool_at(out, {"ok"}), "false");
  EXPECT_EQ(int_at(out, {"qos"}), 2);
  for (const char* m : {"robot-a", "robot-b"}) {
    EXPECT_EQ(str_at(out, {"members", m, "result"}), "acknowledged") << m;
    EXPECT_NE(json::dump(robots_[m]->status(fleet_token_)).find("\"estop_active\":true"),
              std::string::npos)
        << m;
  }
  EXPECT_EQ(str_at(out, {"members", "robot-c", "result"}), "timeout");
  EXPECT_EQ(str_at(out, {"members", "robot-c", "last_status", "reason"}), "connection_lost");
  // Naming the members that are up, or not waiting at all, succeeds.
  auto named = fleet({"estop", "alpha", "--members", "robot-a,robot-b"});
  EXPECT_EQ(named.exit_code, 0) << named.out << named.err;
  auto fire = fleet({"estop", "alpha", "--no-wait"});
  EXPECT_EQ(fire.exit_code, 0) << fire.out << fire.err;
  EXPECT_EQ(bool_at(parse(fire.out), {"waited"}), "false");
  // A RESUME or a command no member's confirmation of could be verified (no --members-dir) is
  // not sent.
  auto lone = test::run_cli({"fleet", "resume", "alpha", "--broker", broker_->url(), "--token",
                             tmp_.file("fleet.token"), "--key-dir", key_dir_});
  EXPECT_EQ(lone.exit_code, 1);
  EXPECT_NE(lone.err.find("nothing was sent"), std::string::npos) << lone.err;
  EXPECT_NE(json::dump(robots_["robot-a"]->status(fleet_token_)).find("\"estop_active\":true"),
            std::string::npos);
}

// A commander whose fleet token binds its ML-DSA-65 key (rcan token issue --bind-alg ml-dsa-65):
// the CLI signs with that key, and the robots verify it (docs/FLEET.md §Benchmark: an ML-DSA-65
// signature costs a robot a quarter of an Ed25519 one's CPU). A message from it signed with its
// Ed25519 key instead is refused: the token names the one key.
TEST_F(FleetTest, AFleetTokenBoundToAnMlDsaKeyStopsAndResumesTheFleet) {
  add_robot("robot-a", "0000000a");
  add_robot("robot-b", "0000000b");
  const std::string pq_token =
      token("owner", {"robot-a", "robot-b"}, "coordinator", "rcan://local.rcan/rcan/sim-rover/*",
            true, msgsig::Alg::kMlDsa65);
  write_file(tmp_.file("fleet.token"), pq_token);
  auto stopped = fleet({"estop", "alpha", "--members", "robot-a,robot-b", "--reason", "pq"});
  ASSERT_EQ(stopped.exit_code, 0) << stopped.out << stopped.err;
  for (const char* m : {"robot-a", "robot-b"}) {
    EXPECT_EQ(str_at(parse(stopped.out), {"members", m, "result"}), "acknowledged") << m;
    EXPECT_NE(json::dump(robots_[m]->status(fleet_token_)).find("\"estop_active\":true"),
              std::string::npos)
        << m;
  }
  auto resumed = fleet({"resume", "alpha", "--members", "robot-a,robot-b"});
  ASSERT_EQ(resumed.exit_code, 0) << resumed.out << resumed.err;
  for (const char* m : {"robot-a", "robot-b"})
    EXPECT_NE(json::dump(robots_[m]->status(fleet_token_)).find("\"estop_active\":false"),
              std::string::npos)
        << m;
  // The same token on a message signed with the commander's Ed25519 key: not the bound key.
  Watcher w(broker_->url(), {"rcan/fleet/alpha/robot/robot-a/reply"});
  json::Value wrong =
      command_msg("SAFETY", {{"safety_event", "ESTOP"}, {"fleet_id", "alpha"}}, pq_token);
  w.publish("rcan/fleet/alpha/robot/robot-a/cmd", wrong);
  auto reply = w.wait([&](const Watcher::Msg& m) {
    return str_of(m.body, "reply_to") == str_of(wrong, "message_id") &&
           str_of(m.body, "type") != "EVENT";
  });
  ASSERT_TRUE(reply);
  EXPECT_EQ(payload_str(reply->body, "error_code"), "SIGNATURE_INVALID") << json::dump(reply->body);
  EXPECT_NE(json::dump(robots_["robot-a"]->status(fleet_token_)).find("\"estop_active\":false"),
            std::string::npos);
}

// A broker that accepts a publish and drops it: Mosquitto denying the operator write access by
// ACL. Over MQTT 3.1.1 (what the CLI speaks) Mosquitto still answers PUBACK, so the broker's
// acknowledgement proves nothing here; waiting for the members does: every verb exits 1 and
// names the robot that never heard it.
TEST_F(FleetTest, AnAclDenialIsCaughtByWaitingForTheMembers) {
  write_file(tmp_.file("acl"), "topic readwrite rcan/#\nuser operator\ntopic read rcan/#\n");
  auto dir = tmp_.path() + "/acl-broker";
  fs::create_directories(dir);
  // Started as root, Mosquitto drops to its own user before reading the ACL file, which lives
  // in this test's private directory: keep it root (ignored when the test is not root).
  Broker acl(dir, "user root\nacl_file " + tmp_.file("acl") + "\n");
  robots_["robot-a"] =
      std::make_unique<Robot>(tmp_.path(), "robot-a", "0000000a", acl.url(), secret_);
  write_file(tmp_.file("run.json"), R"({"command":"COORDINATED_MOVE","fleet_id":"alpha",
    "choreography":{"type":"sequential","steps":[
      {"robot":"robot-a","action":"move","params":{"linear":0.1,"duration_ms":100}}]}})");
  const std::vector<std::vector<std::string>> verbs{
      {"estop", "alpha"},  // the members directory: robot-a
      {"resume", "alpha"},
      {"command", "alpha", "move", "--params", R"({"linear":0.1,"duration_ms":100})"},
      {"run", tmp_.file("run.json")},
  };
  for (auto args : verbs) {
    args.insert(args.begin(), "fleet");
    args.insert(args.end(),
                {"--broker", acl.url(), "--token", tmp_.file("fleet.token"), "--key-dir", key_dir_,
                 "--members-dir", members_dir(), "--username", "operator", "--timeout-ms", "1500"});
    auto r = test::run_cli(args);
    EXPECT_EQ(r.exit_code, 1) << args[1] << "\n" << r.out << r.err;
    EXPECT_NE(r.err.find("robot-a"), std::string::npos) << args[1] << ": " << r.err;
  }
  EXPECT_EQ(json::dump(robots_["robot-a"]->status(fleet_token_)).find("\"estop_active\":true"),
            std::string::npos);
  // The control: an anonymous client may write, and the same ESTOP latches the robot.
  auto allowed = test::run_cli({"fleet", "estop", "alpha", "--members", "robot-a", "--broker",
                                acl.url(), "--token", tmp_.file("fleet.token"), "--key-dir",
                                key_dir_, "--members-dir", members_dir()});
  EXPECT_EQ(allowed.exit_code, 0) << allowed.out << allowed.err;
  EXPECT_NE(json::dump(robots_["robot-a"]->status(fleet_token_)).find("\"estop_active\":true"),
            std::string::npos);
}

TEST_F(FleetTest, LastWillShowsTheRobotOffline) {
  add_robot("robot-a", "0000000a");
  add_robot("robot-b", "0000000b");
  Watcher w(broker_->url(),
            {"rcan/fleet/alpha/robot/robot-a/status", "rcan/fleet/alpha/robot/robot-b/status"});
  // A graceful stop says so itself (a clean disconnect sends no will).
  EXPECT_EQ(robots_["robot-b"]->proc().stop(SIGTERM, 10000), 0);
  auto gone = w.wait([](const Watcher::Msg& m) {
    return m.topic == "rcan/fleet/alpha/robot/robot-b/status" && m.body.get("online") &&
           !m.body.get("online")->as_bool();
  });
  ASSERT_TRUE(gone);
  EXPECT_EQ(str_of(gone->body, "reason"), "shutdown");
  auto online = w.wait([](const Watcher::Msg& m) {
    return m.topic == "rcan/fleet/alpha/robot/robot-a/status" && m.body.get("online") &&
           m.body.get("online")->as_bool();
  });
  ASSERT_TRUE(online);
  robots_["robot-a"]->kill9();
  auto offline = w.wait([](const Watcher::Msg& m) {
    return m.topic == "rcan/fleet/alpha/robot/robot-a/status" && m.body.get("online") &&
           !m.body.get("online")->as_bool();
  });
  ASSERT_TRUE(offline);
  EXPECT_EQ(str_of(offline->body, "reason"), "connection_lost");
  // `rcan fleet status` sees the retained will.
  auto s = fleet({"status", "alpha"});
  EXPECT_EQ(s.exit_code, 0);
  EXPECT_NE(s.out.find("connection_lost"), std::string::npos) << s.out;
}

TEST_F(FleetTest, ReconnectAfterBrokerRestartNeverRunsACommandTwice) {
  Robot& a = add_robot("robot-a", "0000000a");
  std::string cmd_topic = "rcan/robot/local_rcan/rcan/sim-rover/0000000a/cmd";
  std::string reply_topic = "rcan/robot/local_rcan/rcan/sim-rover/0000000a/reply";
  std::string id = new_uuid_v4();
  json::Value msg = command_msg(
      "COMMAND", json::Object{{"action", "move"}, {"linear", 0.1}, {"duration_ms", 100}},
      token("owner", {}), id);
  {
    Watcher w(broker_->url(), {reply_topic});
    w.publish(cmd_topic, msg);
    auto ack = w.wait([&](const Watcher::Msg& m) { return str_of(m.body, "reply_to") == id; });
    ASSERT_TRUE(ack);
    EXPECT_EQ(str_of(ack->body, "type"), "ACK");
  }
  // The broker goes away and comes back; the robot reconnects by itself (backoff).
  broker_->stop();
  ASSERT_TRUE(a.proc().wait_for_line("mqtt_disconnected", 10000));
  broker_->start();
  ASSERT_TRUE(a.proc().wait_for_line("\"connects\":2", 15000)) << a.proc().err();
  // The same message again (a redelivery after reconnect looks exactly like this): refused.
  Watcher w(broker_->url(), {reply_topic});
  w.publish(cmd_topic, msg);
  auto again = w.wait([&](const Watcher::Msg& m) { return str_of(m.body, "reply_to") == id; });
  ASSERT_TRUE(again);
  EXPECT_EQ(str_of(again->body, "type"), "ERROR");
  EXPECT_EQ(payload_str(again->body, "error_code"), "REPLAY_DETECTED");
  // Exactly one COMMAND record for that id: it ran once. (A refusal is answered without waiting
  // for its record to be durable, so the REPLAY_DETECTED record may trail the ERROR briefly.)
  int commands = 0, replays = 0;
  for (int attempt = 0; attempt < 100 && replays == 0; ++attempt) {
    if (attempt > 0) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    commands = replays = 0;
    json::Value entries = parse(a.audit(fleet_token_));
    for (const auto& e : entries.get("entries")->as_array()) {
      if (str_of(e, "message_id") != id) continue;
      if (str_of(e, "event") == "COMMAND") ++commands;
      if (str_of(e, "event") == "REPLAY_DETECTED") ++replays;
    }
  }
  EXPECT_EQ(commands, 1);
  EXPECT_EQ(replays, 1);
}

TEST_F(FleetTest, BrokerRestartInTheMiddleOfARunExecutesNoStepTwice) {
  three_robots();
  write_file(tmp_.file("long.json"), R"({"command":"COORDINATED_MOVE","fleet_id":"alpha",
    "choreography":{"type":"sequential","steps":[
      {"robot":"robot-a","action":"move","params":{"linear":0.1,"duration_ms":1500},"timeout_ms":8000},
      {"robot":"robot-b","action":"move","params":{"linear":0.1,"duration_ms":300},"timeout_ms":8000},
      {"robot":"robot-c","action":"move","params":{"linear":0.1,"duration_ms":300},"timeout_ms":8000}]}})");
  test::RunResult run;
  std::thread coordinator([&] {
    run = fleet({"run", tmp_.file("long.json"), "--timeout-ms", "3000"});
  });
  // Step 0 (1.5 s of motion) is under way: take the broker away and bring it back.
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  broker_->stop();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  broker_->start();
  coordinator.join();
  // The run either finished or failed safely (every moved robot stopped) — never a usage error.
  ASSERT_TRUE(run.exit_code == 0 || run.exit_code == 1) << run.out << run.err;
  json::Value out = parse(run.out);
  std::string cid = str_of(out, "choreography_id");
  ASSERT_FALSE(cid.empty());
  // No step ran twice on any robot: at most one accepted COMMAND per (robot, step).
  for (auto& [name, robot] : robots_) {
    json::Value entries = parse(robot->audit(fleet_token_));
    std::map<int64_t, int> per_step;
    for (const auto& e : entries.get("entries")->as_array()) {
      const json::Value* d = e.get("detail");
      if (str_of(e, "event") != "COMMAND" || d == nullptr || str_of(*d, "choreography_id") != cid)
        continue;
      ++per_step[d->get("fleet_step")->as_int()];
    }
    for (auto& [step, n] : per_step) EXPECT_EQ(n, 1) << name << " step " << step;
    if (name == "robot-a") {
      EXPECT_EQ(per_step[0], 1);  // sent before the restart: ran exactly once
    }
  }
  if (run.exit_code == 1) {
    for (auto& [name, robot] : robots_) EXPECT_TRUE(comes_to_rest(*robot)) << name;
  }
}

TEST_F(FleetTest, FleetJwtIsCheckedPerRobot) {
  three_robots();
  Watcher w(broker_->url(), {"rcan/fleet/alpha/robot/+/reply"});
  // A fleet token listing robot-a and robot-b only.
  std::string partial = token("owner", {"robot-a", "robot-b"});
  std::string id = new_uuid_v4();
  w.publish("rcan/fleet/alpha/cmd",
            command_msg("FLEET_COMMAND", json::Object{{"command", "status"}, {"fleet_id", "alpha"}},
                        partial, id));
  auto reply_of = [&](const std::string& robot, const std::string& mid) {
    return w.wait([&](const Watcher::Msg& m) {
      return m.topic == "rcan/fleet/alpha/robot/" + robot + "/reply" &&
             str_of(m.body, "reply_to") == mid && str_of(m.body, "type") != "EVENT";
    });
  };
  for (const char* m : {"robot-a", "robot-b"}) {
    auto r = reply_of(m, id);
    ASSERT_TRUE(r) << m;
    EXPECT_EQ(str_of(r->body, "type"), "ACK") << m;
  }
  auto c = reply_of("robot-c", id);
  ASSERT_TRUE(c);
  EXPECT_EQ(payload_str(c->body, "error_code"), "AUTH_INVALID");
  // A valid token without a `fleet` claim may not command through the fleet…
  std::string plain = token("owner", {});
  std::string id2 = new_uuid_v4();
  w.publish("rcan/fleet/alpha/robot/robot-a/cmd",
            command_msg("COMMAND", json::Object{{"action", "status"}}, plain, id2));
  auto r2 = reply_of("robot-a", id2);
  ASSERT_TRUE(r2);
  EXPECT_EQ(payload_str(r2->body, "error_code"), "INSUFFICIENT_PRIVILEGES");
  // …nor name another fleet…
  std::string id3 = new_uuid_v4();
  w.publish("rcan/fleet/alpha/robot/robot-a/cmd",
            command_msg("FLEET_COMMAND", json::Object{{"command", "status"}, {"fleet_id", "beta"}},
                        fleet_token_, id3));
  auto r3 = reply_of("robot-a", id3);
  ASSERT_TRUE(r3);
  EXPECT_EQ(payload_str(r3->body, "error_code"), "INSUFFICIENT_PRIVILEGES");
  // …but it may always stop a robot (ESTOP/STOP need authentication only).
  std::string id4 = new_uuid_v4();
  w.publish("rcan/fleet/alpha/robot/robot-a/cmd",
            command_msg("SAFETY", json::Object{{"safety_event", "STOP"}}, plain, id4));
  auto r4 = reply_of("robot-a", id4);
  ASSERT_TRUE(r4);
  EXPECT_EQ(str_of(r4->body, "type"), "ACK");
  // The v1.5 fleet audience "rcan://fleet/<group>": accepted from a fleet token of this fleet only.
  struct AudCase {
    std::string aud;
    std::vector<std::string> fleet;
    const char* expect;
  } auds[] = {{"rcan://fleet/alpha", {"robot-a"}, "ACK"},
              {"rcan://fleet/alpha", {}, "AUTH_INVALID"},
              {"rcan://fleet/beta", {"robot-a"}, "AUTH_INVALID"},
              // "fleet:<fleet_id>" names every member of that fleet, and no other fleet's.
              {"rcan://fleet/alpha", {"fleet:alpha"}, "ACK"},
              {"rcan://local.rcan/rcan/sim-rover/*", {"fleet:alpha"}, "ACK"},
              {"rcan://fleet/alpha", {"fleet:beta"}, "AUTH_INVALID"},
              {"rcan://fleet/alpha", {"alpha"}, "AUTH_INVALID"}};
  for (const auto& ac : auds) {
    std::string aid = new_uuid_v4();
    w.publish(
        "rcan/fleet/alpha/robot/robot-a/cmd",
        command_msg("FLEET_COMMAND", json::Object{{"command", "status"}, {"fleet_id", "alpha"}},
                    token("owner", ac.fleet, "coordinator", ac.aud), aid));
    auto ar = reply_of("robot-a", aid);
    ASSERT_TRUE(ar) << ac.aud;
    std::string got =
        str_of(ar->body, "type") == "ACK" ? "ACK" : payload_str(ar->body, "error_code");
    EXPECT_EQ(got, ac.expect) << ac.aud << " fleet claim: " << ac.fleet.size();
  }
  // A forged token (wrong secret) is refused everywhere.
  std::string id5 = new_uuid_v4();
  std::string forged = partial.substr(0, partial.rfind('.') + 1) + "AAAA";
  w.publish("rcan/fleet/alpha/estop",
            command_msg("SAFETY", json::Object{{"safety_event", "ESTOP"}}, forged, id5));
  auto r5 = reply_of("robot-a", id5);
  ASSERT_TRUE(r5);
  EXPECT_EQ(payload_str(r5->body, "error_code"), "AUTH_INVALID");
  // Malformed payloads get the error body, never a crash.
  w.publish("rcan/fleet/alpha/robot/robot-b/cmd", json::Value("not an object"));
  auto bad = w.wait([&](const Watcher::Msg& m) {
    return m.topic == "rcan/fleet/alpha/robot/robot-b/reply" &&
           payload_str(m.body, "error_code") == "SCHEMA_VALIDATION_FAILED";
  });
  EXPECT_TRUE(bad);
  EXPECT_TRUE(robots_["robot-b"]->proc().running());
}

// docs/SECURITY.md R8: whoever reads a topic sees the tokens on it. A robot accepts a message
// over MQTT only with a token bound to a key (cnf) and a signature by that key, so a copied
// token cannot carry a message of the reader's own — not even an ESTOP.
TEST_F(FleetTest, MqttMessagesNeedATokenBoundToTheSendersKey) {
  add_robot("robot-a", "0000000a");
  add_robot("robot-b", "0000000b", "", ", require_bound_tokens: false");  // a lab's opt-out
  Watcher w(broker_->url(), {"rcan/fleet/alpha/robot/+/reply"});
  auto reply_of = [&](const std::string& robot, const std::string& mid) {
    return w.wait([&](const Watcher::Msg& m) {
      return m.topic == "rcan/fleet/alpha/robot/" + robot + "/reply" &&
             str_of(m.body, "reply_to") == mid && str_of(m.body, "type") != "EVENT";
    });
  };
  auto outcome = [&](const std::string& robot, const json::Value& msg) {
    w.publish("rcan/fleet/alpha/robot/" + robot + "/cmd", msg);
    auto r = reply_of(robot, str_of(msg, "message_id"));
    if (!r) return std::string("no reply");
    return str_of(r->body, "type") == "ACK" ? std::string("ACK")
                                            : payload_str(r->body, "error_code");
  };
  const json::Object estop{{"safety_event", "ESTOP"}, {"fleet_id", "alpha"}};
  const json::Object status{{"command", "status"}, {"fleet_id", "alpha"}};
  // A plain bearer token, as anyone reading a topic of an older deployment would have it.
  std::string bearer = token("owner", {"robot-a", "robot-b"}, "coordinator",
                             "rcan://local.rcan/rcan/sim-rover/*", false);
  EXPECT_EQ(outcome("robot-a", command_msg("SAFETY", estop, bearer, new_uuid_v4(), false)),
            "AUTH_INVALID");
  EXPECT_EQ(outcome("robot-a", command_msg("SAFETY", estop, bearer)), "AUTH_INVALID");
  // A bound token without a signature.
  EXPECT_EQ(outcome("robot-a", command_msg("SAFETY", estop, fleet_token_, new_uuid_v4(), false)),
            "AUTH_REQUIRED");
  // The commander's signed message, seen on the topic…
  json::Value seen = command_msg("FLEET_COMMAND", status, fleet_token_);
  EXPECT_EQ(outcome("robot-a", seen), "ACK");
  // …and the reader's own message with the commander's token and signature copied onto it.
  json::Value copied = seen;
  copied.as_object().set("message_id", new_uuid_v4());
  copied.as_object().set("type", "SAFETY");
  copied.as_object().set("payload", estop);
  EXPECT_EQ(outcome("robot-a", copied), "SIGNATURE_INVALID");
  // …or signed with the reader's own key.
  const std::string other_dir = tmp_.file("reader-keys");
  ASSERT_EQ(test::run_cli({"keys", "generate", "--dir", other_dir}).exit_code, 0);
  auto other = keys::load_dir(other_dir);
  ASSERT_TRUE(other.ok());
  json::Object theirs{{"version", "1.0.0"},         {"message_id", new_uuid_v4()},
                      {"type", "SAFETY"},           {"timestamp_ms", wall_ms()},
                      {"auth_token", fleet_token_}, {"payload", estop}};
  ASSERT_TRUE(msgsig::sign_ed25519(theirs, other->ed25519_seed.span()).ok());
  EXPECT_EQ(outcome("robot-a", json::Value(theirs)), "SIGNATURE_INVALID");
  // None of it latched robot-a.
  EXPECT_NE(json::dump(robots_["robot-a"]->status(fleet_token_)).find("\"estop_active\":false"),
            std::string::npos);
  // The opted-out robot takes a bearer token, and said at start what that means.
  EXPECT_EQ(outcome("robot-b", command_msg("FLEET_COMMAND", status, bearer, new_uuid_v4(), false)),
            "ACK");
  EXPECT_NE(robots_["robot-b"]->proc().err().find("mqtt_unbound_tokens_accepted"),
            std::string::npos);
  EXPECT_EQ(robots_["robot-a"]->proc().err().find("mqtt_unbound_tokens_accepted"),
            std::string::npos);
  // The CLI will not send with a bound token whose key it was not given.
  auto cli = test::run_cli(
      {"fleet", "estop", "alpha", "--broker", broker_->url(), "--token", tmp_.file("fleet.token")});
  EXPECT_EQ(cli.exit_code, 2) << cli.out << cli.err;
  EXPECT_NE(cli.err.find("--key-dir"), std::string::npos) << cli.err;
  EXPECT_NE(json::dump(robots_["robot-a"]->status(fleet_token_)).find("\"estop_active\":false"),
            std::string::npos);
}

// docs/SECURITY.md: a commander's token reaches the robots in the command envelope, and no
// robot passes it on — nothing a robot publishes (replies, status, telemetry, events, audit
// records) carries it, for accepted and for refused commands alike.
TEST_F(FleetTest, RobotsNeverPublishTheCommandersToken) {
  three_robots();
  Watcher w(broker_->url(), {"rcan/#"});
  // Accepted: a fleet command to every member. Refused: a token without a fleet claim, and a
  // forged one.
  std::string plain = token("owner", {}, "plain-commander");
  std::string forged = fleet_token_.substr(0, fleet_token_.rfind('.') + 1) + "AAAA";
  std::string fleet_id = new_uuid_v4();
  w.publish("rcan/fleet/alpha/cmd",
            command_msg("FLEET_COMMAND", json::Object{{"command", "status"}, {"fleet_id", "alpha"}},
                        fleet_token_, fleet_id));
  std::vector<std::pair<std::string, std::string>> waits;  // (robot, message id)
  for (const char* robot : {"robot-a", "robot-b", "robot-c"}) waits.emplace_back(robot, fleet_id);
  for (const std::string& tok : {plain, forged}) {
    std::string id = new_uuid_v4();
    w.publish("rcan/fleet/alpha/robot/robot-a/cmd",
              command_msg("COMMAND", json::Object{{"action", "status"}}, tok, id));
    waits.emplace_back("robot-a", id);
  }
  for (const auto& [robot, id] : waits)
    ASSERT_TRUE(w.wait([&](const Watcher::Msg& m) {
      return m.topic == "rcan/fleet/alpha/robot/" + robot + "/reply" &&
             str_of(m.body, "reply_to") == id;
    })) << robot
        << " " << id;
  std::this_thread::sleep_for(
      std::chrono::milliseconds(300));  // the audit mirror publishes after the record
  size_t outbound = 0;
  for (const auto& m : w.all()) {
    bool inbound = m.topic.ends_with("/cmd") || m.topic.ends_with("/estop");
    if (inbound) continue;
    ++outbound;
    std::string text = json::dump(m.body);
    for (const std::string& tok : {fleet_token_, plain, forged}) {
      EXPECT_EQ(text.find(tok), std::string::npos) << m.topic;
      size_t dot = tok.rfind('.');
      if (dot != std::string::npos && tok.size() - dot > 20) {
        EXPECT_EQ(text.find(tok.substr(dot + 1)), std::string::npos)
            << m.topic << ": " << text.substr(0, 300);
      }
    }
  }
  EXPECT_GT(outbound, 6u) << "the robots published nothing to check";
}

// The robot's events topic is read by whoever the broker lets subscribe: it carries the events
// for everyone (ESTOP) and never one principal's (a queued claim's PROMOTED).
TEST_F(FleetTest, EventsTopicCarriesNoOnePrincipalsEvents) {
  Robot& r = add_robot("robot-a", "0000000a");
  Watcher w(broker_->url(), {"rcan/fleet/alpha/robot/robot-a/events"});
  auto post = [&](const std::string& path, const std::string& body, const std::string& tok) {
    return test::http(r.port(), "POST", path, body, {{"Authorization", "Bearer " + tok}});
  };
  // HTTP calls carry no message signature: plain bearer tokens (a bound one needs its key's).
  const std::string aud = "rcan://local.rcan/rcan/sim-rover/*";
  std::string a = token("user", {}, "mqtt-user-a", aud, false);
  std::string b = token("user", {}, "mqtt-user-b", aud, false);
  auto claimed = post("/rcan/v1/auth/claim", "{}", a);
  ASSERT_EQ(claimed.status, 200) << claimed.body;
  auto queued = post("/rcan/v1/auth/claim", "{}", b);
  ASSERT_EQ(queued.status, 409) << queued.body;
  ASSERT_NE(queued.body.find("\"queued\":true"), std::string::npos) << queued.body;
  auto released = post("/rcan/v1/auth/release", "{}", a);
  ASSERT_EQ(released.status, 200) << released.body;
  // B now holds control (the promotion happened, on B's streams only).
  auto again = post("/rcan/v1/auth/claim", "{}", a);
  ASSERT_EQ(again.status, 409) << again.body;
  // An event for everyone after it: when it is on the topic, the promotion would be too.
  auto stop =
      post("/api/stop", R"({"reason":"events topic test"})", token("owner", {}, "op", aud, false));
  ASSERT_EQ(stop.status, 200) << stop.body;
  ASSERT_TRUE(w.wait([](const Watcher::Msg& m) {
    return json::dump(m.body).find("ESTOP") != std::string::npos;
  })) << "no ESTOP event on the events topic";
  for (const auto& m : w.all()) {
    std::string text = json::dump(m.body);
    EXPECT_EQ(text.find("PROMOTED"), std::string::npos) << text;
    EXPECT_EQ(text.find("key_b64"), std::string::npos) << text;
  }
}

TEST_F(FleetTest, SwarmLeaderFailoverAndJoinPolicy) {
  three_robots(swarm_yaml());
  Watcher w(broker_->url(), {"rcan/swarm/s42/announce", "rcan/swarm/s42/join/+"});
  auto first =
      w.wait([](const Watcher::Msg& m) { return payload_str(m.body, "leader") == "robot-a"; });
  ASSERT_TRUE(first);
  EXPECT_EQ(str_of(first->body, "type"), "SWARM_ANNOUNCE");
  EXPECT_EQ(payload_str(first->body, "formation"), "follow-leader");
  EXPECT_EQ(payload_str(first->body, "join_policy"), "approval");
  // Join under the approval policy: pending, then granted by an OWNER's approval.
  std::string jid = new_uuid_v4();
  w.publish("rcan/swarm/s42/join",
            signed_msg(json::Object{{"type", "SWARM_JOIN"},
                                    {"message_id", jid},
                                    {"timestamp_ms", wall_ms()},
                                    {"auth_token", token("user", {}, "robot-d")},
                                    {"payload", json::Object{{"member", "robot-d"}}}}));
  auto pending = w.wait([&](const Watcher::Msg& m) { return str_of(m.body, "reply_to") == jid; });
  ASSERT_TRUE(pending);
  EXPECT_EQ(str_of(pending->body, "type"), "PENDING_AUTH");
  // The announce with the request pending raised the epoch: a replay of the swarm's own earlier
  // announce (its MAC is valid, nothing pending in it) is stale, and the leader puts its state
  // back. Were it of the same epoch, the leader would take it and forget the pending request,
  // and the OWNER's approval below would be refused.
  auto with_pending = w.wait([](const Watcher::Msg& m) {
    return payload_str(m.body, "reason") == "join_pending" &&
           json::dump(*m.body.get("payload")->get("pending")).find("robot-d") != std::string::npos;
  });
  ASSERT_TRUE(with_pending);
  EXPECT_GT(with_pending->body.get("payload")->get("epoch")->as_int(),
            first->body.get("payload")->get("epoch")->as_int());
  w.publish("rcan/swarm/s42/announce", first->body);
  auto put_back = w.wait([](const Watcher::Msg& m) {
    return payload_str(m.body, "reason") == "superseded" &&
           json::dump(*m.body.get("payload")->get("pending")).find("robot-d") != std::string::npos;
  });
  EXPECT_TRUE(put_back) << "the replayed announce was taken";
  std::string aid = new_uuid_v4();
  w.publish("rcan/swarm/s42/join",
            signed_msg(json::Object{{"type", "SWARM_APPROVE"},
                                    {"message_id", aid},
                                    {"timestamp_ms", wall_ms()},
                                    {"auth_token", token("owner", {})},
                                    {"payload", json::Object{{"member", "robot-d"}}}}));
  auto granted = w.wait([&](const Watcher::Msg& m) { return str_of(m.body, "reply_to") == aid; });
  ASSERT_TRUE(granted);
  EXPECT_EQ(str_of(granted->body, "type"), "GRANTED");
  // A join with a bad token is denied.
  std::string bid = new_uuid_v4();
  w.publish("rcan/swarm/s42/join",
            signed_msg(json::Object{{"type", "SWARM_JOIN"},
                                    {"message_id", bid},
                                    {"timestamp_ms", wall_ms()},
                                    {"auth_token", "not-a-token"},
                                    {"payload", json::Object{{"member", "robot-e"}}}}));
  auto denied = w.wait([&](const Watcher::Msg& m) { return str_of(m.body, "reply_to") == bid; });
  ASSERT_TRUE(denied);
  EXPECT_EQ(str_of(denied->body, "type"), "DENIED");
  // So is an OWNER's approval with a plain bearer token (a copy read off the topic would do).
  std::string cid = new_uuid_v4();
  w.publish(
      "rcan/swarm/s42/join",
      json::Value(json::Object{{"type", "SWARM_APPROVE"},
                               {"message_id", cid},
                               {"timestamp_ms", wall_ms()},
                               {"auth_token", token("owner", {}, "coordinator",
                                                    "rcan://local.rcan/rcan/sim-rover/*", false)},
                               {"payload", json::Object{{"member", "robot-e"}}}}));
  auto copied = w.wait([&](const Watcher::Msg& m) { return str_of(m.body, "reply_to") == cid; });
  ASSERT_TRUE(copied);
  EXPECT_EQ(str_of(copied->body, "type"), "DENIED");
  EXPECT_EQ(payload_str(copied->body, "reason"), "AUTH_INVALID");
  // The leader goes silent: robot-b (first live member in order) takes over and announces.
  robots_["robot-a"]->kill9();
  auto next =
      w.wait([](const Watcher::Msg& m) { return payload_str(m.body, "reason") == "leader_silent"; },
             15000);
  ASSERT_TRUE(next);
  EXPECT_EQ(payload_str(next->body, "leader"), "robot-b");
  EXPECT_EQ(payload_str(next->body, "previous_leader"), "robot-a");
  EXPECT_EQ(payload_str(next->body, "announced_by"), "robot-b");
  std::string members = json::dump(*next->body.get("payload")->get("members"));
  EXPECT_NE(members.find("robot-d"), std::string::npos) << members;  // the approved member stays
  // The change is audited on the new leader (the record is written just after the announce).
  bool audited = false;
  for (int i = 0; i < 100 && !audited; ++i) {
    audited =
        robots_["robot-b"]->audit(fleet_token_).find("SWARM_LEADER_CHANGE") != std::string::npos;
    if (!audited) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_TRUE(audited);
}

// docs/FLEET.md §Swarms, authenticity: announces and heartbeats carry an HMAC under the
// members' shared secret. A client with the broker's credentials but not the secret forges a
// retained announce naming itself leader, and keeps a dead leader "alive" with heartbeats, forged
// and replayed: the members drop them all, the leader puts its own announce back, and when the
// leader really dies the next member takes over.
TEST_F(FleetTest, SwarmMessagesWithoutTheSecretAreDropped) {
  three_robots(swarm_yaml());
  Watcher w(broker_->url(), {"rcan/swarm/s42/announce", "rcan/swarm/s42/heartbeat/robot-a"});
  auto first = w.wait([](const Watcher::Msg& m) {
    return m.topic == "rcan/swarm/s42/announce" && payload_str(m.body, "leader") == "robot-a";
  });
  ASSERT_TRUE(first);
  EXPECT_EQ(str_of(first->body, "swarm_mac").size(), 64u) << json::dump(first->body);
  auto beat = w.wait([](const Watcher::Msg& m) { return str_of(m.body, "type") == "HEARTBEAT"; });
  ASSERT_TRUE(beat);
  EXPECT_EQ(str_of(beat->body, "swarm_mac").size(), 64u) << json::dump(beat->body);

  // A forged retained announce (no MAC, then a made-up one): mallory leads at epoch 1000.
  json::Object forged{
      {"type", "SWARM_ANNOUNCE"},
      {"message_id", new_uuid_v4()},
      {"timestamp_ms", wall_ms()},
      {"payload", json::Object{{"swarm_id", "s42"},
                               {"members", json::Array{"mallory", "robot-a", "robot-b", "robot-c"}},
                               {"leader", "mallory"},
                               {"epoch", 1000},
                               {"announced_by", "mallory"}}}};
  w.publish("rcan/swarm/s42/announce", json::Value(forged), true);
  forged.set("swarm_mac", std::string(64, 'a'));
  w.publish("rcan/swarm/s42/announce", json::Value(forged), true);
  // Each forged announce is answered by the leader's own; the second, which came within the
  // same second, once the leader's once-a-second limit allows — so the swarm's has the last word
  // (before, the limit swallowed it and the second forgery stayed retained).
  int restores = 0;
  auto restored = w.wait([&](const Watcher::Msg& m) {
    return payload_str(m.body, "reason") == "restored" &&
           payload_str(m.body, "leader") == "robot-a" && ++restores == 2;
  });
  ASSERT_TRUE(restored) << restores << " restored announce(s)";
  // What a member starting now is greeted with is the swarm's own announce.
  {
    Watcher late(broker_->url(), {"rcan/swarm/s42/announce"});
    auto retained = late.wait([](const Watcher::Msg& m) { return m.retained; });
    ASSERT_TRUE(retained);
    EXPECT_EQ(payload_str(retained->body, "leader"), "robot-a") << json::dump(retained->body);
  }

  // The leader dies; robot-a's captured heartbeat is replayed and fresh ones are forged.
  robots_["robot-a"]->kill9();
  std::atomic<bool> done{false};
  std::thread keep_alive([&] {
    json::Value replay = beat->body;
    while (!done.load()) {
      w.publish("rcan/swarm/s42/heartbeat/robot-a", replay);
      json::Object fresh = beat->body.as_object();
      fresh.set("timestamp_ms", wall_ms());
      w.publish("rcan/swarm/s42/heartbeat/robot-a", json::Value(fresh));
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  });
  auto next =
      w.wait([](const Watcher::Msg& m) { return payload_str(m.body, "reason") == "leader_silent"; },
             15000);
  done = true;
  keep_alive.join();
  ASSERT_TRUE(next);
  EXPECT_EQ(payload_str(next->body, "leader"), "robot-b");
  EXPECT_EQ(payload_str(next->body, "previous_leader"), "robot-a");
  const std::string members = json::dump(*next->body.get("payload")->get("members"));
  EXPECT_EQ(members.find("mallory"), std::string::npos) << members;
  // The members said what they dropped.
  EXPECT_TRUE(robots_["robot-b"]->proc().wait_for_line("swarm_message_dropped", 5000));
}

TEST_F(FleetTest, FleetAuditIntoPostgresCatchesTamperingAndGaps) {
  Postgres pg;
  three_robots();
  // The collector holds each robot's chain secret (to verify HMACs on ingest).
  fs::create_directories(tmp_.file("secrets"));
  fs::permissions(tmp_.file("secrets"), fs::perms::owner_all);
  for (auto& [name, robot] : robots_) {
    fs::copy_file(robot->dir() + "/audit.secret", tmp_.file("secrets/" + name + ".secret"));
    fs::permissions(tmp_.file("secrets/" + name + ".secret"),
                    fs::perms::owner_read | fs::perms::owner_write);
  }
  Watcher w(broker_->url(), {"rcan/fleet/alpha/robot/+/audit"});
  test::RunResult collected;
  std::thread collector([&] {
    collected = fleet({"audit", "collect", "alpha", "--db", pg.conninfo(), "--secrets-dir",
                       tmp_.file("secrets"), "--duration-ms", "6000"});
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // the collector is subscribed
  auto r = fleet({"command", "alpha", "status", "--members", "robot-a,robot-b,robot-c"});
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  auto rec = w.wait([](const Watcher::Msg& m) {
    return m.topic == "rcan/fleet/alpha/robot/robot-a/audit" &&
           str_of(m.body, "event") == "COMMAND";
  });
  ASSERT_TRUE(rec);
  int64_t seq = rec->body.get("seq")->as_int();
  // 1. A tampered copy (the outcome rewritten, the hmac kept) under the next seq: refused.
  json::Object tampered = rec->body.as_object();
  tampered.set("outcome", "blocked");
  tampered.set("seq", seq + 100);
  w.publish("rcan/fleet/alpha/robot/robot-a/audit", json::Value(tampered));
  // 2. A correctly sealed record (with robot-b's own secret) far ahead of its chain: a gap.
  std::string secret = test::read_file(tmp_.file("secrets/robot-b.secret"));
  auto b_rec = w.wait(
      [](const Watcher::Msg& m) { return m.topic == "rcan/fleet/alpha/robot/robot-b/audit"; });
  ASSERT_TRUE(b_rec);
  json::Object gap = b_rec->body.as_object();
  int64_t gap_seq = gap.find("seq")->as_int() + 50;
  gap.set("seq", gap_seq);
  gap.erase("hmac");
  gap.set("hmac", hmac_sha256_hex(secret, json::canonical_without(gap, "hmac")));
  w.publish("rcan/fleet/alpha/robot/robot-b/audit", json::Value(gap));
  collector.join();
  ASSERT_EQ(collected.exit_code, 1) << collected.out << collected.err;
  json::Value out = parse(collected.out);
  std::string a_problems = json::dump(*out.get("robots")->get("robot-a")->get("problems"));
  EXPECT_NE(a_problems.find("hmac_mismatch"), std::string::npos) << a_problems;
  std::string b_problems = json::dump(*out.get("robots")->get("robot-b")->get("problems"));
  EXPECT_NE(b_problems.find("\"gap\""), std::string::npos) << b_problems;
  EXPECT_EQ(json::dump(*out.get("robots")->get("robot-c")->get("problems")), "[]");
  // The database holds the genuine chains (the tampered record is not stored, only flagged).
  auto stored = pg.sql("SELECT count(*) FROM rcan_fleet_audit WHERE member='robot-a' AND seq=" +
                       std::to_string(seq + 100));
  EXPECT_EQ(stored.out, "0\n") << stored.err;
  auto flagged = pg.sql("SELECT problem FROM rcan_fleet_audit_problems WHERE member='robot-a'");
  EXPECT_NE(flagged.out.find("hmac_mismatch"), std::string::npos) << flagged.out << flagged.err;
  // Re-verification from the database: robot-b's gap is still there…
  auto v = fleet({"audit", "verify", "--db", pg.conninfo(), "--fleet", "alpha", "--secrets-dir",
                  tmp_.file("secrets")});
  EXPECT_EQ(v.exit_code, 1) << v.out << v.err;
  EXPECT_NE(v.out.find("\"gap\""), std::string::npos) << v.out;
  EXPECT_EQ(v.out.find("robot-a"), std::string::npos) << v.out;
  // …and a row altered inside the database after ingest is caught.
  auto upd = pg.sql(
      "UPDATE rcan_fleet_audit SET line = replace(line, '\"outcome\":\"ok\"', "
      "'\"outcome\":\"blocked\"') "
      "WHERE member='robot-a' AND seq=" +
      std::to_string(seq));
  EXPECT_EQ(upd.exit_code, 0) << upd.err;
  auto v2 = fleet({"audit", "verify", "--db", pg.conninfo(), "--fleet", "alpha"});
  EXPECT_EQ(v2.exit_code, 1);
  EXPECT_NE(v2.out.find("record_hash_mismatch"), std::string::npos) << v2.out;
  EXPECT_NE(v2.out.find("robot-a"), std::string::npos) << v2.out;
}

// ---- fleets on NATS (docs/FLEET.md §Running on NATS)

// The reproduction of issue 32 on a 3-node NATS cluster: the robot is on node 1, the operator on
// node 3. `rcan fleet estop` (no --members: the members directory names robot-a) goes
// out at QoS 1 — the cluster's SUBACK granted no more — and exits 0 only once the robot has
// confirmed the latch. With node 1 gone (and no failover URL) the robot cannot hear it: the CLI
// exits 1 and names it.
TEST_F(NatsFleetTest, ClusterFleetEstopLatchesTheRobotAndNamesItWhenItsBrokerIsGone) {
  Nats nats(tmp_.path(), 3);
  {
    // The robot's status, published on node 1, has crossed the cluster to node 3 (a robot's
    // first connection to a fresh cluster waits for its JetStream session).
    Watcher w(nats.url(2), {"rcan/fleet/alpha/robot/+/status"});
    robot_on(nats.url(0), "robot-a", "0000000a");
    ASSERT_TRUE(
        w.wait([](const Watcher::Msg& m) { return m.body.get("online") != nullptr; }, 15000));
  }
  auto r = fleet_via(nats.url(2), {"estop", "alpha", "--reason", "nats cluster"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  json::Value out = parse(r.out);
  EXPECT_EQ(bool_at(out, {"ok"}), "true");
  EXPECT_EQ(int_at(out, {"qos"}), 1);
  EXPECT_EQ(str_at(out, {"members", "robot-a", "result"}), "acknowledged") << r.out;
  EXPECT_TRUE(latched("robot-a"));
  auto res = fleet_via(nats.url(1), {"resume", "alpha"});
  ASSERT_EQ(res.exit_code, 0) << res.out << res.err;
  EXPECT_FALSE(latched("robot-a"));

  nats.kill(0);
  ASSERT_TRUE(robots_["robot-a"]->proc().wait_for_line("mqtt_disconnected", 10000));
  // The two remaining nodes elect new leaders for the MQTT streams of node 1 (NATS refuses
  // subscriptions meanwhile): wait until node 3 serves the fleet's statuses again.
  int settled_after = -1;
  for (int i = 0; i < 60 && settled_after < 0; ++i) {
    if (fleet_via(nats.url(2), {"status", "alpha", "--timeout-ms", "2000"}).exit_code == 0)
      settled_after = i;
    else
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
  ASSERT_GE(settled_after, 0) << nats.proc(2).err();
  // A publish the settling cluster drops before its PUBACK is NOT DELIVERED (exit 1 too), and a
  // connection it refuses while it settles is "cannot connect" (exit 2): both are sent again.
  test::RunResult gone;
  for (int i = 0; i < 5; ++i) {
    gone =
        fleet_via(nats.url(2), {"estop", "alpha", "--members", "robot-a", "--timeout-ms", "15000"});
    if (gone.err.find("NOT DELIVERED") == std::string::npos &&
        gone.err.find("cannot connect to the broker") == std::string::npos)
      break;
    std::this_thread::sleep_for(std::chrono::seconds(1));
  }
  EXPECT_EQ(gone.exit_code, 1) << gone.out << gone.err;
  EXPECT_NE(gone.err.find("robot-a (timeout)"), std::string::npos) << gone.err;
  json::Value g = parse(gone.out);
  EXPECT_EQ(bool_at(g, {"ok"}), "false");
  const json::Value* unconfirmed = path_of(g, {"unconfirmed"});
  EXPECT_EQ(unconfirmed ? json::dump(*unconfirmed) : "missing", "[\"robot-a\"]") << gone.out;
  EXPECT_FALSE(latched("robot-a"));  // the exit code told the truth: it did not stop
}

// NATS refuses '.' in a topic (its subjects are dotted), and a robot's own topic carries its
// registry (`local.rcan` by default): every subscription of a fleet member must still be granted
// on NATS, its RURI topic answered, and a move longer than mqtt.failover_ms must not be cut
// short as if the fleet channel were lost.
TEST_F(NatsFleetTest, EveryTopicOfARobotWorksOnNats) {
  Nats nats(tmp_.path(), 1);
  Robot& robot = robot_on(nats.url(0), "robot-a", "0000000a", ", failover_ms: 500");
  auto ruri = parse_ruri("rcan://local.rcan/rcan/sim-rover/0000000a");
  ASSERT_TRUE(ruri.ok());
  auto t = mqtt::robot_topics("rcan", *ruri);
  ASSERT_TRUE(t.ok());
  Watcher w(nats.url(0), {t->reply()});
  const std::string id = new_uuid_v4();
  w.publish(t->cmd(),
            command_msg("COMMAND",
                        json::Object{{"action", "move"}, {"linear", 0.1}, {"duration_ms", 2500}},
                        token("owner", {}), id));
  auto ack = w.wait([&](const Watcher::Msg& m) { return str_of(m.body, "reply_to") == id; });
  ASSERT_TRUE(ack) << robot.proc().err();
  EXPECT_EQ(str_of(ack->body, "type"), "ACK") << json::dump(ack->body);
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // 3 × failover_ms, moving
  robot.proc().drain(100);
  EXPECT_EQ(robot.proc().err().find("mqtt_subscription_refused"), std::string::npos)
      << robot.proc().err();
  EXPECT_EQ(robot.proc().err().find("fleet_channel_stop"), std::string::npos) << robot.proc().err();
  EXPECT_EQ(json::dump(robot.status(fleet_token_)).find("fleet_channel_lost"), std::string::npos);
}

// A broker that refuses a publish — NATS, with QoS 2 forced by --qos 2 — makes every fleet verb
// exit 1 with the reason, --no-wait included; nothing reaches the robot. Left to choose, the
// same verbs work at QoS 1 on the same broker, also for a robot whose estop subscription asks
// for QoS 2 (mqtt.estop_qos: 2, granted 1), one capped by mqtt.max_qos: 1 and one that takes the
// fleet ESTOP at QoS 0 (mqtt.estop_qos: 0: no JetStream consumer for it).
TEST_F(NatsFleetTest, ARefusedPublishFailsEveryVerb) {
  Nats nats(tmp_.path(), 1);
  robot_on(nats.url(0), "robot-a", "0000000a", ", estop_qos: 2");
  robot_on(nats.url(0), "robot-b", "0000000b", ", max_qos: 1");
  robot_on(nats.url(0), "robot-c", "0000000c", ", estop_qos: 0");
  write_file(tmp_.file("run.json"), R"({"command":"COORDINATED_MOVE","fleet_id":"alpha",
    "choreography":{"type":"sequential","steps":[
      {"robot":"robot-a","action":"move","params":{"linear":0.1,"duration_ms":100}}]}})");
  const std::vector<std::vector<std::string>> verbs{
      {"estop", "alpha"},
      {"estop", "alpha", "--no-wait"},
      {"resume", "alpha", "--members", "robot-a,robot-b,robot-c"},
      {"command", "alpha", "move", "--params", R"({"linear":0.1,"duration_ms":100})"},
      {"run", tmp_.file("run.json")},
  };
  for (auto args : verbs) {
    args.insert(args.end(), {"--qos", "2", "--timeout-ms", "3000"});
    auto r = fleet_via(nats.url(0), args);
    EXPECT_EQ(r.exit_code, 1) << args[0] << " " << args.back() << "\n" << r.out << r.err;
    EXPECT_NE(r.err.find("closed the connection before acknowledging"), std::string::npos)
        << args[0] << ": " << r.err;
  }
  for (const char* m : {"robot-a", "robot-b", "robot-c"}) EXPECT_FALSE(latched(m)) << m;
  // Chosen automatically: QoS 1, acknowledged by the broker and by every robot.
  auto e = fleet_via(nats.url(0), {"estop", "alpha"});
  ASSERT_EQ(e.exit_code, 0) << e.out << e.err;
  EXPECT_EQ(int_at(parse(e.out), {"qos"}), 1);
  for (const char* m : {"robot-a", "robot-b", "robot-c"}) {
    EXPECT_TRUE(latched(m)) << m;
    EXPECT_EQ(str_at(parse(e.out), {"members", m, "result"}), "acknowledged") << e.out;
    // Delivered at the granted QoS: 1 (NATS grants a requested 2 at 1), 0 for robot-c.
    auto estops = audit_events(*robots_[m], fleet_token_, "ESTOP");
    ASSERT_FALSE(estops.empty()) << m;
    EXPECT_EQ(int_at(estops.front(), {"detail", "mqtt_qos"}), std::string(m) == "robot-c" ? 0 : 1)
        << m;
  }
  auto r = fleet_via(nats.url(0), {"resume", "alpha", "--qos", "1"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  auto c = fleet_via(nats.url(0), {"command", "alpha", "move", "--params",
                                   R"({"linear":0.1,"duration_ms":100})", "--wait-complete"});
  EXPECT_EQ(c.exit_code, 0) << c.out << c.err;
  auto run = fleet_via(nats.url(0), {"run", tmp_.file("run.json")});
  EXPECT_EQ(run.exit_code, 0) << run.out << run.err;
}

TEST(FleetJwt, FleetAudienceNeedsAFleetClaim) {
  jwt::VerifyOptions o;
  o.audience = "rcan://local.rcan/rcan/sim-rover/0000000a";
  o.fleet_ids = {"robot-a"};
  o.fleet_audiences = {"rcan://fleet/alpha"};
  int64_t now = 1'800'000'000;
  json::Object base{{"iss", "i"},      {"sub", "s"},
                    {"role", "owner"}, {"scope", json::Array{"control"}},
                    {"iat", now},      {"exp", now + 60}};
  auto with = [&](const char* aud, bool fleet_claim) {
    json::Object c = base;
    c.set("aud", aud);
    if (fleet_claim) c.set("fleet", json::Array{"robot-a"});
    return jwt::check_claims(c, o, now);
  };
  EXPECT_TRUE(with("rcan://fleet/alpha", true).ok());
  EXPECT_FALSE(with("rcan://fleet/alpha", false).ok());  // not a fleet token
  EXPECT_FALSE(with("rcan://fleet/beta", true).ok());    // another fleet
  EXPECT_TRUE(with("rcan://local.rcan/rcan/sim-rover/*", false).ok());
  o.fleet_ids = {"robot-b"};
  EXPECT_FALSE(with("rcan://fleet/alpha", true).ok());  // this robot is not in the claim
}

TEST(FleetConfig, MqttFleetAndSwarmBlocksAreStrict) {
  const std::string base =
      "rcan_version: \"1.2\"\nruri: rcan://local.rcan/rcan/sim-rover/0000000a\nnode: {data_dir: "
      "/tmp/x}\n";
  auto ok = config::parse_config_text(
      base +
      "mqtt: {enabled: true, broker: \"mqtt://broker.local:1884\"}\n"
      "fleet: {fleet_id: alpha, member_id: robot-a, robots: [robot-a, robot-b],"
      " commands: {broadcast: false}}\n"
      "swarm: {swarm_id: s1, member_id: robot-a, members: [robot-b, robot-a],"
      " secret_file: /tmp/x/swarm.secret}\n");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_TRUE(ok->mqtt.enabled);
  EXPECT_EQ(ok->fleet.fleet_id, "alpha");
  EXPECT_FALSE(ok->fleet.broadcast);
  EXPECT_EQ(ok->swarm.leader, "robot-a");  // first in order by default
  EXPECT_EQ(ok->swarm.join_policy, "closed");
  struct Bad {
    std::string yaml, field;
  } bad[] = {
      {"mqtt: {enabled: true, broker: \"http://x\"}\n", "mqtt.broker"},
      {"mqtt: {enabled: true, broker: \"mqtts://x\"}\n", "mqtt.tls.ca_file"},
      {"mqtt: {enabled: true, topic_prefix: \"rcan/#\"}\n", "mqtt.topic_prefix"},
      {"mqtt: {enabled: true, username: u}\n", "mqtt.password_file"},
      {"mqtt: {enabled: true, brokr: x}\n", "mqtt.brokr"},
      {"fleet: {fleet_id: alpha, robots: [a]}\n", "fleet"},
      {"mqtt: {enabled: true}\nfleet: {fleet_id: alpha, robots: [robot-b]}\n", "fleet.robots"},
      {"mqtt: {enabled: true}\nfleet: {fleet_id: \"al/pha\", robots: [0000000a]}\n",
       "fleet.fleet_id"},
      {"mqtt: {enabled: true}\nswarm: {swarm_id: s, members: [a], leader: z}\n", "swarm.leader"},
      {"mqtt: {enabled: true}\nswarm: {swarm_id: s, join_policy: maybe}\n", "swarm.join_policy"},
      {"mqtt: {enabled: true}\nswarm: {swarm_id: s}\n", "swarm.secret_file"},
  };
  for (const auto& b : bad) {
    auto r = config::parse_config_text(base + b.yaml);
    ASSERT_FALSE(r.ok()) << b.yaml;
    EXPECT_EQ(r.error().field, b.field) << b.yaml << " → " << r.error().message;
  }
  // The swarm's secret file is read at start: private and long enough, or rcand says why.
  test::TempDir dir;
  config::NodeConfig c = *ok;
  c.swarm.secret_file = dir.file("swarm.secret");
  EXPECT_EQ(node::mqtt_node_options(c).error().code, ErrorCode::kNotFound);
  write_file(c.swarm.secret_file, "0123456789abcdef0123456789abcdef-swarm",
             fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read);
  auto open = node::mqtt_node_options(c);
  ASSERT_FALSE(open.ok());
  EXPECT_NE(open.error().message.find("chmod 600"), std::string::npos) << open.error().message;
  write_file(c.swarm.secret_file, "too short");
  EXPECT_EQ(node::mqtt_node_options(c).error().code, ErrorCode::kSchemaValidationFailed);
  write_file(c.swarm.secret_file, "0123456789abcdef0123456789abcdef-swarm\n");
  auto good = node::mqtt_node_options(c);
  ASSERT_TRUE(good.ok()) << good.error().message;
  EXPECT_EQ(good->swarm_secret, "0123456789abcdef0123456789abcdef-swarm");
}

TEST(MqttTopics, LayoutAndParser) {
  auto ruri = parse_ruri("rcan://local.rcan/acme/rover/0000000a");
  ASSERT_TRUE(ruri.ok());
  auto t = mqtt::robot_topics("rcan", *ruri);
  ASSERT_TRUE(t.ok());
  EXPECT_EQ(t->cmd(), "rcan/robot/local_rcan/acme/rover/0000000a/cmd");
  EXPECT_EQ(mqtt::parse_topic("rcan", t->cmd()).kind, mqtt::TopicKind::kRobotCmd);
  auto f = mqtt::parse_topic("rcan", "rcan/fleet/alpha/robot/robot-a/cmd");
  EXPECT_EQ(f.kind, mqtt::TopicKind::kMemberCmd);
  EXPECT_EQ(f.fleet_id, "alpha");
  EXPECT_EQ(f.member, "robot-a");
  EXPECT_EQ(mqtt::parse_topic("rcan", "rcan/fleet/alpha/estop").kind, mqtt::TopicKind::kFleetEstop);
  EXPECT_EQ(mqtt::parse_topic("rcan", "rcan/fleet/+/cmd").kind, mqtt::TopicKind::kOther);
  EXPECT_EQ(mqtt::parse_topic("rcan", "rcan/fleet//cmd").kind, mqtt::TopicKind::kOther);
  EXPECT_EQ(mqtt::parse_topic("rcan", "other/fleet/alpha/cmd").kind, mqtt::TopicKind::kOther);
  EXPECT_EQ(mqtt::parse_topic("rcan", "rcanx/fleet/alpha/cmd").kind, mqtt::TopicKind::kOther);
  EXPECT_EQ(mqtt::parse_payload("[1]").error().code, ErrorCode::kSchemaValidationFailed);
  EXPECT_EQ(mqtt::parse_payload("{").error().code, ErrorCode::kMalformedJson);
  EXPECT_EQ(mqtt::parse_payload(std::string(70000, ' ')).error().code, ErrorCode::kBodyTooLarge);
  EXPECT_TRUE(mqtt::parse_payload("{\"a\":1}").ok());
  auto u = transport::parse_broker_url("mqtts://[::1]:8884");
  ASSERT_TRUE(u.ok());
  EXPECT_EQ(u->host, "::1");
  EXPECT_EQ(u->port, 8884);
  EXPECT_TRUE(u->tls);
  EXPECT_EQ(transport::parse_broker_url("mqtt://h").value().port, 1883);
  EXPECT_FALSE(transport::parse_broker_url("mqtt://h:0").ok());
  EXPECT_FALSE(transport::parse_broker_url("mqtt://h:99999").ok());
  EXPECT_FALSE(transport::parse_broker_url("mqtt://").ok());
}

}  // namespace
}  // namespace rcan

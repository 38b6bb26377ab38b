// rcan fleet — drive a fleet of robots over an MQTT broker (docs/FLEET.md).
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "base/clock.h"
#include "cli.h"
#include "fleet_audit_db.h"
#include "fleet_choreography.h"
#include "fleet_session.h"
#include "message_signer.h"
#include "rcan/audit/secret.h"
#include "rcan/errors.h"
#include "rcan/hash.h"
#include "rcan/json.h"
#include "rcan/mqtt_topics.h"
#include "transport/mqtt_client.h"

namespace rcan::cli {
namespace {

constexpr const char* kHelp =
    "usage:\n"
    "  rcan fleet estop FLEET [--members a,b,…] [--no-wait] [--reason TEXT]\n"
    "      Publishes a retained ESTOP on the fleet's estop topic (QoS 2, or QoS 1 on a broker\n"
    "      without QoS 2): every member latches it, and so does a member that connects later.\n"
    "      Waits for the broker's acknowledgement, then for each member's signed confirmation:\n"
    "      --members, else every member of --members-dir, sending a new ESTOP every 2 s to each\n"
    "      one still silent. Names each robot that did not confirm (a reply its robot did not\n"
    "      sign is not believed). Without --members-dir it is still published, and exit 1.\n"
    "      --no-wait: fire and forget (the broker must still acknowledge).\n"
    "  rcan fleet resume FLEET [--members a,b,…] [--no-wait]\n"
    "      Replaces the retained ESTOP with a RESUME (LEASEE or above); live members resume.\n"
    "  rcan fleet command FLEET ACTION [--params JSON] [--members a,b,…] [--no-wait]\n"
    "      [--wait-complete]\n"
    "      Broadcasts a FLEET_COMMAND to every member and waits for each ACK (and, with\n"
    "      --wait-complete, each completion); members as for estop.\n"
    "  rcan fleet run CHOREOGRAPHY.json\n"
    "      Runs a COORDINATED_MOVE: publishes each step to its robot, waits for its completion\n"
    "      (sequential, or parallel with wait_for), and on a refusal, an abort, a timeout or a\n"
    "      publish the broker did not acknowledge stops every robot it moved and reports the\n"
    "      failed step. Needs --members-dir with every robot of the run.\n"
    "  rcan fleet status FLEET\n"
    "      Prints each member's retained status (online or offline); with --members-dir only\n"
    "      the statuses their robots signed, and the members without one.\n"
    "  rcan fleet audit collect FLEET (--out DIR | --db CONNINFO) [--secrets-dir D] [--duration-ms "
    "N]\n"
    "      Subscribes to the members' audit topics for N ms (default 5000) and checks each\n"
    "      robot's chain on ingest: seq continuity (gap), prev_hash links (break), and with\n"
    "      D/<member>.secret the HMAC (a tampered record is refused). --out appends the records\n"
    "      to DIR/<member>.jsonl (verify offline with rcan audit verify --partial); --db stores\n"
    "      them in PostgreSQL (libpq connection string; schema in docs/FLEET.md).\n"
    "  rcan fleet audit verify --db CONNINFO [--fleet F] [--secrets-dir D]\n"
    "      Re-verifies every stored chain from the database: record hashes, links, gaps, HMACs.\n"
    "  Common options: --broker URL[,URL…] (a cluster's nodes, tried in turn; default\n"
    "    $RCAN_MQTT_URL, else mqtt://127.0.0.1:1883),\n"
    "    --token FILE (a fleet JWT; default $RCAN_TOKEN_FILE), --prefix P (default rcan),\n"
    "    --key-dir D (default $RCAN_KEY_DIR: the key pair the token is bound to; robots accept\n"
    "    MQTT messages only with a key-bound token, signed by its key: rcan token issue\n"
    "    --bind-key D),\n"
    "    --members-dir D (default $RCAN_FLEET_MEMBERS_DIR: one directory per member, named by its\n"
    "    member id, holding that robot's ed25519.pub from its key_dir; a\n"
    "    reply or status counts only when that robot signed it; needed to wait for members),\n"
    "    --ca-file F (mqtts), --username U --password-file F, --timeout-ms N (default 10000),\n"
    "    --qos 1|2 (force the QoS of every publish and subscription; default: 2 for the estop\n"
    "    topic and 1 for commands, and 1 throughout when the broker's SUBACK grants less than 2).\n"
    "  Exit: 0 success; 1 the broker did not acknowledge a publish (it refused it, or the\n"
    "    connection dropped on each of 3 attempts, each on a new connection), or a robot\n"
    "    refused, failed or did not confirm in time (its signed reply), or no member's\n"
    "    confirmation can be verified;\n"
    "    2 usage error or no connection to the broker.\n";

int64_t wall_ms() { return unix_ms(); }

void print(const json::Value& v) { std::printf("%s\n", json::dump(v).c_str()); }

using fleet::mono_ms;
using fleet::Session;

struct Common {
  std::string prefix = "rcan";
  std::string token;
  MessageSigner signer;  // signs with the key the token is bound to (cnf), if it is
  int64_t timeout_ms = 10000;
  int qos = 0;  // --qos: 1 or 2 forced; 0: QoS 2 for the estop topic unless the broker lacks it
  bool wait = true;  // --no-wait: fire and forget (the broker's acknowledgement is still needed)
};

const std::vector<std::string> kValued{
    "broker",     "token",       "prefix", "ca-file", "username", "password-file",
    "timeout-ms", "members",     "reason", "params",  "out",      "duration-ms",
    "db",         "secrets-dir", "fleet",  "qos",     "key-dir",  "members-dir"};
const std::vector<std::string> kFlags{"wait-complete", "no-wait"};

Result<Common> common(const Options& o, bool need_token) {
  Common c;
  c.prefix = o.get("prefix", "rcan");
  if (!mqtt::valid_topic_prefix(c.prefix))
    return Error(ErrorCode::kSchemaValidationFailed, "--prefix is not a valid topic prefix");
  std::string tf =
      o.get("token", std::getenv("RCAN_TOKEN_FILE") ? std::getenv("RCAN_TOKEN_FILE") : "");
  if (need_token) {
    if (tf.empty())
      return Error(ErrorCode::kSchemaValidationFailed, "--token FILE is required (a fleet JWT)");
    auto t = read_file(tf);
    if (!t.ok()) return t.error();
    c.token = *t;
    while (!c.token.empty() &&
           (c.token.back() == '\n' || c.token.back() == '\r' || c.token.back() == ' '))
      c.token.pop_back();
    std::string kd =
        o.get("key-dir", std::getenv("RCAN_KEY_DIR") ? std::getenv("RCAN_KEY_DIR") : "");
    auto signer = MessageSigner::for_token(c.token, kd);
    if (!signer.ok()) return signer.error();
    c.signer = std::move(signer).value();
  }
  if (o.has("timeout-ms")) {
    const std::string text = o.get("timeout-ms");  // `end` points into it
    char* end = nullptr;
    long long v = std::strtoll(text.c_str(), &end, 10);
    if (end == nullptr || *end != '\0' || v < 1 || v > 3'600'000)
      return Error(ErrorCode::kSchemaValidationFailed, "--timeout-ms must be 1..3600000");
    c.timeout_ms = v;
  }
  if (o.has("qos")) {
    if (o.get("qos") != "1" && o.get("qos") != "2")
      return Error(ErrorCode::kSchemaValidationFailed, "--qos must be 1 or 2");
    c.qos = o.get("qos") == "1" ? 1 : 2;
  }
  c.wait = !o.has("no-wait");
  return c;
}

// Exit 1 with the reason on stderr: the fleet did not get what was asked of it.
int failure(std::string_view verb, const std::string& msg) {
  std::fprintf(stderr, "rcan %.*s: %s\n", static_cast<int>(verb.size()), verb.data(), msg.c_str());
  return 1;
}

// A message with the fleet token, signed by the key the token is bound to (when it is).
json::Value message(const std::string& type, json::Object payload, const Common& c,
                    const std::string& id = new_uuid_v4()) {
  json::Value m(json::Object{{"version", "1.0.0"},
                             {"message_id", id},
                             {"type", type},
                             {"timestamp_ms", wall_ms()},
                             {"auth_token", c.token},
                             {"payload", std::move(payload)}});
  if (Status s = c.signer.sign(m); !s.ok())  // the robot refuses it unsigned, and says why
    std::fprintf(stderr, "rcan fleet: cannot sign the message: %s\n", s.error().message.c_str());
  return m;
}

bool valid_ids(const std::vector<std::string>& ids) {
  for (const auto& m : ids)
    if (!mqtt::valid_topic_segment(m)) return false;
  return true;
}

// Waits for the reply to `ids` (message_id → member) on the member reply topics: ACK/ERROR,
// and with `complete`, the COMPLETED/ABORTED event. Returns {member: result}.
json::Object await_replies(Session& s, const std::map<std::string, std::string>& ids, bool complete,
                           int64_t timeout_ms, bool* all_ok) {
  std::map<std::string, json::Object> results;
  std::set<std::string> open;
  for (const auto& [id, member] : ids) open.insert(id);
  int64_t deadline = mono_ms() + timeout_ms;
  while (!open.empty()) {
    auto m = s.next(deadline);
    if (!m) break;
    std::string reply_to = json::string_field(m->body, "reply_to");
    auto it = ids.find(reply_to);
    if (it == ids.end() || open.count(reply_to) == 0) continue;
    std::string type = json::string_field(m->body, "type");
    json::Object& r = results[reply_to];
    r.set("member", it->second);
    if (type == "ERROR") {
      const json::Value* p = m->body.get("payload");
      r.set("result", "refused");
      if (p != nullptr) r.set("error", *p);
      open.erase(reply_to);
    } else if (type == "ACK") {
      r.set("result", "acknowledged");
      if (!complete) open.erase(reply_to);
    } else if (type == "EVENT") {
      const json::Value* p = m->body.get("payload");
      std::string ev = p != nullptr ? json::string_field(*p, "event") : "";
      r.set("result", ev == "COMPLETED" ? "completed" : "aborted");
      open.erase(reply_to);
    }
  }
  json::Object out;
  *all_ok = true;
  for (const auto& [id, member] : ids) {
    auto it = results.find(id);
    json::Object r =
        it == results.end() ? json::Object{{"member", member}, {"result", "timeout"}} : it->second;
    std::string res = json::string_field(json::Value(r), "result");
    if (open.count(id) != 0 && res == "acknowledged") r.set("result", "timeout");
    res = json::string_field(json::Value(r), "result");
    if (res != (complete ? "completed" : "acknowledged") && !(complete && res == "completed"))
      *all_ok = false;
    out.set(member, std::move(r));
  }
  return out;
}

// Who must confirm: --members, else every member of --members-dir; with --no-wait, nobody.
// Members come from the operator's configuration, never from what the broker holds: a topic
// writer can erase a retained status (and with it a member) or add one.
struct Targets {
  std::vector<std::string> members;
  std::vector<std::string> no_key;            // of them, those whose replies cannot be verified
  std::shared_ptr<fleet::FleetMembers> keys;  // null: no --members-dir
};

Result<std::shared_ptr<fleet::FleetMembers>> members_dir(const Options& o) {
  const char* env = std::getenv("RCAN_FLEET_MEMBERS_DIR");
  const std::string dir = o.get("members-dir", env != nullptr ? env : "");
  if (dir.empty()) return std::shared_ptr<fleet::FleetMembers>();
  auto m = fleet::FleetMembers::load(dir);
  if (!m.ok()) return m.error();
  return std::make_shared<fleet::FleetMembers>(std::move(m).value());
}

// Opens the session (member replies and statuses subscribed, believed only when signed by their
// robot) and names the members that must confirm. Errors are usage/connection errors (exit 2).
Result<Targets> open_fleet(Session& s, const Options& o, const Common& c, const std::string& fleet,
                           const mqtt::FleetTopics& topics) {
  Targets t;
  t.members = split_list(o.get("members"));
  if (!valid_ids(t.members))
    return Error(ErrorCode::kSchemaValidationFailed, "bad member id in --members");
  s.set_timeout(c.timeout_ms);
  std::vector<std::string> subs{topics.base + "/robot/+/reply"};
  if (c.wait) {
    auto keys = members_dir(o);
    if (!keys.ok()) return keys.error();
    t.keys = std::move(keys).value();
    if (t.members.empty() && t.keys) t.members = t.keys->names();
    for (const auto& m : t.members)
      if (!t.keys || !t.keys->knows(m)) t.no_key.push_back(m);
    // Statuses: each silent member's last word (signed too), for the report.
    subs.push_back(topics.base + "/robot/+/status");
  } else {
    t.members.clear();
  }
  s.vouched_by(fleet, topics.base, t.keys.get());
  if (Status st = s.open(o, subs, c.qos); !st.ok()) return st.error();
  return t;
}

// A fleet ESTOP sent again while members have not confirmed it: every `every_ms`, a new ESTOP
// (`make`: a fresh message_id and timestamp — a copy of the first would be stale past a
// member's safety window) on the command topic of each member still silent. It reaches a member
// that came back from a broker outage after the first was published, also when the broker
// acknowledged the first but did not keep its retained copy (NATS 2.9 logs "unable to store
// retained message" and acknowledges anyway, while its cluster elects leaders). Members that
// confirmed get nothing more. A RESUME or a command is never sent twice.
struct Resend {
  std::function<json::Value()> make;
  int64_t every_ms = 2000;
  std::vector<std::string> ids;  // the message_ids sent again
};

// Waits for each member's answer to `id` (or to one of `resend`'s) on its reply topic: ACK,
// ERROR and, with `complete`, the COMPLETED / ABORTED event. Returns {member: {result, reply}};
// `unconfirmed` gets every member that did not confirm (refused, aborted, incomplete or silent).
json::Object await_members(Session& s, const mqtt::FleetTopics& topics, const std::string& id,
                           const Targets& t, bool complete, int64_t timeout_ms, Resend* resend,
                           std::vector<std::string>* unconfirmed) {
  json::Object results;
  std::set<std::string> open(t.members.begin(), t.members.end());
  for (const auto& m : t.no_key) open.erase(m);  // nothing it says could be believed
  std::map<std::string, json::Value> last_status;
  std::set<std::string> acked, ids{id};
  int64_t deadline = mono_ms() + timeout_ms;
  int64_t next_resend = resend != nullptr ? mono_ms() + resend->every_ms : INT64_MAX;
  const uint64_t connects = s.connects();
  while (!open.empty() && !s.lost(connects)) {  // a dropped connection loses the replies
    if (mono_ms() >= next_resend && mono_ms() < deadline) {
      json::Value again = resend->make();
      for (const auto& mem : open) s.publish_queued(topics.member(mem).cmd(), again, 1, false);
      ids.insert(json::string_field(again, "message_id"));
      resend->ids.push_back(json::string_field(again, "message_id"));
      next_resend = mono_ms() + resend->every_ms;
      continue;
    }
    auto m = s.next(std::min({deadline, next_resend, mono_ms() + 200}));
    if (!m && mono_ms() >= deadline) break;
    if (m && m->topic.size() > 7 && m->topic.compare(m->topic.size() - 7, 7, "/status") == 0) {
      for (const auto& mem : t.members)
        if (m->topic == topics.member(mem).status()) last_status[mem] = m->body;
      continue;
    }
    if (!m || ids.count(json::string_field(m->body, "reply_to")) == 0) continue;
    for (const auto& mem : t.members) {
      if (m->topic != topics.member(mem).reply() || open.count(mem) == 0) continue;
      std::string type = json::string_field(m->body, "type");
      if (type == "ACK" && complete) {
        acked.insert(mem);
        continue;
      }
      std::string res = type == "ACK" ? "acknowledged" : type == "ERROR" ? "refused" : "";
      if (type == "EVENT") {
        const json::Value* p = m->body.get("payload");
        res = p != nullptr && json::string_field(*p, "event") == "COMPLETED" ? "completed"
                                                                             : "aborted";
      }
      if (res.empty()) continue;
      results.set(mem, json::Object{{"result", res}, {"reply", m->body}});
      const json::Value* p = m->body.get("payload");
      const std::string code = p != nullptr ? json::string_field(*p, "error_code") : "";
      // A late copy (a session's queued one after an outage): the retained ESTOP may still latch.
      if (code == "MESSAGE_STALE" || code == "REPLAY_DETECTED") continue;
      if (res != "acknowledged" && res != "completed") unconfirmed->push_back(mem);
      open.erase(mem);
    }
  }
  for (const auto& mem : open) {
    if (results.find(mem) != nullptr) {  // only a late copy's refusal came
      unconfirmed->push_back(mem);
      continue;
    }
    json::Object r{{"result", acked.count(mem)   ? "incomplete"
                              : s.lost(connects) ? "broker_lost"
                                                 : "timeout"}};
    auto st = last_status.find(mem);
    if (st != last_status.end()) r.set("last_status", st->second);
    results.set(mem, std::move(r));
    unconfirmed->push_back(mem);
  }
  for (const auto& mem : t.no_key) {
    results.set(mem, json::Object{{"result", "no_key"}});
    unconfirmed->push_back(mem);
  }
  // What a topic writer (or a robot with another key) said in a member's name: never believed,
  // always shown.
  for (const auto& [mem, d] : s.dropped()) {
    json::Value* r = results.find(mem);
    if (r == nullptr || !r->is_object()) continue;
    r->as_object().set("unverified_replies", d.count);
    r->as_object().set("unverified_reason", d.reason);
  }
  return results;
}

// "robot-a (timeout), robot-b (refused)"; "robot-c (timeout; 1 message not signed by robot-c
// ignored: unsigned)".
std::string name_unconfirmed(const std::vector<std::string>& unconfirmed,
                             const json::Object& results) {
  std::string out;
  for (const auto& m : unconfirmed) {
    const json::Value* r = results.find(m);
    std::string why = r ? json::string_field(*r, "result") : "?";
    const json::Value* n = r ? r->get("unverified_replies") : nullptr;
    if (n != nullptr && n->is_int())
      why += "; " + std::to_string(n->as_int()) + " message" + (n->as_int() == 1 ? "" : "s") +
             " not signed by " + m + " ignored: " + json::string_field(*r, "unverified_reason");
    if (why == "no_key") why = "no key in --members-dir: its reply cannot be verified";
    out += (out.empty() ? "" : ", ") + m + " (" + why + ")";
  }
  return out;
}

// Publishes one fleet message and, unless --no-wait, waits for the members' confirmations.
// Exit 0 only when the broker acknowledged the publish and every member it waited for
// confirmed; 1 otherwise, naming what failed on stderr.
int publish_and_confirm(Session& s, const char* verb, const Common& c,
                        const mqtt::FleetTopics& topics, const Targets& t, const std::string& topic,
                        const json::Value& msg, int qos, bool retain, bool complete,
                        json::Object out, Resend* resend = nullptr) {
  const std::string id = json::string_field(msg, "message_id");
  const int used_qos = s.qos_for(c.qos != 0 ? c.qos : qos);
  out.set("message_id", id);
  out.set("qos", static_cast<int64_t>(used_qos));
  out.set("waited", c.wait);
  Status sent = s.publish(topic, msg, used_qos, retain);
  out.set("publish_attempts", static_cast<int64_t>(s.attempts()));
  if (Status st = sent; !st.ok()) {
    s.close();
    out.set("ok", false);
    out.set("error", "not delivered: " + st.error().message);
    print(json::Value(std::move(out)));
    return failure(verb, "NOT DELIVERED: " + st.error().message);
  }
  std::vector<std::string> unconfirmed;
  const uint64_t connects = s.connects();
  json::Object results =
      await_members(s, topics, id, t, complete, c.timeout_ms, resend, &unconfirmed);
  const std::string lost =
      s.lost(connects) ? " (the connection to the broker at " + s.url() + " dropped)" : "";
  s.close();
  bool none_known = c.wait && t.members.empty();
  bool ok = unconfirmed.empty() && !none_known;
  out.set("ok", ok);
  out.set("members", results);
  json::Array un;
  for (const auto& m : unconfirmed) un.emplace_back(m);
  out.set("unconfirmed", std::move(un));
  if (resend != nullptr) {
    json::Array again;
    for (const auto& i : resend->ids) again.emplace_back(i);
    out.set("resent", std::move(again));
  }
  print(json::Value(std::move(out)));
  if (none_known)
    return failure(verb,
                   "the broker acknowledged the message, but no member's confirmation can be "
                   "verified: give the fleet's robots' public keys with --members-dir D (or "
                   "RCAN_FLEET_MEMBERS_DIR), or use --no-wait");
  if (!ok)
    return failure(verb, std::to_string(unconfirmed.size()) + " of " +
                             std::to_string(t.members.size()) + " robots did not confirm within " +
                             std::to_string(c.timeout_ms) + " ms" + lost + ": " +
                             name_unconfirmed(unconfirmed, results));
  return 0;
}

// A RESUME or a command is sent only when every member it waits for can confirm it verifiably:
// exit 1, nothing sent, otherwise. 0: go on.
int unverifiable(Session& s, const char* verb, const Common& c, const Targets& t,
                 const char* what) {
  if (!c.wait || (!t.members.empty() && t.no_key.empty())) return 0;
  s.close();
  if (t.members.empty())
    return failure(verb, std::string("no member's confirmation of ") + what +
                             " can be verified: give the fleet's robots' public keys with "
                             "--members-dir D (or RCAN_FLEET_MEMBERS_DIR), or use --no-wait; "
                             "nothing was sent");
  std::string names;
  for (const auto& m : t.no_key) names += (names.empty() ? "" : ", ") + m;
  return failure(verb, std::string("no key in --members-dir for ") + names +
                           ": no confirmation of " + what +
                           " from them could be believed; nothing was sent");
}

int estop_or_resume(const Options& o, bool estop) {
  const char* verb = estop ? "fleet estop" : "fleet resume";
  if (o.positional().size() != 2) return usage_error(verb, "give the fleet id");
  const std::string fleet = o.positional()[1];
  auto c = common(o, true);
  if (!c.ok()) return usage_error(verb, c.error().message);
  if (!mqtt::valid_topic_segment(fleet)) return usage_error(verb, "bad fleet id");
  auto topics = mqtt::fleet_topics(c->prefix, fleet);
  Session s;
  auto t = open_fleet(s, o, *c, fleet, topics);
  if (!t.ok()) return usage_error(verb, t.error().message);
  // An ESTOP goes out even when no confirmation can be verified; a RESUME does not.
  if (!estop) {
    if (int e = unverifiable(s, verb, *c, *t, "a RESUME"); e != 0) return e;
  }
  json::Object payload{{"safety_event", estop ? "ESTOP" : "RESUME"}, {"fleet_id", fleet}};
  payload.set("reason", o.get("reason", estop ? "fleet estop" : "fleet resume"));
  json::Value msg = message("SAFETY", payload, *c);
  // Retained: the fleet's standing state, for members that connect later. Every member answers
  // the same message id on its own reply topic. An ESTOP goes again to the members still
  // silent (Resend).
  Resend resend{[&] { return message("SAFETY", payload, *c); }, 2000, {}};
  return publish_and_confirm(
      s, verb, *c, topics, *t, topics.estop(), msg, 2, true, false,
      json::Object{{"fleet_id", fleet}, {"event", estop ? "ESTOP" : "RESUME"}},
      estop ? &resend : nullptr);
}

int command_main(const Options& o) {
  if (o.positional().size() != 3)
    return usage_error("fleet command", "give the fleet id and the action");
  const std::string fleet = o.positional()[1], action = o.positional()[2];
  auto c = common(o, true);
  if (!c.ok()) return usage_error("fleet command", c.error().message);
  if (!mqtt::valid_topic_segment(fleet)) return usage_error("fleet command", "bad fleet id");
  json::Object payload{{"command", action}, {"fleet_id", fleet}};
  if (o.has("params")) {
    auto p = json::parse(o.get("params"));
    if (!p.ok() || !p->is_object())
      return usage_error("fleet command", "--params must be a JSON object");
    payload.set("params", *p);
  }
  auto topics = mqtt::fleet_topics(c->prefix, fleet);
  Session s;
  auto t = open_fleet(s, o, *c, fleet, topics);
  if (!t.ok()) return usage_error("fleet command", t.error().message);
  if (int e = unverifiable(s, "fleet command", *c, *t, "the command"); e != 0) return e;
  json::Value msg = message("FLEET_COMMAND", std::move(payload), *c);
  return publish_and_confirm(s, "fleet command", *c, topics, *t, topics.cmd(), msg, 1, false,
                             o.has("wait-complete"), json::Object{{"fleet_id", fleet}});
}

// ---- choreography (fleet_choreography.h)

// Sends a SAFETY STOP to every robot a failed run moved and waits for their ACKs; records
// `stopped`, `stops_not_delivered` and `all_stops_acknowledged` in `out`.
void stop_moved(Session& sess, const mqtt::FleetTopics& topics, const std::set<std::string>& moved,
                const std::string& fleet, size_t failed, const Common& c, int qos,
                json::Object* out) {
  std::map<std::string, std::string> stop_ids;
  json::Array undelivered;
  for (const auto& r : moved) {
    std::string id = new_uuid_v4();
    stop_ids[id] = r;
    Status sent = sess.publish(
        topics.member(r).cmd(),
        message("SAFETY",
                json::Object{{"safety_event", "STOP"},
                             {"fleet_id", fleet},
                             {"reason", "choreography step " + std::to_string(failed) + " failed"}},
                c, id),
        qos, false);
    if (!sent.ok()) undelivered.emplace_back(r);
  }
  bool stops_ok = true;
  json::Object stopped = await_replies(sess, stop_ids, false, c.timeout_ms, &stops_ok);
  if (!undelivered.empty()) {
    stops_ok = false;
    out->set("stops_not_delivered", std::move(undelivered));
  }
  out->set("stopped", std::move(stopped));
  out->set("all_stops_acknowledged", stops_ok);
}

int run_main(const Options& o) {
  if (o.positional().size() != 2) return usage_error("fleet run", "give the choreography file");
  auto c = common(o, true);
  if (!c.ok()) return usage_error("fleet run", c.error().message);
  if (!c->wait) return usage_error("fleet run", "a choreography always waits for its steps");
  auto text = read_file(o.positional()[1]);
  if (!text.ok()) return usage_error("fleet run", text.error().message);
  auto doc = json::parse(*text);
  if (!doc.ok())
    return usage_error("fleet run", "the choreography is not JSON: " + doc.error().message);
  std::string fleet, type;
  auto steps = parse_choreography(*doc, &fleet, &type, c->timeout_ms);
  if (!steps.ok()) return usage_error("fleet run", steps.error().message);
  auto topics = mqtt::fleet_topics(c->prefix, fleet);
  std::set<std::string> robots;
  for (const auto& s : *steps) robots.insert(s.robot);
  // Each step waits for its robot's signed ACK and completion: a step started on a completion a
  // topic writer made up would move a robot next to one still moving.
  auto keys = members_dir(o);
  if (!keys.ok()) return usage_error("fleet run", keys.error().message);
  if (!*keys)
    return usage_error("fleet run",
                       "--members-dir D (or RCAN_FLEET_MEMBERS_DIR) is required: the robots' "
                       "public keys, which every step's confirmation must be signed by");
  for (const auto& r : robots)
    if (!(*keys)->knows(r))
      return usage_error("fleet run", "no key in --members-dir for " + r +
                                          ": its confirmations could not be believed");
  Session sess;
  sess.set_timeout(c->timeout_ms);
  sess.vouched_by(fleet, topics.base, keys->get());
  std::vector<std::string> subs;
  for (const auto& r : robots) subs.push_back(topics.member(r).reply());
  if (Status st = sess.open(o, subs, c->qos); !st.ok())
    return usage_error("fleet run", st.error().message);
  const int qos = c->qos != 0 ? c->qos : 1;

  Choreography run(std::move(*steps), type);
  while (!run.failed()) {
    auto make = [&](json::Object payload, const std::string& id) {
      return message("FLEET_COMMAND", std::move(payload), *c, id);
    };
    if (!run.publish_ready(sess, topics, fleet, make, qos) || run.all_done()) break;
    if (auto m = sess.next(run.next_deadline())) run.on_reply(*m, topics);
    run.check_timeouts();
  }
  const std::string& choreography_id = run.id();
  const std::optional<size_t> failed = run.failed();
  const std::string& fail_reason = run.fail_reason();
  const std::vector<Step>& st = run.steps();
  const std::set<std::string>& moved = run.moved();
  json::Array report = run.report();
  json::Object out{{"fleet_id", fleet}, {"choreography_id", choreography_id}, {"type", type}};
  json::Object unverified;
  for (const auto& [robot, d] : sess.dropped())
    unverified.set(robot, json::Object{{"count", d.count}, {"reason", d.reason}});
  if (!unverified.empty()) out.set("unverified_replies", std::move(unverified));
  if (!failed) {
    out.set("ok", true);
    out.set("steps", std::move(report));
    sess.close();
    print(json::Value(std::move(out)));
    return 0;
  }
  // Stop every robot this run moved, then report.
  stop_moved(sess, topics, moved, fleet, *failed, *c, qos, &out);
  sess.close();
  out.set("ok", false);
  out.set("failed_step", static_cast<int64_t>(*failed));
  out.set("failed_robot", st[*failed].robot);
  out.set("reason", fail_reason);
  out.set("steps", std::move(report));
  print(json::Value(std::move(out)));
  return failure("fleet run", "step " + std::to_string(*failed) + " (" + st[*failed].robot +
                                  ") failed: " + fail_reason);
}

int status_main(const Options& o) {
  if (o.positional().size() != 2) return usage_error("fleet status", "give the fleet id");
  auto c = common(o, false);
  if (!c.ok()) return usage_error("fleet status", c.error().message);
  const std::string fleet = o.positional()[1];
  if (!mqtt::valid_topic_segment(fleet)) return usage_error("fleet status", "bad fleet id");
  auto topics = mqtt::fleet_topics(c->prefix, fleet);
  auto keys = members_dir(o);
  if (!keys.ok()) return usage_error("fleet status", keys.error().message);
  Session s;
  s.set_timeout(c->timeout_ms);
  // With --members-dir only the statuses their robots signed are shown; without, what the broker
  // holds, said to be unverified.
  if (*keys) s.vouched_by(fleet, topics.base, keys->get());
  if (Status st = s.open(o, {topics.base + "/robot/+/status"}, c->qos); !st.ok())
    return usage_error("fleet status", st.error().message);
  json::Object members;
  int64_t deadline =
      mono_ms() + std::min<int64_t>(c->timeout_ms, 500);  // retained statuses arrive at once
  while (auto m = s.next(deadline)) {
    std::string member = m->topic.substr(topics.base.size() + 7);
    member = member.substr(0, member.find('/'));
    members.set(member, m->body);
  }
  s.close();
  json::Object out{{"fleet_id", fleet}, {"verified", *keys != nullptr}};
  if (*keys) {
    json::Array missing;
    for (const auto& m : (*keys)->names())
      if (members.find(m) == nullptr) missing.emplace_back(m);
    out.set("missing", std::move(missing));  // members with no status their robot signed
    json::Object unverified;
    for (const auto& [member, d] : s.dropped())
      unverified.set(member, json::Object{{"count", d.count}, {"reason", d.reason}});
    out.set("unverified", std::move(unverified));
  }
  out.set("members", std::move(members));
  print(json::Value(std::move(out)));
  return 0;
}

// D/<member>.secret → member → chain secret (each file must be private, as every secret).
Result<std::map<std::string, std::string>> load_secrets(const Options& o) {
  std::map<std::string, std::string> out;
  if (!o.has("secrets-dir")) return out;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(o.get("secrets-dir"), ec)) {
    std::string name = e.path().filename().string();
    if (name.size() <= 7 || name.substr(name.size() - 7) != ".secret") continue;
    auto s = audit::read_secret_file(e.path().string());
    if (!s.ok()) return s.error();
    out[name.substr(0, name.size() - 7)] = *s;
  }
  if (ec) return Error(ErrorCode::kNotFound, "cannot read --secrets-dir " + o.get("secrets-dir"));
  return out;
}

int audit_verify_main(const Options& o) {
  if (!o.has("db")) return usage_error("fleet audit verify", "--db CONNINFO is required");
  auto secrets = load_secrets(o);
  if (!secrets.ok()) return usage_error("fleet audit verify", secrets.error().message);
  auto db = FleetAuditDb::open(o.get("db"));
  if (!db.ok()) return usage_error("fleet audit verify", db.error().message);
  int64_t n = 0;
  auto problems = (*db)->verify(o.get("fleet"), *secrets, &n);
  if (!problems.ok()) return usage_error("fleet audit verify", problems.error().message);
  json::Array list;
  for (const auto& p : *problems) list.push_back(p.to_json());
  bool ok = problems->empty();
  print(json::Value(json::Object{{"ok", ok},
                                 {"records", n},
                                 {"hmac_checked_members", static_cast<int64_t>(secrets->size())},
                                 {"problems", std::move(list)}}));
  return ok ? 0 : 1;
}

// One robot's audit chain as `fleet audit collect` sees it: the records kept, the last sequence
// number and hash, and every problem found (a gap, a break, a duplicate, a tampered record).
struct CollectedChain {
  uint64_t last_seq = 0;
  std::string last_hash;
  int64_t records = 0;
  json::Array problems;

  // A record the database took: the problems it found in it.
  void stored(const std::vector<AuditProblem>& found, const json::Value& body) {
    for (const auto& p : found) problems.push_back(p.to_json());
    if (found.empty() || found.front().problem == "gap" || found.front().problem == "break")
      ++records;
    const json::Value* sq = body.get("seq");
    if (sq != nullptr && sq->is_int() && sq->as_int() > 0)
      last_seq = std::max<uint64_t>(last_seq, static_cast<uint64_t>(sq->as_int()));
  }

  // A record for the files: checked against the robot's chain secret (when known) and linked to
  // its predecessor; false when it is not kept (tampered, malformed, duplicate or reordered).
  bool take(const json::Value& body, const std::string* secret) {
    if (secret != nullptr && body.is_object()) {
      std::string pre = json::canonical_without(body.as_object(), "hmac");
      if (hmac_sha256_hex(*secret, pre) != json::string_field(body, "hmac")) {
        const json::Value* sq = body.get("seq");
        problems.emplace_back(
            json::Object{{"problem", "hmac_mismatch"},
                         {"seq", sq != nullptr && sq->is_int() ? sq->as_int() : 0}});
        return false;
      }
    }
    const json::Value* seq = body.get("seq");
    std::string prev = json::string_field(body, "prev_hash");
    // The chain links each record to the SHA-256 of its predecessor's canonical form without hmac.
    std::string hash =
        body.is_object() ? sha256_hex(json::canonical_without(body.as_object(), "hmac")) : "";
    if (seq == nullptr || !seq->is_int() || seq->as_int() < 1) {
      problems.emplace_back(json::Object{{"problem", "malformed"}});
      return false;
    }
    uint64_t n = static_cast<uint64_t>(seq->as_int());
    if (records > 0) {
      if (n <= last_seq) {
        problems.emplace_back(
            json::Object{{"problem", "duplicate_or_reordered"}, {"seq", static_cast<int64_t>(n)}});
        return false;
      }
      if (n != last_seq + 1)
        problems.emplace_back(json::Object{{"problem", "gap"},
                                           {"after_seq", static_cast<int64_t>(last_seq)},
                                           {"seq", static_cast<int64_t>(n)}});
      else if (!last_hash.empty() && prev != last_hash)
        problems.emplace_back(json::Object{{"problem", "break"}, {"seq", static_cast<int64_t>(n)}});
    }
    last_seq = n;
    last_hash = hash;
    ++records;
    return true;
  }
};

int audit_collect_main(const Options& o) {
  if (o.positional().size() != 3) return usage_error("fleet audit collect", "give the fleet id");
  auto c = common(o, false);
  if (!c.ok()) return usage_error("fleet audit collect", c.error().message);
  const std::string fleet = o.positional()[2];
  if (!mqtt::valid_topic_segment(fleet) || o.has("out") == o.has("db"))
    return usage_error("fleet audit collect",
                       "give the fleet id and one of --out DIR or --db CONNINFO");
  auto secrets = load_secrets(o);
  if (!secrets.ok()) return usage_error("fleet audit collect", secrets.error().message);
  std::unique_ptr<FleetAuditDb> db;
  if (o.has("db")) {
    auto opened = FleetAuditDb::open(o.get("db"));
    if (!opened.ok()) return usage_error("fleet audit collect", opened.error().message);
    db = std::move(opened).value();
  }
  int64_t duration = 5000;
  if (o.has("duration-ms")) duration = std::strtoll(o.get("duration-ms").c_str(), nullptr, 10);
  if (duration < 1 || duration > 86'400'000)
    return usage_error("fleet audit collect", "--duration-ms must be 1..86400000");
  std::error_code ec;
  if (o.has("out")) std::filesystem::create_directories(o.get("out"), ec);
  if (ec) return usage_error("fleet audit collect", "cannot create " + o.get("out"));
  auto topics = mqtt::fleet_topics(c->prefix, fleet);
  Session s;
  s.set_timeout(c->timeout_ms);
  if (Status st = s.open(o, {topics.base + "/robot/+/audit"}, c->qos); !st.ok())
    return usage_error("fleet audit collect", st.error().message);
  std::map<std::string, CollectedChain> chains;
  int64_t deadline = mono_ms() + duration;
  while (auto m = s.next(deadline)) {
    std::string member = m->topic.substr(topics.base.size() + 7);
    member = member.substr(0, member.find('/'));
    if (!mqtt::valid_topic_segment(member)) continue;
    CollectedChain& ch = chains[member];
    auto sec = secrets->find(member);
    const std::string* secret = sec == secrets->end() ? nullptr : &sec->second;
    if (db) {
      auto found = db->ingest(fleet, member, m->body, secret);
      if (!found.ok()) {
        s.close();
        return usage_error("fleet audit collect", found.error().message);
      }
      ch.stored(*found, m->body);
      continue;
    }
    if (!ch.take(m->body, secret)) continue;
    std::ofstream f(o.get("out") + "/" + member + ".jsonl", std::ios::app);
    f << json::dump(m->body) << "\n";
  }
  s.close();
  json::Object out;
  bool ok = true;
  for (auto& [member, ch] : chains) {
    if (!ch.problems.empty()) ok = false;
    out.set(member, json::Object{{"records", ch.records},
                                 {"last_seq", static_cast<int64_t>(ch.last_seq)},
                                 {"problems", std::move(ch.problems)}});
  }
  print(json::Value(json::Object{{"fleet_id", fleet}, {"ok", ok}, {"robots", std::move(out)}}));
  return ok ? 0 : 1;
}

int fleet_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kHelp, stdout);
    return args.empty() ? 2 : 0;
  }
  Options o(args, kFlags, kValued);
  if (!o.ok()) return usage_error("fleet", o.error());
  const std::string& sub = args[0];
  if (sub == "estop") return estop_or_resume(o, true);
  if (sub == "resume") return estop_or_resume(o, false);
  if (sub == "command") return command_main(o);
  if (sub == "run") return run_main(o);
  if (sub == "status") return status_main(o);
  if (sub == "audit" && o.positional().size() >= 2 && o.positional()[1] == "collect")
    return audit_collect_main(o);
  if (sub == "audit" && o.positional().size() == 2 && o.positional()[1] == "verify")
    return audit_verify_main(o);
  return usage_error("fleet", "unknown subcommand " + sub +
                                  " (estop | resume | command | run | status | audit collect)");
}

const Registration kReg{
    "fleet", "drive a fleet over MQTT: estop, command, run a choreography, audit", &fleet_main};

}  // namespace
}  // namespace rcan::cli

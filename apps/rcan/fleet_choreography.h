// A choreography for `rcan fleet run` (docs/FLEET.md §Choreography): its file, and one run of
// it over a fleet session.
#pragma once

#include <algorithm>
#include <functional>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "fleet_session.h"
#include "rcan/json.h"
#include "rcan/mqtt_topics.h"
#include "rcan/result.h"

namespace rcan::cli {

struct Step {
  size_t index = 0;
  std::string robot;
  std::string action;
  json::Value params;
  std::vector<std::string> wait_for;
  int64_t timeout_ms = 0;
  enum class State { kPending, kSent, kAcked, kDone, kFailed } state = State::kPending;
  std::string message_id;
  int64_t sent_mono = 0;
  json::Value reply;
};

// The choreography file `doc` (COORDINATED_MOVE): its steps, `fleet` and `type` (sequential or
// parallel); a step without timeout_ms gets `default_timeout`. Errors name what is wrong.
Result<std::vector<Step>> parse_choreography(const json::Value& doc, std::string* fleet,
                                             std::string* type, int64_t default_timeout);

// One run of a choreography: which steps may start, what their robots answered, which have run
// out of time. A step waits for its robot's signed ACK and completion (the session drops what
// the robot did not sign); a robot runs its own steps in order, a sequential choreography all
// of them, and a step with wait_for after those robots' earlier steps.
class Choreography {
 public:
  Choreography(std::vector<Step> steps, std::string type)
      : steps_(std::move(steps)), type_(std::move(type)), id_(new_uuid_v4()) {}

  // The signed FLEET_COMMAND envelope of `payload` with message id `id`.
  using MakeMessage = std::function<json::Value(json::Object payload, const std::string& id)>;

  // Publishes every step that may start now; false when a publish failed (the run has failed).
  bool publish_ready(fleet::Session& sess, const mqtt::FleetTopics& topics,
                     const std::string& fleet, const MakeMessage& make, int qos) {
    all_done_ = true;
    for (auto& s : steps_) {
      if (s.state != Step::State::kDone) all_done_ = false;
      if (s.state != Step::State::kPending || !ready(s)) continue;
      json::Object payload{{"command", s.action},
                           {"params", s.params},
                           {"fleet_id", fleet},
                           {"choreography_id", id_},
                           {"step", static_cast<int64_t>(s.index)}};
      s.message_id = new_uuid_v4();
      Status ps = sess.publish(topics.member(s.robot).cmd(), make(std::move(payload), s.message_id),
                               qos, false);
      if (!ps.ok()) {  // the step was never sent: it stays pending in the report
        failed_ = s.index;
        fail_reason_ = "publish failed: " + ps.error().message;
        return false;
      }
      s.state = Step::State::kSent;
      s.sent_mono = fleet::mono_ms();
      moved_.insert(s.robot);
    }
    return true;
  }

  // The answer `m` of a step's robot: ACK, COMPLETED, or anything else (the run fails).
  void on_reply(const fleet::Session::Inbound& m, const mqtt::FleetTopics& topics) {
    const std::string reply_to = json::string_field(m.body, "reply_to");
    for (auto& s : steps_) {
      if (s.message_id != reply_to || m.topic != topics.member(s.robot).reply()) continue;
      const std::string t = json::string_field(m.body, "type");
      const json::Value* p = m.body.get("payload");
      if (t == "ACK") {
        if (s.state == Step::State::kSent) s.state = Step::State::kAcked;
      } else if (t == "EVENT" && p != nullptr && json::string_field(*p, "event") == "COMPLETED") {
        s.state = Step::State::kDone;
      } else {
        s.reply = m.body;
        fail(s,
             t == "ERROR" && p != nullptr
                 ? "refused: " + json::string_field(*p, "error_code") + " " +
                       json::string_field(*p, "error")
                 : "aborted: " + (p != nullptr ? json::string_field(*p, "reason") : std::string()));
      }
    }
  }

  // Fails the first step under way whose time is up.
  void check_timeouts() {
    const int64_t now = fleet::mono_ms();
    for (auto& s : steps_) {
      if (failed_) return;
      if (under_way(s) && now >= s.sent_mono + s.timeout_ms)
        fail(s,
             std::string(s.state == Step::State::kAcked ? "timeout waiting for completion"
                                                        : "timeout waiting for acknowledgement") +
                 " after " + std::to_string(s.timeout_ms) + " ms");
    }
  }

  // The earliest step deadline, at most a second away.
  int64_t next_deadline() const {
    int64_t deadline = fleet::mono_ms() + 1000;
    for (const auto& s : steps_)
      if (under_way(s)) deadline = std::min(deadline, s.sent_mono + s.timeout_ms);
    return deadline;
  }

  json::Array report() const {
    json::Array out;
    for (const auto& s : steps_) {
      const char* names[] = {"pending", "sent", "acknowledged", "completed", "failed"};
      json::Object r{{"step", static_cast<int64_t>(s.index)},
                     {"robot", s.robot},
                     {"action", s.action},
                     {"state", names[static_cast<int>(s.state)]}};
      if (!s.reply.is_null()) r.set("reply", s.reply);
      out.emplace_back(std::move(r));
    }
    return out;
  }

  bool all_done() const { return all_done_; }
  std::optional<size_t> failed() const { return failed_; }
  const std::string& fail_reason() const { return fail_reason_; }
  const std::string& id() const { return id_; }
  const std::vector<Step>& steps() const { return steps_; }
  const std::set<std::string>& moved() const { return moved_; }

 private:
  static bool under_way(const Step& s) {
    return s.state == Step::State::kSent || s.state == Step::State::kAcked;
  }
  // Whether `robot`'s steps before `before` are all done.
  bool robot_done(const std::string& robot, size_t before) const {
    for (size_t i = 0; i < before; ++i)
      if (steps_[i].robot == robot && steps_[i].state != Step::State::kDone) return false;
    return true;
  }
  bool ready(const Step& s) const {
    if (type_ == "sequential")
      for (size_t i = 0; i < s.index; ++i)
        if (steps_[i].state != Step::State::kDone) return false;
    for (const auto& w : s.wait_for)
      if (!robot_done(w, s.index)) return false;
    return robot_done(s.robot, s.index);
  }
  void fail(Step& s, std::string why) {
    s.state = Step::State::kFailed;
    failed_ = s.index;
    fail_reason_ = std::move(why);
  }

  std::vector<Step> steps_;
  std::string type_, id_;
  std::set<std::string> moved_;
  std::optional<size_t> failed_;
  std::string fail_reason_;
  bool all_done_ = false;
};

}  // namespace rcan::cli

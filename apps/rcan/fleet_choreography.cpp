#include "fleet_choreography.h"

#include "rcan/errors.h"

namespace rcan::cli {

Result<std::vector<Step>> parse_choreography(const json::Value& doc, std::string* fleet,
                                             std::string* type, int64_t default_timeout) {
  auto bad = [](std::string m) { return Error(ErrorCode::kSchemaValidationFailed, std::move(m)); };
  if (!doc.is_object()) return bad("the choreography must be a JSON object");
  std::string cmd = json::string_field(doc, "command");
  if (!cmd.empty() && cmd != "COORDINATED_MOVE") return bad("command must be COORDINATED_MOVE");
  *fleet = json::string_field(doc, "fleet_id");
  if (!mqtt::valid_topic_segment(*fleet)) return bad("fleet_id is missing or not a valid id");
  std::set<std::string> targets;
  if (const json::Value* t = doc.get("targets"); t != nullptr) {
    if (!t->is_array()) return bad("targets must be an array of robot ids");
    for (const auto& r : t->as_array()) {
      if (!r.is_string() || !mqtt::valid_topic_segment(r.as_string()))
        return bad("targets must be robot ids");
      targets.insert(r.as_string());
    }
  }
  const json::Value* ch = doc.get("choreography");
  if (ch == nullptr || !ch->is_object()) return bad("choreography is required");
  *type = json::string_field(*ch, "type");
  if (*type != "sequential" && *type != "parallel")
    return bad("choreography.type must be sequential or parallel");
  const json::Value* steps = ch->get("steps");
  if (steps == nullptr || !steps->is_array() || steps->as_array().empty() ||
      steps->as_array().size() > 1000)
    return bad("choreography.steps must be a non-empty array (at most 1000)");
  std::vector<Step> out;
  std::set<std::string> seen;
  for (const auto& sv : steps->as_array()) {
    Step s;
    s.index = out.size();
    std::string where = "step " + std::to_string(s.index);
    if (!sv.is_object()) return bad(where + " must be an object");
    s.robot = json::string_field(sv, "robot");
    s.action = json::string_field(sv, "action");
    if (!mqtt::valid_topic_segment(s.robot))
      return bad(where + ": robot is missing or not a valid id");
    if (!targets.empty() && targets.count(s.robot) == 0)
      return bad(where + ": robot " + s.robot + " is not in targets");
    if (s.action.empty() || s.action.size() > 128) return bad(where + ": action is required");
    if (const json::Value* p = sv.get("params"); p != nullptr) {
      if (!p->is_object()) return bad(where + ": params must be an object");
      s.params = *p;
    } else {
      s.params = json::Object{};
    }
    if (const json::Value* w = sv.get("wait_for"); w != nullptr) {
      std::vector<std::string> names;
      if (w->is_string())
        names.push_back(w->as_string());
      else if (w->is_array())
        for (const auto& n : w->as_array())
          names.push_back(n.is_string() ? n.as_string() : std::string());
      else
        return bad(where + ": wait_for must be a robot id or a list of them");
      for (const auto& n : names)
        if (seen.count(n) == 0)
          return bad(where + ": wait_for names " + n + ", which has no earlier step");
      s.wait_for = std::move(names);
    }
    s.timeout_ms = default_timeout;
    if (const json::Value* t = sv.get("timeout_ms"); t != nullptr) {
      if (!t->is_int() || t->as_int() < 1 || t->as_int() > 3'600'000)
        return bad(where + ": timeout_ms must be 1..3600000");
      s.timeout_ms = t->as_int();
    }
    seen.insert(s.robot);
    out.push_back(std::move(s));
  }
  return out;
}

}  // namespace rcan::cli

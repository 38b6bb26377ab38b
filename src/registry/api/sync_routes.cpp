// GET /api/v1/sync (docs/REGISTRY.md "Federation sync"): the robots changed here since a time,
// oldest first, in the reference's rcan-sync/1.0 answer. The records are the public ones
// GET /api/v1/robots serves; a deleted robot is a tombstone (its RRN, deleted, status and the
// time of the deletion), never its content: peers pull without credentials, and a deletion
// takes the robot's description, metadata, endpoints and keys out of every answer.
#include <charconv>

#include "registry/api/impl.h"

namespace rcan::registry::api {
namespace {

bool digits(std::string_view s) {
  if (s.empty()) return false;
  for (char c : s)
    if (c < '0' || c > '9') return false;
  return true;
}

}  // namespace

std::optional<std::string> normalize_iso(std::string_view s) {
  if (s.size() < 19 || !digits(s.substr(0, 4)) || s[4] != '-' || !digits(s.substr(5, 2)) ||
      s[7] != '-' || !digits(s.substr(8, 2)) || s[10] != 'T' || !digits(s.substr(11, 2)) ||
      s[13] != ':' || !digits(s.substr(14, 2)) || s[16] != ':' || !digits(s.substr(17, 2)))
    return std::nullopt;
  std::string out(s.substr(0, 19));
  std::string_view rest = s.substr(19);
  if (!rest.empty() && rest.back() == 'Z') rest.remove_suffix(1);
  std::string frac = "000";
  if (!rest.empty()) {
    if (rest[0] != '.' || !digits(rest.substr(1)) || rest.size() > 10) return std::nullopt;
    frac = std::string(rest.substr(1)) + "000";
    frac.resize(3);
  }
  return out + "." + frac + "Z";
}

HttpResponse RegistryApi::Impl::sync(const HttpRequest& req) {
  std::string raw(req.query_value("since"));
  auto since = normalize_iso(raw.empty() ? std::string_view("1970-01-01T00:00:00Z") : raw);
  if (!since) return ref_error(400, "Invalid `since` timestamp; expected ISO 8601 format");
  int64_t limit = 100;
  if (req.has_query("limit")) {
    std::string_view l = req.query_value("limit");
    auto [end, ec] = std::from_chars(l.data(), l.data() + l.size(), limit);
    if (ec != std::errc() || end != l.data() + l.size()) limit = 100;
  }
  limit = std::min<int64_t>(1000, std::max<int64_t>(1, limit));
  std::string until = now();
  auto rows = store.robots_changed_since(*since, static_cast<int>(limit + 1));
  if (!rows.ok()) return store_error(rows.error());
  bool has_more = static_cast<int64_t>(rows->size()) > limit;
  if (has_more) rows->resize(static_cast<size_t>(limit));
  json::Array records;
  for (const Robot& r : *rows) {
    if (r.deleted) {
      records.emplace_back(tombstone_json(r));
      continue;
    }
    json::Object j = robot_json(r);
    j.set("deleted", false);
    records.emplace_back(std::move(j));
  }
  std::string next = rows->empty() ? until : rows->back().updated_at;
  int64_t count = static_cast<int64_t>(records.size());
  return json_response(200, json::Object{{"protocol", "rcan-sync/1.0"},
                                         {"from_node", o.public_url},
                                         {"since", *since},
                                         {"until", until},
                                         {"count", count},
                                         {"has_more", has_more},
                                         {"next_since", next},
                                         {"records", std::move(records)}});
}

}  // namespace rcan::registry::api

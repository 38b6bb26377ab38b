// Helpers shared by the two storage backends (store.cpp); not part of the contract.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "registry/store.h"

namespace rcan::registry::detail {

// A LIKE pattern matching `q` as a literal substring, lower-cased, with '\' as the escape
// character (… LIKE ? ESCAPE '\').
std::string like_contains(std::string_view q);
// rcan://<host>/<manufacturer>/<model>/<version>/<device_id>
std::string robot_uri(const NewRobot& r);
// An Error with code kInternal and `what` + ": " + `detail`.
Error db_error(std::string_view what, std::string_view detail);
// Error::reason of a write that met a unique constraint (an API key or challenge id that
// exists), the same on both backends.
inline constexpr const char* kUniqueViolation = "unique_violation";

// The WHERE clause (without "WHERE") for list_robots: `live` (the backend's "not deleted"),
// then the query's filters with the backend's placeholders produced by `ph(i)` for the i-th
// (1-based) bound value; `values` receives the values in order.
template <typename Placeholder, typename Values>
std::string robot_filter(const RobotQuery& q, const char* live, Placeholder ph, Values& values) {
  std::string where = live;
  if (!q.q.empty()) {
    values.push_back(like_contains(q.q));
    std::string p = ph(values.size());
    where += " AND (lower(manufacturer) LIKE " + p + " ESCAPE '\\' OR lower(model) LIKE " + p +
             " ESCAPE '\\' OR lower(rrn) LIKE " + p + " ESCAPE '\\')";
  }
  auto eq = [&](const char* column, const std::string& v) {
    if (v.empty()) return;
    values.push_back(v);
    where += std::string(" AND ") + column + " = " + ph(values.size());
  };
  eq("manufacturer", q.manufacturer);
  eq("model", q.model);
  eq("verification_tier", q.tier);
  return where;
}

}  // namespace rcan::registry::detail

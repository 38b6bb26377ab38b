// Router: method + path pattern → handler, the one route matcher of the node and the registry.
// It only finds the route; what a found route, a 404 or a 405 answers is its user's (each
// side keeps its own error bodies).
//
//   Router<Handler> r;
//   r.add("GET", "/rcan/v1/leases", h1);
//   r.add("DELETE", "/rcan/v1/leases/{id}", h2, "/rcan/v1/leases");  // label: metrics, audit
//   auto m = r.find(req.method, req.path);
//   if (m.found()) …m.route->handler, m.params…
//   else if (m.method_not_allowed()) …m.allow…   // else 404
//
// Patterns: literal segments, `{name}` for one non-empty segment (at most 128 bytes), and a
// final `*` for one or more remaining segments (taken whole, slashes included). A path's route
// is the first pattern, in the order added, that matches it; the route's rows (every row with
// that pattern) then choose by method, the method "*" taking any. A path no pattern matches is
// not found; a route with no row for the method is a 405, `allow` listing its methods.
#pragma once

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace rcan::transport {

// Does `pattern` match `path`? Fills `params` (when given) with the `{…}` and `*` segments, in
// order, when it does.
bool match_path(std::string_view pattern, std::string_view path, std::vector<std::string>* params);

template <class Handler>
class Router {
 public:
  struct Route {
    std::string method;   // "*": any method
    std::string pattern;  // as above
    std::string label;    // the name answers are counted and audited under
    Handler handler;
  };

  struct Match {
    const Route* route = nullptr;  // the row for the method; null on 404 and 405
    const Route* path = nullptr;   // the first row of the path's route; null on 404
    std::vector<std::string> params;
    std::string allow;  // on 405: the route's methods, ", "-separated, in the order added

    bool found() const { return route != nullptr; }
    bool method_not_allowed() const { return route == nullptr && path != nullptr; }
    // The label of the path's route whatever the method; `none` when no route matches.
    const std::string& label_or(const std::string& none) const { return path ? path->label : none; }
  };

  // `label` empty: the pattern.
  void add(std::string method, std::string pattern, Handler handler, std::string label = {}) {
    if (label.empty()) label = pattern;
    routes_.push_back(
        Route{std::move(method), std::move(pattern), std::move(label), std::move(handler)});
  }

  Match find(std::string_view method, std::string_view path) const {
    Match m;
    for (const Route& r : routes_)
      if (match_path(r.pattern, path, &m.params)) {
        m.path = &r;
        break;
      }
    if (!m.path) {
      m.params.clear();
      return m;
    }
    for (const Route& r : routes_) {
      if (r.pattern != m.path->pattern) continue;
      if (r.method == method || r.method == "*") {
        m.route = &r;
        m.allow.clear();
        return m;
      }
      if (!listed(m.allow, r.method)) m.allow += (m.allow.empty() ? "" : ", ") + r.method;
    }
    return m;
  }

  const std::vector<Route>& routes() const { return routes_; }

 private:
  static bool listed(std::string_view allow, std::string_view method) {
    for (size_t at = 0; at < allow.size();) {
      size_t end = allow.find(", ", at);
      if (allow.substr(at, end == std::string_view::npos ? end : end - at) == method) return true;
      if (end == std::string_view::npos) break;
      at = end + 2;
    }
    return false;
  }

  std::vector<Route> routes_;
};

}  // namespace rcan::transport

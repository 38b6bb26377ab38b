#include "transport/router.h"

namespace rcan::transport {
namespace {

// The next '/'-separated segment of `s` from `pos` (which points after a '/').
std::string_view segment(std::string_view s, size_t& pos) {
  size_t end = s.find('/', pos);
  std::string_view seg = s.substr(pos, end == std::string_view::npos ? end : end - pos);
  pos = end == std::string_view::npos ? s.size() + 1 : end + 1;
  return seg;
}

constexpr size_t kMaxParam = 128;

}  // namespace

bool match_path(std::string_view pattern, std::string_view path, std::vector<std::string>* params) {
  if (pattern.empty() || path.empty() || pattern[0] != '/' || path[0] != '/') return false;
  if (params) params->clear();
  size_t pp = 1, sp = 1;
  while (pp <= pattern.size()) {
    std::string_view want = segment(pattern, pp);
    if (want == "*" && pp > pattern.size()) {  // the rest: one or more non-empty segments
      if (sp > path.size()) return false;
      std::string_view rest = path.substr(sp);
      if (rest.empty()) return false;
      if (params) params->emplace_back(rest);
      return true;
    }
    if (sp > path.size()) return false;
    std::string_view got = segment(path, sp);
    if (want.size() > 2 && want.front() == '{' && want.back() == '}') {
      if (got.empty() || got.size() > kMaxParam) return false;
      if (params) params->emplace_back(got);
    } else if (want != got) {
      return false;
    }
  }
  return sp > path.size();
}

}  // namespace rcan::transport

// open_store and the helpers both backends share (store_internal.h).
#include "registry/store.h"

#include "base/strings.h"
#include "registry/store_internal.h"

namespace rcan::registry {
namespace detail {

std::string like_contains(std::string_view q) {
  std::string out = "%";
  for (char c : ascii_lower(q)) {
    if (c == '%' || c == '_' || c == '\\') out += '\\';
    out += c;
  }
  return out + "%";
}

std::string robot_uri(const NewRobot& r) {
  std::string base = r.rcan_uri_base;
  while (!base.empty() && base.back() == '/') base.pop_back();
  return base + "/" + r.manufacturer + "/" + r.model + "/" + r.version + "/" + r.device_id;
}

Error db_error(std::string_view what, std::string_view detail) {
  std::string d(detail);
  while (!d.empty() && (d.back() == '\n' || d.back() == ' ')) d.pop_back();
  return Error(ErrorCode::kInternal, std::string(what) + ": " + d);
}

}  // namespace detail

Robot robot_of(const NewRobot& r) {
  Robot robot;
  robot.manufacturer = r.manufacturer;
  robot.model = r.model;
  robot.version = r.version;
  robot.device_id = r.device_id;
  robot.rcan_uri = detail::robot_uri(r);
  robot.description = r.description;
  robot.contact_email = r.contact_email;
  robot.source = r.source;
  robot.metadata_json = r.metadata_json;
  robot.ed25519_pub = r.ed25519_pub;
  robot.mldsa65_pub = r.mldsa65_pub;
  robot.endpoints_json = r.endpoints_json;
  robot.owner_key_id = r.owner_key_id;
  robot.registered_at = robot.updated_at = r.now;
  return robot;
}

Result<std::unique_ptr<Store>> open_store(const std::string& spec, const StoreOptions& o) {
  if (spec.starts_with("postgresql://") || spec.starts_with("postgres://"))
    return open_postgres(spec, o);
  return open_sqlite(spec, o);
}

}  // namespace rcan::registry

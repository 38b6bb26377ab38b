#include "node/admission/registry_trust_link.h"

#include "runtime/http_client.h"
#include "runtime/log.h"

namespace rcan::node {

RegistryTrustLink::RegistryTrustLink(RegistryTrustOptions opts, Clock& clock, TrustRecorder record,
                                     base::Env* env)
    : opts_(std::move(opts)),
      dir_(opts_.data_dir + "/registry"),
      clock_(clock),
      record_(std::move(record)),
      env_(env ? env : base::Env::posix()) {}

std::string RegistryTrustLink::url(const std::string& path) const {
  std::string base = opts_.registry_url;
  while (!base.empty() && base.back() == '/') base.pop_back();
  return base + path;
}

Result<std::string> RegistryTrustLink::get(const std::string& path, int timeout_ms) const {
  auto u = parse_web_url(url(path));
  if (!u.ok()) return u.error();
  HttpRequestOptions o;
  o.ca_file = opts_.ca_file;
  auto a = http_request("GET", *u, "", timeout_ms, o);
  if (!a.ok()) return a.error();
  if (a->status != 200)
    return Error(ErrorCode::kInternal, "the registry answered " + std::to_string(a->status));
  return std::move(a->body);
}

Status RegistryTrustLink::make_dir() const {
  // The data directory is rcand's (made at start); the link's own is made here.
  for (const std::string& d : {opts_.data_dir, dir_}) {
    base::IoStatus s = env_->create_dir(d);
    if (!s.ok())
      return Error(ErrorCode::kInternal, "cannot create " + d + ": " + s.error().message);
  }
  return Status::Ok();
}

void RegistryTrustLink::record(TrustRecord r) const {
  if (record_) record_(std::move(r));
}

void RegistryTrustLink::failed(const std::string& what, const std::string& error) {
  {
    MutexLock l(mu_);
    (what.rfind("registry keys", 0) == 0 ? keys_error_ : other_error_) = what + ": " + error;
  }
  log(LogLevel::kWarn, "registry_trust_failed", json::Object{{"what", what}, {"error", error}});
}

void RegistryTrustLink::keys_ok() {
  MutexLock l(mu_);
  keys_error_.clear();
}

void RegistryTrustLink::feed_ok() {
  MutexLock l(mu_);
  if (other_error_.rfind("registry revocations:", 0) == 0) other_error_.clear();
}

json::Value RegistryTrustLink::last_error() const {
  MutexLock l(mu_);
  return !keys_error_.empty()    ? json::Value(keys_error_)
         : !other_error_.empty() ? json::Value(other_error_)
                                 : json::Value();
}

}  // namespace rcan::node

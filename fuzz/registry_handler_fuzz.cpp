// libFuzzer: HTTP requests through rcan-registry's real router (RegistryApi::serve) on a SQLite
// store — every route's parsing: registrations, updates, keys, nodes, webhooks, the token
// authority's clients, grants, revocations and device approvals, the OAuth forms, resolve and
// sync queries. The input is one request:
//
//   METHOD SP TARGET LF [header-name: value LF]* LF body
//
// A header value or the body may say ADMIN: it is replaced by an admin API key of the store
// (so the authenticated routes are reached). Rate limits are off (the fuzzer is one address).
//
// Invariants: nothing crashes; every status is 1xx..5xx and never 500; a JSON answer parses.
// RCAN_FUZZ_VERBOSE=1 prints every exchange.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

#include "rcan/crypto/ed25519.h"
#include "rcan/json.h"
#include "registry/api/registry_api.h"
#include "registry/store.h"
#include "transport/http_parse.h"

namespace {

struct Harness {
  std::unique_ptr<rcan::registry::Store> store;
  std::unique_ptr<rcan::registry::api::RegistryApi> api;
  std::string admin;
};

Harness& harness() {
  static Harness* h = [] {
    auto* out = new Harness;
    const std::string dir = (std::filesystem::temp_directory_path() /
                             ("rcan-registry-fuzz-" + std::to_string(::getpid())))
                                .string();
    std::filesystem::create_directories(dir);
    static std::string remove_at_exit = dir;
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(remove_at_exit, ec);
    });
    auto s = rcan::registry::open_sqlite(dir + "/registry.db");
    if (!s.ok()) {
      std::fprintf(stderr, "registry_handler_fuzz: %s\n", s.error().message.c_str());
      std::abort();
    }
    out->store = std::move(s).value();
    rcan::registry::api::ApiOptions o;
    o.node_seed = rcan::ed25519::random_seed();
    o.write_per_key = {0, 0};
    o.write_per_address = {0, 0};
    o.read_per_address = {0, 0};
    o.allow_http_node_urls = false;
    o.webhooks.queue_capacity = 0;  // every webhook event dropped: the fuzzer never dials out
    out->api = std::make_unique<rcan::registry::api::RegistryApi>(*out->store, nullptr, o);
    auto key = out->api->create_key("admin", "", "fuzz", "fuzz");
    if (!key.ok()) std::abort();
    out->admin = *key;
    return out;
  }();
  return *h;
}

std::string expand(std::string s, const std::string& admin) {
  for (size_t at = s.find("ADMIN"); at != std::string::npos; at = s.find("ADMIN", at)) {
    s.replace(at, 5, admin);
    at += admin.size();
  }
  return s;
}

[[noreturn]] void fail(const char* what, const rcan::transport::HttpResponse& r) {
  std::fprintf(stderr, "registry_handler_fuzz: %s (status %d): %.2000s\n", what, r.status,
               r.body.c_str());
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Harness& h = harness();
  std::string_view in(reinterpret_cast<const char*>(data), size);
  const size_t line_end = in.find('\n');
  if (line_end == std::string_view::npos) return 0;
  const std::string_view line = in.substr(0, line_end);
  const size_t sp = line.find(' ');
  if (sp == std::string_view::npos || sp == 0 || sp > 10) return 0;
  rcan::transport::HttpRequest req;
  req.method = std::string(line.substr(0, sp));
  req.target = std::string(line.substr(sp + 1));
  if (req.target.empty() || req.target[0] != '/') return 0;
  // The transport's own split (percent-decoding, query pairs): a target it refuses never
  // reaches the router.
  if (rcan::transport::detail::split_target(req.target, req.path, req.query)) return 0;
  size_t at = line_end + 1;
  while (at < in.size()) {
    const size_t end = in.find('\n', at);
    const std::string_view header = in.substr(at, end == std::string_view::npos ? end : end - at);
    at = end == std::string_view::npos ? in.size() : end + 1;
    if (header.empty()) break;
    const size_t colon = header.find(':');
    if (colon == std::string_view::npos || colon == 0) continue;
    std::string value(header.substr(colon + 1));
    while (!value.empty() && value.front() == ' ') value.erase(0, 1);
    req.headers.emplace_back(rcan::ascii_lower(header.substr(0, colon)), expand(value, h.admin));
  }
  req.body = expand(std::string(in.substr(std::min(at, in.size()))), h.admin);
  req.remote_addr = "127.0.0.1:40000";
  const rcan::transport::HttpResponse r = h.api->serve(req);
  if (std::getenv("RCAN_FUZZ_VERBOSE") != nullptr)
    std::fprintf(stderr, "%s %s -> %d %.300s\n", req.method.c_str(), req.target.c_str(), r.status,
                 r.body.c_str());
  if (r.status < 100 || r.status > 599) fail("status out of range", r);
  if (r.status == 500) fail("500 on input", r);
  if (r.content_type.rfind("application/json", 0) == 0 &&
      !rcan::json::parse(r.body, {.max_depth = 256, .max_bytes = 1u << 30}).ok())
    fail("JSON answer does not parse", r);
  return 0;
}

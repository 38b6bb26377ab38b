// `security`: keys, the audit log, JWT issuers, trusted robot and signer keys, the injection
// screen, the profile commitment block, and the refusal of the v1.5 key rotation and
// revocation blocks (docs/CONFIG.md §security). The key, audit and secret paths default to files
// under the data dir.
#include <algorithm>
#include <filesystem>
#include <regex>

#include "config/blocks/blocks.h"

namespace rcan::config::internal {
namespace {

using S = Rows<SecurityConfig>;

// A path that defaults to one under data_dir (derive_paths): resolved, never empty, and
// remembered as set so that --data-dir does not move it.
template <typename T>
Row<T> explicit_path(std::string key, std::string T::*member,
                     bool NodeConfig::ExplicitPaths::*set) {
  return Rows<T>::read(std::move(key), Str(), [member, set](const At& a, T& out, Ctx& x) {
    if (!a) return;
    out.*member = resolve_path(a.str(), x.opts.base_dir);
    x.c.explicit_paths.*set = true;
    if (a.str().empty()) fail(a.path, "must not be empty", "invalid_value");
  });
}

Table<AuditConfig> audit_rows() {
  using A = Rows<AuditConfig>;
  using P = NodeConfig::ExplicitPaths;
  return {
      explicit_path("dir", &AuditConfig::dir, &P::audit_dir),
      explicit_path("chain_secret_file", &AuditConfig::chain_secret_file, &P::chain_secret_file),
      A::read("sync", Enum({"per_group", "interval"}),
              [](const At& a, AuditConfig& au, Ctx&) {
                if (a)
                  au.sync_policy = a.str() == "interval" ? audit::SyncPolicy::kInterval
                                                         : audit::SyncPolicy::kPerGroup;
              }),
      A::field("sync_interval_ms", Int(1, 10'000), &AuditConfig::sync_interval_ms),
      A::field("max_segment_bytes", Int(64 * 1024, 4.0 * 1024 * 1024 * 1024),
               &AuditConfig::max_segment_bytes),
      A::block("retention",
               Table<AuditConfig>{
                   A::field("max_bytes", Int(0, 9.0e15), &AuditConfig::retention_max_bytes),
                   A::field("max_age_days", Int(0, 36'500), &AuditConfig::retention_max_age_days),
               }),
  };
}

Table<JwtConfig> jwt_rows() {
  using I = Rows<jwt::TrustStore::IssuerConfig>;
  static const Table<jwt::TrustStore::IssuerConfig> issuer = {
      I::read("issuer", Str(512),
              [](const At& a, jwt::TrustStore::IssuerConfig& ic, Ctx&) {
                ic.issuer = a.str();
                if (ic.issuer.empty()) fail(a.path, "must not be empty", "invalid_value");
              })
          .required(),
      I::read("key_file", Str(),
              [](const At& a, jwt::TrustStore::IssuerConfig& ic, Ctx& x) {
                ic.key_file = resolve_path(a.str(), x.opts.base_dir);
                if (ic.key_file.empty()) fail(a.path, "must not be empty", "invalid_value");
              })
          .required(),
      I::field("kind", Enum({"auto", "hs256_secret"}), &jwt::TrustStore::IssuerConfig::kind),
      I::field("kid", Str(128), &jwt::TrustStore::IssuerConfig::kid),
  };
  using J = Rows<JwtConfig>;
  return {
      J::read("issuers", Arr(object_of(issuer), 64),
              [](const At& a, JwtConfig& j, Ctx& x) {
                for (size_t i = 0; i < a.size(); ++i) j.issuers.push_back(element(issuer, a[i], x));
              }),
      J::field("leeway_s", Int(0, 3600), &JwtConfig::leeway_s),
  };
}

// trusted_robot_keys and trusted_signer_keys: the same shape; names unique across both lists.
Row<SecurityConfig> trusted_keys(std::string key,
                                 std::vector<TrustedRobotKey> SecurityConfig::*list) {
  using K = Rows<TrustedRobotKey>;
  static const Table<TrustedRobotKey> rows = {
      K::read("name", Str(128),
              [](const At& a, TrustedRobotKey& t, Ctx& x) {
                t.name = a.str();
                if (t.name.empty()) fail(a.path, "must not be empty", "invalid_value");
                auto named = [&t](const std::vector<TrustedRobotKey>& v) {
                  return std::any_of(v.begin(), v.end(),
                                     [&t](const TrustedRobotKey& k) { return k.name == t.name; });
                };
                if (named(x.c.security.trusted_robot_keys) ||
                    named(x.c.security.trusted_signer_keys))
                  fail(a.path, "duplicate trusted key name \"" + printable(t.name) + "\"",
                       "invalid_value");
              })
          .required(),
      K::path("mldsa65_pub_file", Str(), &TrustedRobotKey::mldsa65_pub_file),
      K::path("ed25519_pub_file", Str(), &TrustedRobotKey::ed25519_pub_file),
      K::check([](const At& k, TrustedRobotKey& t, Ctx&) {
        if (t.mldsa65_pub_file.empty() && t.ed25519_pub_file.empty())
          fail(k.path, "needs mldsa65_pub_file and/or ed25519_pub_file", "missing_key");
      }),
  };
  return S::read(std::move(key), Arr(object_of(rows), 256),
                 [list](const At& a, SecurityConfig& s, Ctx& x) {
                   for (size_t i = 0; i < a.size(); ++i)
                     (s.*list).push_back(element(rows, a[i], x));
                 });
}

// The injection screen: the built-in substrings (unless use_defaults: false), then the
// configured substrings and regular expressions.
Table<SecurityConfig> injection_rows() {
  return {
      S::read("use_defaults", Bool(),
              [](const At& a, SecurityConfig& s, Ctx&) {
                if (a.flag(true))
                  for (const auto& p : default_injection_patterns())
                    s.injection_patterns.push_back({p, false});
              }),
      S::read("patterns", Arr(Either({Str(256), Obj({{"regex", Str(256)}}, {"regex"})}), 512),
              [](const At& a, SecurityConfig& s, Ctx&) {
                for (size_t i = 0; i < a.size(); ++i) {
                  At p = a[i];
                  InjectionPattern ip;
                  if (p.is_string()) {
                    ip.text = p.str();
                  } else {
                    ip.text = p["regex"].str();
                    ip.regex = true;
                    try {
                      std::regex test(ip.text, std::regex::ECMAScript | std::regex::icase);
                      (void)test;
                    } catch (const std::regex_error& e) {
                      fail(p["regex"].path, std::string("invalid regular expression: ") + e.what(),
                           "invalid_value");
                    }
                  }
                  if (ip.text.empty()) fail(p.path, "empty pattern", "invalid_value");
                  s.injection_patterns.push_back(std::move(ip));
                }
              }),
  };
}

Table<CommitmentConfig> commitment_rows() {
  using C = Rows<CommitmentConfig>;
  return {
      C::field("enabled", Bool(), &CommitmentConfig::enabled),
      C::field("key_mode", Enum({"classical", "quantum", "hybrid"}), &CommitmentConfig::key_mode),
      C::field("qber_threshold", Num(0.0, 1.0), &CommitmentConfig::qber_threshold),
  };
}

// v1.5 blocks rcand does not implement: refused when present (even empty), never parsed and
// ignored. Key rotation: add the new key beside the old one (security.jwt issuers, trusted
// keys), then revoke the old key id (`rcan token revoke --kid`). A registry's revocation feed:
// the node's own list (`revocations.json`, POST /rcan/v1/revocations) is always on.
Row<SecurityConfig> not_implemented(const char* key, const char* instead) {
  return S::read(key, Free(), [key, instead](const At& a, SecurityConfig&, Ctx&) {
    if (a)
      fail(a.path,
           std::string("security.") + key + " is not implemented by rcand; " + instead +
               " (docs/CONFIG.md)",
           "not_supported");
  });
}

Table<SecurityConfig> security_rows() {
  return {
      explicit_path("key_dir", &SecurityConfig::key_dir, &NodeConfig::ExplicitPaths::key_dir),
      S::block("audit", audit_rows(), &SecurityConfig::audit),
      S::block("jwt", jwt_rows(), &SecurityConfig::jwt),
      S::field("replay_window_s", Int(5, 300), &SecurityConfig::replay_window_s),
      S::field("msg_id_cache_size", Int(100, 10'000'000), &SecurityConfig::msg_id_cache_size),
      S::field("failed_auth_per_address_per_minute", Int(0, 1'000'000),
               &SecurityConfig::failed_auth_per_address_per_minute),
      trusted_keys("trusted_robot_keys", &SecurityConfig::trusted_robot_keys),
      trusted_keys("trusted_signer_keys", &SecurityConfig::trusted_signer_keys),
      S::block("injection", injection_rows()),
      S::block("commitment", commitment_rows(), &SecurityConfig::commitment),
      not_implemented("key_rotation",
                      "add the new key beside the old one and revoke the old key id with "
                      "`rcan token revoke --kid`"),
      not_implemented("revocation",
                      "the node's own revocation list is always on (`rcan token revoke`); "
                      "remove the block"),
  };
}

}  // namespace

Table<NodeConfig> security_blocks() {
  return {Rows<NodeConfig>::block("security", security_rows(), &NodeConfig::security)};
}

void derive_paths(NodeConfig& c) {
  namespace fs = std::filesystem;
  if (!c.explicit_paths.key_dir) c.security.key_dir = (fs::path(c.data_dir) / "keys").string();
  if (!c.explicit_paths.audit_dir) c.security.audit.dir = (fs::path(c.data_dir) / "audit").string();
  if (!c.explicit_paths.chain_secret_file)
    c.security.audit.chain_secret_file = (fs::path(c.data_dir) / "audit.secret").string();
}

}  // namespace rcan::config::internal

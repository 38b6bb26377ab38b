// First-run identity and the robot's secrets (identity.h).
#include "identity.h"

#include <sys/stat.h>

#include <chrono>
#include <cstdio>
#include <filesystem>

#include "base/clock.h"
#include "rcan/audit/secret.h"
#include "rcan/base/env.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/encoding.h"
#include "rcan/errors.h"
#include "rcan/hash.h"

namespace fs = std::filesystem;

namespace rcan::rcand {
namespace {

Result<std::string> read_text(const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return Error(ErrorCode::kNotFound, "cannot read " + path);
  std::string s;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0 && s.size() < (1u << 20)) s.append(buf, n);
  std::fclose(f);
  return s;
}

// Whether the owner token in `path` has expired at `now` (or within the next minute), or is
// unreadable as a JWT: then a fresh one replaces it.
bool owner_token_expired(const std::string& path, int64_t now) {
  auto text = read_text(path);
  if (!text.ok()) return true;
  std::string t = *text;
  while (!t.empty() && (t.back() == '\n' || t.back() == '\r' || t.back() == ' ')) t.pop_back();
  auto d = jwt::decode(t);
  if (!d.ok()) return true;
  const json::Value* exp = d->claims.find("exp");
  return !exp || !exp->is_int() || exp->as_int() <= now + 60;
}

}  // namespace

Status make_private_dir(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Error(ErrorCode::kInternal, "cannot create " + dir + ": " + ec.message());
  ::chmod(dir.c_str(), 0700);
  return Status::Ok();
}

Result<LocalIdentity> ensure_local_identity(const std::string& data_dir) {
  LocalIdentity id;
  if (Status s = make_private_dir(data_dir); !s.ok()) return s.error();
  std::string device_file = data_dir + "/device_id";
  if (auto t = read_text(device_file); t.ok()) {
    id.device_id = *t;
    while (!id.device_id.empty() && (id.device_id.back() == '\n' || id.device_id.back() == '\r'))
      id.device_id.pop_back();
  } else {
    uint8_t b[4];
    if (!random_bytes(b, sizeof b)) return Error(ErrorCode::kInternal, "no randomness");
    id.device_id = to_hex(b, sizeof b);
    std::string text = id.device_id + "\n";
    if (Status s = keys::write_new_file(
            device_file, {reinterpret_cast<const uint8_t*>(text.data()), text.size()}, 0644);
        !s.ok())
      return s.error();
    id.created = true;
  }
  id.issuer_seed_file = data_dir + "/issuer/ed25519.seed";
  id.owner_token_file = data_dir + "/owner.token";
  return id;
}

Status ensure_issuer_and_token(const LocalIdentity& id, const std::string& ruri,
                               jwt::TrustStore& trust, bool& token_created) {
  if (auto made = keys::ensure_issuer_dir(fs::path(id.issuer_seed_file).parent_path()); !made.ok())
    return made.error();
  auto signing = jwt::SigningKey::from_file(id.issuer_seed_file);
  if (!signing.ok()) return signing.error();
  auto verify = signing->verification_key();
  if (!verify.ok()) return verify.error();
  trust.add(id.issuer, *verify);
  token_created = false;
  const int64_t now = unix_seconds();
  if (fs::exists(id.owner_token_file) && !owner_token_expired(id.owner_token_file, now))
    return Status::Ok();
  // First run, or the last owner token has expired (or is no JWT): a fresh one, with its own
  // jti. It lives kOwnerTokenTtlS; `rcan token issue --key <data>/issuer/ed25519.seed …` mints
  // more (docs/NODE.md).
  json::Object claims{{"iss", id.issuer},
                      {"sub", "local-owner"},
                      {"aud", ruri},
                      {"role", "owner"},
                      {"scope", json::Array{"status", "chat", "control", "config", "training"}},
                      {"jti", new_uuid_v4()},
                      {"iat", now},
                      {"exp", now + kOwnerTokenTtlS}};
  auto token = jwt::issue(claims, *signing);
  if (!token.ok()) return token.error();
  std::string text = *token + "\n";
  if (base::IoStatus s = base::Env::posix()->write_file_atomic(id.owner_token_file, text); !s.ok())
    return Error(ErrorCode::kInternal,
                 "cannot write " + id.owner_token_file + ": " + s.error().message);
  token_created = true;
  return Status::Ok();
}

// What a configured robot without its identity should run.
std::string init_hint(const config::NodeConfig& cfg) {
  return "; `rcand init --dir " + cfg.data_dir + "` creates what a configured robot needs";
}

Result<keys::RobotKeys> robot_keys(const config::NodeConfig& cfg, bool create) {
  if (create && !fs::exists(cfg.security.key_dir + "/" + std::string(keys::kMldsaSeedFile))) {
    auto k = keys::generate();
    if (!k.ok()) return k.error();
    if (Status s = keys::write_dir(cfg.security.key_dir, *k); !s.ok()) return s.error();
  }
  auto loaded = keys::load_dir(cfg.security.key_dir);
  if (!loaded.ok())
    return Error(ErrorCode::kInternal,
                 "robot keys in " + cfg.security.key_dir + ": " + loaded.error().message +
                     " (create them with: rcan keys generate --dir " + cfg.security.key_dir + ")" +
                     (create ? "" : init_hint(cfg)));
  return loaded;
}

Result<std::string> chain_secret(const config::NodeConfig& cfg, bool create) {
  const std::string& file = cfg.security.audit.chain_secret_file;
  if (create && !fs::exists(file)) {
    if (Status s = audit::create_secret_file(file); !s.ok()) return s.error();
  }
  auto secret = audit::load_chain_secret(file);
  if (!secret.ok()) {
    std::string msg = secret.error().message;
    if (msg.find("new-secret") == std::string::npos)
      msg += " (create one with: rcan audit new-secret --out " + file + ")";
    if (!create) msg += init_hint(cfg);
    return Error(ErrorCode::kInternal, msg);
  }
  return secret;
}

}  // namespace rcan::rcand

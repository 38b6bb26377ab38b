// What a robot needs before it can serve: its private data directory, robot keys, the audit
// chain secret and — for the embedded default only — a device id, a local token issuer and an
// OWNER token. Everything secret is written with mode 0600 in a 0700 directory.
#pragma once

#include <string>

#include "config/config.h"
#include "rcan/crypto/jwt.h"
#include "rcan/crypto/keys.h"
#include "rcan/result.h"

namespace rcan::rcand {

// Creates `dir` (and its parents) and sets it to 0700.
Status make_private_dir(const std::string& dir);

// The embedded default's identity. Created once; later runs reuse it.
struct LocalIdentity {
  std::string device_id;  // 8 hex characters, in <data_dir>/device_id
  std::string issuer = "rcand-local";
  std::string issuer_seed_file;  // <data_dir>/issuer/ed25519.seed
  std::string owner_token_file;  // <data_dir>/owner.token
  bool created = false;          // the device id was made by this run
};

// Reads (or, on the first run, creates) the device id in `data_dir`.
Result<LocalIdentity> ensure_local_identity(const std::string& data_dir);

// How long the OWNER token rcand writes is valid (24 h): short, so that a copied token does not
// outlive the day; `rcan token issue` with the local issuer key mints more (docs/NODE.md).
inline constexpr int64_t kOwnerTokenTtlS = 24 * 3600;

// The local issuer's key (created once), trusted as `id.issuer` in `trust`, and an OWNER token
// for `ruri` (each with a fresh jti; written on the first run and again whenever the last one
// has expired; `token_created` says whether this run wrote it).
Status ensure_issuer_and_token(const LocalIdentity& id, const std::string& ruri,
                               jwt::TrustStore& trust, bool& token_created);

// The robot's keys from security.key_dir, created when missing and `create` is set (the
// embedded default's first run, `rcand init`); otherwise missing keys are an error that says
// how to make them (`rcand init`).
Result<keys::RobotKeys> robot_keys(const config::NodeConfig& cfg, bool create);

// The audit chain secret from security.audit.chain_secret_file; created when missing and
// `create` is set, else required (the error says how to make one).
Result<std::string> chain_secret(const config::NodeConfig& cfg, bool create);

}  // namespace rcan::rcand

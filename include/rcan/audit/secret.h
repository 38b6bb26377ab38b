// Loading the audit chain secret. There is no default secret anywhere.
//
// Sources, first match wins:
//   1. an explicit file path (config `security.audit.chain_secret_file`),
//   2. env RCAN_AUDIT_SECRET_FILE (a path),
//   3. env RCAN_AUDIT_SECRET (the secret itself).
// A file must be a regular file not readable or writable by group/other (mode 0600 or
// stricter) and is used byte-exact: a trailing newline is refused rather than silently
// stripped, so every tool derives the same key. Minimum length 16 bytes.
// With nothing configured the error (kAuditUnavailable) says how to create a secret.
#pragma once

#include <string>

#include "rcan/result.h"

namespace rcan::audit {

inline constexpr size_t kMinSecretBytes = 16;

// Reads a secret file with the checks above.
Result<std::string> read_secret_file(const std::string& path);
// Resolves the secret from `explicit_file` (may be empty) and the environment.
Result<std::string> load_chain_secret(const std::string& explicit_file = {});
// 64 lower-case hex characters from the system CSPRNG.
Result<std::string> generate_secret();
// Writes a new secret to `path` with mode 0600, refusing to overwrite.
Status create_secret_file(const std::string& path);
// The message given when no secret is configured.
std::string secret_setup_hint();

}  // namespace rcan::audit

// Robot identity keys and the key directory that holds them.
//
// A key directory holds four raw files (no headers, no encodings):
//   mldsa65.seed   32 bytes   ML-DSA-65 seed ξ            secret, mode 0600
//   mldsa65.pub    1952 bytes ML-DSA-65 public key (FIPS 204 encoding)
//   ed25519.seed   32 bytes   Ed25519 seed (RFC 8032 private key)   secret, mode 0600
//   ed25519.pub    32 bytes   Ed25519 public key
// The ML-DSA-65 secret key (4032 bytes) is never stored: it is derived from the seed with
// ML-DSA.KeyGen_internal when the directory is loaded.
//
// Files are created with O_CREAT|O_EXCL (never overwritten); secrets get mode 0600 and the
// directory 0700 when this code creates it. Loading refuses a secret file that is not a
// regular file or is group/world accessible (any of mode bits 077), and checks that each
// .pub file matches the key derived from its seed.
//
// kid = first 8 lower-case hex of SHA-256(raw ML-DSA-65 pk) — the rcan-py/rcan-ts key id.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "rcan/encoding.h"
#include "rcan/json.h"
#include "rcan/result.h"

namespace rcan::keys {

inline constexpr std::string_view kMldsaSeedFile = "mldsa65.seed";
inline constexpr std::string_view kMldsaPubFile = "mldsa65.pub";
inline constexpr std::string_view kEd25519SeedFile = "ed25519.seed";
inline constexpr std::string_view kEd25519PubFile = "ed25519.pub";

// A byte buffer for secrets: wiped on destruction and on reassignment. Move-only.
class SecretBytes {
 public:
  SecretBytes() = default;
  explicit SecretBytes(Bytes b) : b_(std::move(b)) {}
  SecretBytes(const uint8_t* p, size_t n) : b_(p, p + n) {}
  SecretBytes(const SecretBytes&) = delete;
  SecretBytes& operator=(const SecretBytes&) = delete;
  SecretBytes(SecretBytes&& o) noexcept : b_(std::move(o.b_)) { o.b_.clear(); }
  SecretBytes& operator=(SecretBytes&& o) noexcept;
  ~SecretBytes() { wipe(); }

  void wipe();
  const uint8_t* data() const { return b_.data(); }
  size_t size() const { return b_.size(); }
  bool empty() const { return b_.empty(); }
  std::span<const uint8_t> span() const { return {b_.data(), b_.size()}; }
  std::string_view view() const { return {reinterpret_cast<const char*>(b_.data()), b_.size()}; }
  SecretBytes clone() const { return SecretBytes(Bytes(b_)); }

 private:
  Bytes b_;
};

// Public half of a robot identity.
struct PublicKeys {
  Bytes mldsa65_pk;         // 1952 bytes
  Bytes ed25519_pk;         // 32 bytes
  std::string kid() const;  // ML-DSA-65 kid
};

// The full identity. Secrets are wiped when it goes out of scope.
struct RobotKeys {
  SecretBytes mldsa65_seed;  // 32
  SecretBytes mldsa65_sk;    // 4032, derived
  SecretBytes ed25519_seed;  // 32
  PublicKeys pub;
};

// Deterministic keys from the two 32-byte seeds (recovery, tests).
Result<RobotKeys> derive(std::span<const uint8_t> mldsa65_seed,
                         std::span<const uint8_t> ed25519_seed);
// Fresh random seeds from the OS CSPRNG.
Result<RobotKeys> generate();

// Writes the four files into `dir` (created with mode 0700 when absent). Fails, writing
// nothing new, when any of the files already exists.
Status write_dir(const std::string& dir, const RobotKeys& keys);
// A JWT issuer's Ed25519 key pair in `dir` (created 0700 when absent): ed25519.seed (0600, the
// key `rcan token issue --key` signs with) and ed25519.pub.pem (its SubjectPublicKeyInfo PEM,
// what security.jwt.issuers[].key_file names). Existing files are kept, never replaced; a seed
// without its PEM gets one, and a PEM that is not the seed's public key is an error. True when
// this call created the seed.
inline constexpr std::string_view kIssuerSeedFile = "ed25519.seed";
inline constexpr std::string_view kIssuerPubFile = "ed25519.pub.pem";
Result<bool> ensure_issuer_dir(const std::string& dir);
// Loads and cross-checks a key directory (secrets included).
Result<RobotKeys> load_dir(const std::string& dir);
// Loads only the public files of a key directory (no permission requirements).
Result<PublicKeys> load_public_dir(const std::string& dir);

// Reads a secret file: must be a regular file (symlinks are not followed), not group/world
// accessible, and exactly `expected_size` bytes when expected_size != 0 (at most 1 MiB
// otherwise).
Result<SecretBytes> read_secret_file(const std::string& path, size_t expected_size = 0);
// Creates a new file with O_CREAT|O_EXCL|O_NOFOLLOW and `mode`, writes `data`, fsyncs.
Status write_new_file(const std::string& path, std::span<const uint8_t> data, unsigned mode);
// Reads a (public) file of at most `max_size` bytes.
Result<Bytes> read_public_file(const std::string& path, size_t max_size = 1 << 20);

// rcan-py `encode_public_key_jwk` shape, members in rcan-py order:
// {"kty":"OKP","crv":"ML-DSA-65","x":<b64url nopad pk>,"kid":…,"use":"sig","alg":"ml-dsa-65"}
json::Value mldsa65_jwk(std::span<const uint8_t> pk);
// Inverse of mldsa65_jwk (requires kty OKP, crv ML-DSA-65, a 1952-byte x; a present kid must
// match the key). Accepts the rcan-ts shape too ({kty:"OKP", alg:"ML-DSA-65", x}).
Result<Bytes> mldsa65_pk_from_jwk(const json::Value& jwk);

// rcan-py's (deprecated) Ed25519 key id: first 8 hex of SHA-256 over the SPKI PEM text.
Result<std::string> ed25519_kid(std::span<const uint8_t> pk);

}  // namespace rcan::keys

// Robot identity key directories (see include/rcan/crypto/keys.h).
#include "rcan/crypto/keys.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <vector>

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/mldsa65.h"
#include "rcan/hash.h"

namespace rcan::keys {
namespace {

Error io_error(const std::string& what, const std::string& path, int err) {
  return Error(ErrorCode::kInternal, what + " " + path + ": " + std::strerror(err), path);
}

std::string join(const std::string& dir, std::string_view name) {
  if (!dir.empty() && dir.back() == '/') return dir + std::string(name);
  return dir + "/" + std::string(name);
}

// Reads everything from an open descriptor, refusing more than `max_size` bytes.
Result<Bytes> read_fd(int fd, const std::string& path, size_t max_size) {
  Bytes out;
  uint8_t buf[4096];
  for (;;) {
    ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0) {
      if (errno == EINTR) continue;
      int e = errno;
      secure_wipe(out.data(), out.size());
      secure_wipe(buf, sizeof buf);
      return io_error("cannot read", path, e);
    }
    if (n == 0) break;
    if (out.size() + static_cast<size_t>(n) > max_size) {
      secure_wipe(out.data(), out.size());
      secure_wipe(buf, sizeof buf);
      return Error(ErrorCode::kSchemaValidationFailed, path + " is larger than expected", path);
    }
    out.insert(out.end(), buf, buf + n);
  }
  secure_wipe(buf, sizeof buf);
  return out;
}

}  // namespace

SecretBytes& SecretBytes::operator=(SecretBytes&& o) noexcept {
  if (this != &o) {
    wipe();
    b_ = std::move(o.b_);
    o.b_.clear();
  }
  return *this;
}

void SecretBytes::wipe() {
  secure_wipe(b_.data(), b_.size());
  b_.clear();
}

std::string PublicKeys::kid() const { return mldsa65::kid(mldsa65_pk); }

Result<SecretBytes> read_secret_file(const std::string& path, size_t expected_size) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0) return io_error("cannot open secret file", path, errno);
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    int e = errno;
    ::close(fd);
    return io_error("cannot stat secret file", path, e);
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    return Error(ErrorCode::kSchemaValidationFailed,
                 "secret file " + path + " is not a regular file", path);
  }
  if ((st.st_mode & 077) != 0) {
    ::close(fd);
    char mode[8];
    std::snprintf(mode, sizeof mode, "%04o", static_cast<unsigned>(st.st_mode & 07777));
    return Error(ErrorCode::kSchemaValidationFailed,
                 "refusing secret file " + path + " with mode " + mode +
                     ": it is group/world accessible (chmod 600 it)",
                 path, "insecure_permissions");
  }
  auto data = read_fd(fd, path, expected_size ? expected_size + 1 : (1u << 20));
  ::close(fd);
  if (!data.ok()) return data.error();
  SecretBytes secret(std::move(data).value());
  if (expected_size != 0 && secret.size() != expected_size) {
    size_t got = secret.size();
    return Error(ErrorCode::kSchemaValidationFailed,
                 path + " must be exactly " + std::to_string(expected_size) + " bytes, found " +
                     std::to_string(got),
                 path);
  }
  return secret;
}

Result<Bytes> read_public_file(const std::string& path, size_t max_size) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return io_error("cannot open", path, errno);
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return Error(ErrorCode::kSchemaValidationFailed, path + " is not a regular file", path);
  }
  auto data = read_fd(fd, path, max_size);
  ::close(fd);
  return data;
}

Status write_new_file(const std::string& path, std::span<const uint8_t> data, unsigned mode) {
  int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC,
                  static_cast<mode_t>(mode));
  if (fd < 0) return io_error("cannot create", path, errno);
  // The umask may have removed bits but never adds any; make the mode exact.
  if (::fchmod(fd, static_cast<mode_t>(mode)) != 0) {
    int e = errno;
    ::close(fd);
    ::unlink(path.c_str());
    return io_error("cannot chmod", path, e);
  }
  size_t off = 0;
  while (off < data.size()) {
    ssize_t n = ::write(fd, data.data() + off, data.size() - off);
    if (n < 0) {
      if (errno == EINTR) continue;
      int e = errno;
      ::close(fd);
      ::unlink(path.c_str());
      return io_error("cannot write", path, e);
    }
    off += static_cast<size_t>(n);
  }
  if (::fsync(fd) != 0) {
    int e = errno;
    ::close(fd);
    ::unlink(path.c_str());
    return io_error("cannot fsync", path, e);
  }
  if (::close(fd) != 0) return io_error("cannot close", path, errno);
  return Status::Ok();
}

Result<RobotKeys> derive(std::span<const uint8_t> mldsa65_seed,
                         std::span<const uint8_t> ed25519_seed) {
  if (mldsa65_seed.size() != mldsa65::kSeedBytes)
    return Error(ErrorCode::kSchemaValidationFailed, "ML-DSA-65 seed must be 32 bytes",
                 "mldsa65_seed");
  if (ed25519_seed.size() != ed25519::kSeedBytes)
    return Error(ErrorCode::kSchemaValidationFailed, "Ed25519 seed must be 32 bytes",
                 "ed25519_seed");
  auto kp = mldsa65::keygen_from_seed(mldsa65_seed);
  if (!kp.ok()) return kp.error();
  auto edpk = ed25519::public_key_from_seed(ed25519_seed);
  if (!edpk.ok()) return edpk.error();
  RobotKeys k;
  k.mldsa65_seed = SecretBytes(mldsa65_seed.data(), mldsa65_seed.size());
  k.mldsa65_sk = SecretBytes(kp->secret_key.data(), kp->secret_key.size());
  k.ed25519_seed = SecretBytes(ed25519_seed.data(), ed25519_seed.size());
  k.pub.mldsa65_pk = kp->public_key;
  k.pub.ed25519_pk = std::move(edpk).value();
  return k;
}

Result<RobotKeys> generate() {
  uint8_t seeds[64];
  if (!random_bytes(seeds, sizeof seeds))
    return Error(ErrorCode::kInternal, "the system random generator failed");
  auto k = derive(std::span<const uint8_t>(seeds, 32), std::span<const uint8_t>(seeds + 32, 32));
  secure_wipe(seeds, sizeof seeds);
  return k;
}

namespace {

// `dir` as a key directory: created with mode 0700 when absent, else it must be a directory.
Status key_directory(const std::string& dir) {
  struct stat st {};
  if (::stat(dir.c_str(), &st) != 0) {
    if (errno != ENOENT) return io_error("cannot stat", dir, errno);
    if (::mkdir(dir.c_str(), 0700) != 0) return io_error("cannot create directory", dir, errno);
  } else if (!S_ISDIR(st.st_mode)) {
    return Error(ErrorCode::kSchemaValidationFailed, dir + " exists and is not a directory", dir);
  }
  return Status::Ok();
}

}  // namespace

Status write_dir(const std::string& dir, const RobotKeys& keys) {
  if (keys.mldsa65_seed.size() != mldsa65::kSeedBytes ||
      keys.ed25519_seed.size() != ed25519::kSeedBytes ||
      keys.pub.mldsa65_pk.size() != mldsa65::kPublicKeyBytes ||
      keys.pub.ed25519_pk.size() != ed25519::kPublicKeyBytes)
    return Error(ErrorCode::kInternal, "incomplete key set");
  if (Status s = key_directory(dir); !s.ok()) return s;
  struct stat st {};
  const std::string files[] = {join(dir, kMldsaSeedFile), join(dir, kMldsaPubFile),
                               join(dir, kEd25519SeedFile), join(dir, kEd25519PubFile)};
  for (const auto& f : files) {
    if (::lstat(f.c_str(), &st) == 0)
      return Error(ErrorCode::kSchemaValidationFailed,
                   f + " already exists; refusing to overwrite a key", f);
  }
  struct Item {
    const std::string& path;
    std::span<const uint8_t> data;
    unsigned mode;
  };
  const Item items[] = {{files[0], keys.mldsa65_seed.span(), 0600},
                        {files[1], keys.pub.mldsa65_pk, 0644},
                        {files[2], keys.ed25519_seed.span(), 0600},
                        {files[3], keys.pub.ed25519_pk, 0644}};
  for (size_t i = 0; i < 4; ++i) {
    Status s = write_new_file(items[i].path, items[i].data, items[i].mode);
    if (!s.ok()) {
      for (size_t j = 0; j < i; ++j) ::unlink(items[j].path.c_str());
      return s;
    }
  }
  return Status::Ok();
}

Result<RobotKeys> load_dir(const std::string& dir) {
  auto ms = read_secret_file(join(dir, kMldsaSeedFile), mldsa65::kSeedBytes);
  if (!ms.ok()) return ms.error();
  auto es = read_secret_file(join(dir, kEd25519SeedFile), ed25519::kSeedBytes);
  if (!es.ok()) return es.error();
  auto keys = derive(ms->span(), es->span());
  if (!keys.ok()) return keys.error();
  auto pub = load_public_dir(dir);
  if (!pub.ok()) return pub.error();
  if (pub->mldsa65_pk != keys->pub.mldsa65_pk)
    return Error(ErrorCode::kSchemaValidationFailed,
                 join(dir, kMldsaPubFile) + " does not match the key derived from " +
                     std::string(kMldsaSeedFile),
                 std::string(kMldsaPubFile));
  if (pub->ed25519_pk != keys->pub.ed25519_pk)
    return Error(ErrorCode::kSchemaValidationFailed,
                 join(dir, kEd25519PubFile) + " does not match the key derived from " +
                     std::string(kEd25519SeedFile),
                 std::string(kEd25519PubFile));
  return keys;
}

Result<PublicKeys> load_public_dir(const std::string& dir) {
  auto mp = read_public_file(join(dir, kMldsaPubFile), mldsa65::kPublicKeyBytes + 1);
  if (!mp.ok()) return mp.error();
  if (mp->size() != mldsa65::kPublicKeyBytes)
    return Error(ErrorCode::kSchemaValidationFailed,
                 join(dir, kMldsaPubFile) + " must be exactly 1952 bytes",
                 std::string(kMldsaPubFile));
  auto ep = read_public_file(join(dir, kEd25519PubFile), ed25519::kPublicKeyBytes + 1);
  if (!ep.ok()) return ep.error();
  if (ep->size() != ed25519::kPublicKeyBytes)
    return Error(ErrorCode::kSchemaValidationFailed,
                 join(dir, kEd25519PubFile) + " must be exactly 32 bytes",
                 std::string(kEd25519PubFile));
  PublicKeys p;
  p.mldsa65_pk = std::move(mp).value();
  p.ed25519_pk = std::move(ep).value();
  return p;
}

json::Value mldsa65_jwk(std::span<const uint8_t> pk) {
  json::Object o;
  o.set("kty", "OKP");
  o.set("crv", "ML-DSA-65");
  o.set("x", base64url_encode(pk.data(), pk.size(), false));
  o.set("kid", mldsa65::kid(pk));
  o.set("use", "sig");
  o.set("alg", "ml-dsa-65");
  return json::Value(std::move(o));
}

Result<Bytes> mldsa65_pk_from_jwk(const json::Value& jwk) {
  auto bad = [](const std::string& m, const std::string& f = {}) {
    return Error(ErrorCode::kSchemaValidationFailed, "ML-DSA-65 JWK: " + m, f);
  };
  if (!jwk.is_object()) return bad("not a JSON object");
  const json::Value* kty = jwk.get("kty");
  if (!kty || !kty->is_string() || kty->as_string() != "OKP")
    return bad("kty must be \"OKP\"", "kty");
  const json::Value* crv = jwk.get("crv");
  const json::Value* alg = jwk.get("alg");
  bool crv_ok = crv && crv->is_string() && crv->as_string() == "ML-DSA-65";
  bool alg_ok = alg && alg->is_string() &&
                (alg->as_string() == "ML-DSA-65" || alg->as_string() == "ml-dsa-65");
  if (crv && !crv_ok) return bad("crv must be \"ML-DSA-65\"", "crv");
  if (alg && !alg_ok) return bad("alg must be \"ml-dsa-65\"", "alg");
  if (!crv_ok && !alg_ok) return bad("neither crv nor alg names ML-DSA-65");
  if (const json::Value* use = jwk.get("use");
      use && !(use->is_string() && use->as_string() == "sig"))
    return bad("use must be \"sig\"", "use");
  const json::Value* x = jwk.get("x");
  if (!x || !x->is_string()) return bad("x is missing", "x");
  auto pk = base64url_decode(x->as_string());
  if (!pk) return bad("x is not base64url", "x");
  if (pk->size() != mldsa65::kPublicKeyBytes) return bad("x must decode to 1952 bytes", "x");
  if (const json::Value* kid = jwk.get("kid")) {
    if (!kid->is_string() || kid->as_string() != mldsa65::kid(*pk))
      return bad("kid does not match the key", "kid");
  }
  return *pk;
}

Result<std::string> ed25519_kid(std::span<const uint8_t> pk) {
  auto pem = ed25519::public_key_to_pem(pk);
  if (!pem.ok()) return pem.error();
  return sha256_hex(*pem).substr(0, 8);
}

Result<bool> ensure_issuer_dir(const std::string& dir) {
  if (Status s = key_directory(dir); !s.ok()) return s.error();
  const std::string seed_file = join(dir, kIssuerSeedFile), pem_file = join(dir, kIssuerPubFile);
  struct stat st {};
  bool created = false;
  if (::lstat(seed_file.c_str(), &st) != 0) {
    Bytes seed = ed25519::random_seed();
    Status s = write_new_file(seed_file, seed, 0600);
    secure_wipe(seed.data(), seed.size());
    if (!s.ok()) return s.error();
    created = true;
  }
  auto seed = read_secret_file(seed_file, ed25519::kSeedBytes);
  if (!seed.ok()) return seed.error();
  auto pk = ed25519::public_key_from_seed(seed->span());
  if (!pk.ok()) return pk.error();
  auto pem = ed25519::public_key_to_pem(*pk);
  if (!pem.ok()) return pem.error();
  if (::lstat(pem_file.c_str(), &st) == 0) {
    auto have = read_public_file(pem_file, 4096);
    if (!have.ok()) return have.error();
    if (std::string(have->begin(), have->end()) != *pem)
      return Error(ErrorCode::kSchemaValidationFailed,
                   pem_file + " is not the public key of " + seed_file, pem_file);
    return created;
  }
  if (Status s = write_new_file(pem_file,
                                {reinterpret_cast<const uint8_t*>(pem->data()), pem->size()}, 0644);
      !s.ok())
    return s.error();
  return created;
}

}  // namespace rcan::keys

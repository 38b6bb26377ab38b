#include "rcan/audit/secret.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

#include "rcan/encoding.h"
#include "rcan/hash.h"

namespace rcan::audit {
namespace {

Error secret_error(std::string msg) { return Error(ErrorCode::kAuditUnavailable, std::move(msg)); }

}  // namespace

std::string secret_setup_hint() {
  return "no audit chain secret configured (there is no default). Create one with\n"
         "  rcan audit new-secret --out /var/lib/rcan/audit.secret\n"
         "(64 hex characters, mode 0600, no trailing newline), then set\n"
         "security.audit.chain_secret_file in the config or\n"
         "RCAN_AUDIT_SECRET_FILE=/var/lib/rcan/audit.secret in the environment.";
}

Result<std::string> read_secret_file(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    return secret_error("cannot read audit secret file " + path + ": " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) return secret_error("audit secret " + path + " is not a regular file");
  if ((st.st_mode & 077) != 0) {
    char mode[8];
    std::snprintf(mode, sizeof mode, "%04o", static_cast<unsigned>(st.st_mode & 07777));
    return secret_error("audit secret file " + path + " has mode " + mode +
                        "; it must not be accessible by group or others (chmod 600 " + path + ")");
  }
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0)
    return secret_error("cannot read audit secret file " + path + ": " + std::strerror(errno));
  std::string s;
  char buf[4096];
  for (;;) {
    ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    s.append(buf, static_cast<size_t>(n));
    if (s.size() > 65536) break;
  }
  ::close(fd);
  secure_wipe(buf, sizeof buf);
  if (s.empty()) return secret_error("audit secret file " + path + " is empty");
  if (s.back() == '\n' || s.back() == '\r') {
    secure_wipe(s.data(), s.size());
    return secret_error("audit secret file " + path +
                        " ends with a newline; the key is the file's exact bytes, so write it "
                        "without one (printf '%s' \"$SECRET\" > file)");
  }
  if (s.size() < kMinSecretBytes) {
    secure_wipe(s.data(), s.size());
    return secret_error("audit secret in " + path + " is shorter than " +
                        std::to_string(kMinSecretBytes) + " bytes");
  }
  return s;
}

Result<std::string> load_chain_secret(const std::string& explicit_file) {
  if (!explicit_file.empty()) return read_secret_file(explicit_file);
  if (const char* f = std::getenv("RCAN_AUDIT_SECRET_FILE"); f && *f) return read_secret_file(f);
  if (const char* v = std::getenv("RCAN_AUDIT_SECRET"); v && *v) {
    std::string s(v);
    if (s.size() < kMinSecretBytes)
      return secret_error("RCAN_AUDIT_SECRET is shorter than " + std::to_string(kMinSecretBytes) +
                          " bytes");
    return s;
  }
  return secret_error(secret_setup_hint());
}

Result<std::string> generate_secret() {
  uint8_t b[32];
  if (!random_bytes(b, sizeof b)) return secret_error("system random generator failed");
  std::string hex = to_hex(b, sizeof b);
  secure_wipe(b, sizeof b);
  return hex;
}

Status create_secret_file(const std::string& path) {
  auto s = generate_secret();
  if (!s.ok()) return s.error();
  int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0)
    return secret_error("cannot create " + path + ": " + std::strerror(errno) +
                        " (an existing secret is never overwritten)");
  const std::string& v = *s;
  bool ok = ::write(fd, v.data(), v.size()) == static_cast<ssize_t>(v.size()) && ::fsync(fd) == 0;
  ::close(fd);
  std::string copy = v;
  secure_wipe(copy.data(), copy.size());
  if (!ok) return secret_error("cannot write " + path);
  return Status::Ok();
}

}  // namespace rcan::audit

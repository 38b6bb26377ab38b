#include "runtime/state_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "rcan/errors.h"

namespace rcan {

Status write_state_file(const std::string& path, const json::Value& v, base::Env* env) {
  if (!env) env = base::Env::posix();
  base::IoStatus s = env->write_file_atomic(path, json::dump(v) + "\n");
  if (!s.ok()) return Error(ErrorCode::kInternal, s.error().message);
  return Status::Ok();
}

Result<json::Value> read_state_file(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return Error(ErrorCode::kNotFound, "no state file " + path);
  std::string text;
  char buf[8192];
  ssize_t n;
  while ((n = ::read(fd, buf, sizeof buf)) > 0 && text.size() < (4u << 20))
    text.append(buf, static_cast<size_t>(n));
  ::close(fd);
  auto v = json::parse(text, {.max_depth = 32, .max_bytes = 4u << 20});
  if (!v.ok() || !v->is_object())
    return Error(ErrorCode::kSchemaValidationFailed,
                 "state file " + path + " is not a JSON object");
  return std::move(v).value();
}

}  // namespace rcan

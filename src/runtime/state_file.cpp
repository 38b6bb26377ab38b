#include "runtime/state_file.h"

#include "rcan/errors.h"

namespace rcan {

Status write_state_file(const std::string& path, const json::Value& v, base::Env* env) {
  if (!env) env = base::Env::posix();
  base::IoStatus s = env->write_file_atomic(path, json::dump(v) + "\n");
  if (!s.ok()) return Error(ErrorCode::kInternal, s.error().message);
  return Status::Ok();
}

Result<json::Value> read_state_file(const std::string& path, base::Env* env) {
  constexpr size_t kMaxBytes = 4u << 20;
  if (!env) env = base::Env::posix();
  // One byte past the limit is enough to refuse a longer file without reading it whole.
  auto text = env->read_range(path, 0, kMaxBytes + 1);
  if (!text.ok()) return Error(ErrorCode::kNotFound, "no state file " + path);
  auto v = json::parse(*text, {.max_depth = 32, .max_bytes = kMaxBytes});
  if (!v.ok() || !v->is_object())
    return Error(ErrorCode::kSchemaValidationFailed,
                 "state file " + path + " is not a JSON object");
  return std::move(v).value();
}

}  // namespace rcan

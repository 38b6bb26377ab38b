#include "runtime/data_dir.h"

#include <pwd.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <vector>

namespace rcan {

Result<std::string> user_data_dir(std::string_view app, const char* env_var) {
  auto env = [](const char* name) -> std::string {
    const char* v = std::getenv(name);
    return v != nullptr ? std::string(v) : std::string();
  };
  namespace fs = std::filesystem;
  if (std::string d = env(env_var); !d.empty()) {
    std::error_code ec;
    fs::path abs = fs::absolute(d, ec);
    return (ec ? fs::path(d) : abs).lexically_normal().string();
  }
  if (std::string x = env("XDG_DATA_HOME"); !x.empty() && x[0] == '/')
    return (fs::path(x) / std::string(app)).lexically_normal().string();
  std::string home = env("HOME");
  if (home.empty() || home[0] != '/') {
    struct passwd pw {};
    struct passwd* result = nullptr;
    std::vector<char> buf(16384);
    if (getpwuid_r(getuid(), &pw, buf.data(), buf.size(), &result) == 0 && result != nullptr &&
        result->pw_dir != nullptr && result->pw_dir[0] == '/')
      home = result->pw_dir;
  }
  if (home.empty() || home[0] != '/')
    return Error(ErrorCode::kSchemaValidationFailed,
                 "no data directory: set " + std::string(env_var) + " or HOME, or pass --data-dir",
                 "node.data_dir", "missing_key");
  return (fs::path(home) / ".local" / "share" / std::string(app)).lexically_normal().string();
}

}  // namespace rcan

// Shared helpers for the test programs: vector files, temp dirs, child processes.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "rcan/encoding.h"
#include "rcan/json.h"

namespace rcan::test {

// Whole file as bytes; fails the current test (and returns "") when unreadable.
std::string read_file(const std::string& path);
// Parses tests/vectors/<name> (copied from the shared vector set; see tests/vectors/README.md).
json::Value load_vector(const std::string& name);
// Hex string to bytes; fails the current test on bad hex.
Bytes hex(std::string_view h);

// A fresh directory under $TMPDIR, removed with its contents on destruction.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::string& path() const { return path_; }
  std::string file(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

struct RunResult {
  int exit_code = -1;  // -1 when the process did not exit normally
  std::string out;
  std::string err;
};
// Runs argv[0] (a path) with arguments, feeding `stdin_data`; captures both outputs.
RunResult run(const std::vector<std::string>& argv, const std::string& stdin_data = {},
              const std::vector<std::string>& extra_env = {});
// Runs the rcan CLI built alongside the tests.
RunResult run_cli(const std::vector<std::string>& args, const std::string& stdin_data = {},
                  const std::vector<std::string>& extra_env = {});

}  // namespace rcan::test

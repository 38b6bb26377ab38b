// fuzz_replay — runs the fuzz targets' LLVMFuzzerTestOneInput without libFuzzer, over their
// seed corpora and committed regression inputs (docs/FUZZING.md). Built by the normal build
// (any compiler): each fuzz/<name>_fuzz.cpp is compiled with its entry point renamed to
// rcan_fuzz_<name>, and the generated table below lists them.
//
//   fuzz_replay --list
//   fuzz_replay NAME --dir FUZZ_DIR   every file in FUZZ_DIR/corpus/NAME and
//   FUZZ_DIR/regressions/NAME fuzz_replay NAME FILE…            the given inputs
//
// A target that misbehaves aborts (the test fails with the input's name printed last). With
// --dir the seed corpus must not be empty.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "fuzz_targets.inc"  // kTargets: {name, entry}

namespace fs = std::filesystem;

namespace {

using Entry = int (*)(const uint8_t*, size_t);

std::vector<std::string> files_in(const fs::path& dir) {
  std::vector<std::string> out;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return out;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (e.is_regular_file() && name != "README" && name != "README.md" && name[0] != '.')
      out.push_back(e.path().string());
  }
  std::sort(out.begin(), out.end());
  return out;
}

bool run_file(Entry fn, const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::fprintf(stderr, "fuzz_replay: cannot read %s\n", path.c_str());
    return false;
  }
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::fprintf(stderr, "  %s (%zu bytes)\n", path.c_str(), bytes.size());
  // A heap copy of exactly the input's size, as libFuzzer gives, so that an overread is seen
  // by AddressSanitizer builds.
  std::vector<uint8_t> data(bytes.begin(), bytes.end());
  uint8_t* p = data.empty() ? nullptr : data.data();
  fn(p, data.size());
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 2 && std::strcmp(argv[1], "--list") == 0) {
    for (const auto& t : kTargets) std::printf("%s\n", t.name);
    return 0;
  }
  if (argc < 3) {
    std::fprintf(stderr, "usage: fuzz_replay --list | NAME --dir FUZZ_DIR | NAME FILE...\n");
    return 2;
  }
  Entry fn = nullptr;
  for (const auto& t : kTargets)
    if (std::strcmp(t.name, argv[1]) == 0) fn = t.entry;
  if (!fn) {
    std::fprintf(stderr, "fuzz_replay: no target %s\n", argv[1]);
    return 2;
  }
  std::vector<std::string> files;
  if (std::strcmp(argv[2], "--dir") == 0) {
    if (argc != 4) return 2;
    const fs::path dir = argv[3];
    files = files_in(dir / "corpus" / argv[1]);
    if (files.empty()) {
      std::fprintf(stderr, "fuzz_replay: %s has no seed corpus in %s\n", argv[1],
                   (dir / "corpus" / argv[1]).c_str());
      return 1;
    }
    auto reg = files_in(dir / "regressions" / argv[1]);
    files.insert(files.end(), reg.begin(), reg.end());
  } else {
    files.assign(argv + 2, argv + argc);
  }
  std::fprintf(stderr, "fuzz_replay %s: %zu inputs\n", argv[1], files.size());
  for (const auto& f : files)
    if (!run_file(fn, f)) return 1;
  std::fprintf(stderr, "fuzz_replay %s: %zu inputs, all passed\n", argv[1], files.size());
  return 0;
}

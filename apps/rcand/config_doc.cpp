// `rcand config-doc`: the key tables of docs/CONFIG.md from the config's block tables
// (config/config_doc.h). ctest runs `--check` on the tree's docs/CONFIG.md.
#include "config/config_doc.h"

#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

using namespace rcan;

namespace {

constexpr const char* kConfigDocUsage =
    "usage: rcand config-doc KEYS…              the table of these top-level keys\n"
    "       rcand config-doc --check FILE       exit 1 when a generated region of FILE differs\n"
    "       rcand config-doc --write FILE       rewrite FILE's generated regions\n";

// The first line where `a` and `b` differ, 1-based.
size_t first_difference(const std::string& a, const std::string& b) {
  size_t line = 1;
  for (size_t i = 0; i < a.size() && i < b.size() && a[i] == b[i]; ++i) line += a[i] == '\n';
  return line;
}

int check_or_write(const char* mode, const char* file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) {
    std::fprintf(stderr, "rcand config-doc: cannot read %s\n", file);
    return 2;
  }
  std::stringstream text;
  text << in.rdbuf();
  auto generated = config::regenerate_config_doc(text.str());
  if (!generated.ok()) {
    std::fprintf(stderr, "rcand config-doc: %s: %s\n", file, generated.error().message.c_str());
    return 2;
  }
  if (std::strcmp(mode, "--write") == 0) {
    if (*generated != text.str()) std::ofstream(file, std::ios::binary) << *generated;
    return 0;
  }
  if (*generated == text.str()) return 0;
  std::fprintf(stderr,
               "rcand config-doc: %s line %zu differs from the config's key tables; "
               "run `rcand config-doc --write %s`\n",
               file, first_difference(text.str(), *generated), file);
  return 1;
}

}  // namespace

int config_doc_main(int argc, char** argv) {
  if (argc == 4 && (std::strcmp(argv[2], "--check") == 0 || std::strcmp(argv[2], "--write") == 0))
    return check_or_write(argv[2], argv[3]);
  if (argc < 3 || argv[2][0] == '-') {
    std::fputs(kConfigDocUsage, argc < 3 ? stderr : stdout);
    return argc < 3 ? 2 : 0;
  }
  std::string keys;
  for (int i = 2; i < argc; ++i) keys += std::string(argv[i]) + " ";
  auto table = config::config_doc_table(keys);
  if (!table.ok()) {
    std::fprintf(stderr, "rcand config-doc: %s\n", table.error().message.c_str());
    return 2;
  }
  std::fputs(table->c_str(), stdout);
  return 0;
}

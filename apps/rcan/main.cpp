// rcan — the RCAN command-line tool. Verbs register themselves (see cli.h).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <iterator>
#include <sstream>

#include "base/clock.h"
#include "base/strings.h"
#include "cli.h"
#include "rcan/errors.h"
#include "rcan/json.h"
#include "rcan/version.h"

namespace rcan::cli {
namespace {

std::vector<Verb>& registry() {
  static std::vector<Verb> v;
  return v;
}

void print_help() {
  std::printf("usage: rcan <verb> [args…]\n\nverbs:\n");
  auto list = verbs();
  std::sort(list.begin(), list.end(), [](const Verb& a, const Verb& b) { return a.name < b.name; });
  for (const auto& v : list) std::printf("  %-12s %s\n", v.name.c_str(), v.summary.c_str());
  std::printf(
      "\n'rcan <verb> --help' describes a verb. Verbs that talk to a node take --url (default\n"
      "$RCAN_URL), --token-file (default $RCAN_TOKEN_FILE) and --json; rcand prints both\n"
      "variables on its first run. Bash completion: source <(rcan completion bash).\n"
      "Exit codes: 0 success, 1 negative answer (refused by the node, invalid input, failed\n"
      "verification), 2 usage or malformed input, 3 node unreachable, 4 waiting for a human\n"
      "authorization.\n");
}

}  // namespace

Registration::Registration(std::string name, std::string summary, VerbFn fn) {
  registry().push_back(Verb{std::move(name), std::move(summary), fn});
}

const std::vector<Verb>& verbs() { return registry(); }

std::string read_stdin() {
  std::string data;
  char buf[65536];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, stdin)) > 0) data.append(buf, n);
  return data;
}

std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  for (std::string_view item : split(s, ',', /*keep_empty=*/false)) out.emplace_back(item);
  return out;
}

Result<std::string> read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error(ErrorCode::kNotFound, "cannot read " + path + ": " + std::strerror(errno));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void print_error_body(const Error& err, std::string_view reply_to) {
  auto now_ms = unix_ms();
  std::cout << json::dump(error_body(err, reply_to, now_ms)) << "\n";
}

Options::Options(const Args& args, const std::vector<std::string>& flags,
                 const std::vector<std::string>& valued) {
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a.size() > 2 && a.rfind("--", 0) == 0) {
      std::string name = a.substr(2);
      std::string value;
      bool inline_value = false;
      if (auto eq = name.find('='); eq != std::string::npos) {
        value = name.substr(eq + 1);
        name = name.substr(0, eq);
        inline_value = true;
      }
      if (std::find(flags.begin(), flags.end(), name) != flags.end()) {
        if (inline_value) {
          error_ = "--" + name + " takes no value";
          return;
        }
        values_.emplace_back(name, "");
      } else if (std::find(valued.begin(), valued.end(), name) != valued.end()) {
        if (!inline_value) {
          if (i + 1 >= args.size()) {
            error_ = "--" + name + " needs a value";
            return;
          }
          value = args[++i];
        }
        values_.emplace_back(name, value);
      } else {
        error_ = "unknown option --" + name;
        return;
      }
    } else {
      positional_.push_back(a);
    }
  }
}

bool Options::has(const std::string& name) const {
  return std::any_of(values_.begin(), values_.end(),
                     [&](const auto& p) { return p.first == name; });
}

std::string Options::get(const std::string& name, const std::string& def) const {
  for (auto it = values_.rbegin(); it != values_.rend(); ++it)
    if (it->first == name) return it->second;
  return def;
}

int usage_error(std::string_view verb, std::string_view msg) {
  std::fprintf(stderr, "rcan %.*s: %.*s\n", static_cast<int>(verb.size()), verb.data(),
               static_cast<int>(msg.size()), msg.data());
  return 2;
}

}  // namespace rcan::cli

int main(int argc, char** argv) {
  using namespace rcan::cli;
  if (argc < 2 || std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0 ||
      std::strcmp(argv[1], "help") == 0) {
    print_help();
    return argc < 2 ? 2 : 0;
  }
  if (std::strcmp(argv[1], "--version") == 0) {
    std::printf("rcan %s (RCAN protocol 1.0.0)\n", std::string(rcan::kSoftwareVersion).c_str());
    return 0;
  }
  std::string verb = argv[1];
  Args args(argv + 2, argv + argc);
  // `--help` (or -h) anywhere after the verb — `rcan token issue --help` — prints the verb's
  // usage, which covers its sub-verbs.
  const bool help = std::any_of(args.begin(), args.end(),
                                [](const std::string& a) { return a == "--help" || a == "-h"; });
  for (const auto& v : verbs()) {
    if (v.name == verb) return help ? v.fn(Args{"--help"}) : v.fn(args);
  }
  std::fprintf(stderr, "rcan: unknown verb '%s' (try 'rcan --help')\n", verb.c_str());
  return 2;
}

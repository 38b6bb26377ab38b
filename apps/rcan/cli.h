// The rcan command-line tool: verb registry and shared helpers.
//
// Each verb group lives in its own file and registers itself:
//   static const rcan::cli::Registration kReg{"ruri", "parse and validate RURIs", &ruri_main};
// `rcan <verb> args…` calls the registered function with the arguments after the verb.
// Exit codes: 0 success, 1 negative answer (invalid input, failed verification),
// 2 usage error or malformed input the verb cannot judge.
#pragma once

#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "rcan/result.h"

namespace rcan::cli {

using Args = std::vector<std::string>;
using VerbFn = int (*)(const Args& args);

struct Verb {
  std::string name;
  std::string summary;
  VerbFn fn;
};

struct Registration {
  Registration(std::string name, std::string summary, VerbFn fn);
};

const std::vector<Verb>& verbs();

// Reads all of standard input.
std::string read_stdin();
// Reads a whole file; Error with a message naming the path on failure.
Result<std::string> read_file(const std::string& path);
// "a,b,,c" → {a, b, c}: an option's comma-separated list, empty items dropped.
std::vector<std::string> split_list(const std::string& s);

// Prints the profile's error body (docs/PROTOCOL.md §Errors) for `err` to stdout.
void print_error_body(const Error& err, std::string_view reply_to = {});

// Minimal option parsing: "--name value" and "--flag". Unknown options are errors.
class Options {
 public:
  // `flags` take no value; `valued` take one. Positional arguments are collected.
  Options(const Args& args, const std::vector<std::string>& flags,
          const std::vector<std::string>& valued);
  bool ok() const { return error_.empty(); }
  const std::string& error() const { return error_; }
  bool has(const std::string& name) const;
  std::string get(const std::string& name, const std::string& def = {}) const;
  const std::vector<std::string>& positional() const { return positional_; }

 private:
  std::vector<std::pair<std::string, std::string>> values_;
  std::vector<std::string> positional_;
  std::string error_;
};

// Prints "rcan <verb>: <msg>" to stderr and returns 2.
int usage_error(std::string_view verb, std::string_view msg);

}  // namespace rcan::cli

#include "net_common.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <iostream>

#include "rcan/registry.h"

namespace rcan::cli {

const std::vector<std::string>& net_flags() {
  static const std::vector<std::string> f{"json", "insecure"};
  return f;
}
const std::vector<std::string>& net_valued() {
  static const std::vector<std::string> v{"url", "token-file", "timeout", "ca-file", "registry"};
  return v;
}

const char* const kNetHelp =
    "  Connection: --url URL (default $RCAN_URL, else http://127.0.0.1:8080; https:// for TLS;\n"
    "              an RRN or RURI is resolved through --registry URL, default $RCAN_REGISTRY)\n"
    "              --token-file F (default $RCAN_TOKEN_FILE)  --timeout MS (default 10000)\n"
    "              --ca-file PEM  --insecure (skip TLS verification)  --json (machine output)\n"
    "  Exit: 0 done, 1 refused by the node (its error code is printed), 2 usage,\n"
    "        3 node unreachable, 4 waiting for a human authorization.\n";

client::ClientOptions client_options(const Options& o, bool need_token, std::string& err) {
  client::ClientOptions co;
  std::string url = o.get("url");
  if (url.empty())
    if (const char* env = std::getenv("RCAN_URL"); env && *env) url = env;
  if (url.rfind("rcan://", 0) == 0 || registry::normalize_rrn(url)) {
    auto found = robot_url_from_registry(url, o.get("registry"));
    if (!found.ok()) {
      err = found.error().message;
      return co;
    }
    url = *found;
  }
  if (!url.empty()) co.url = url;
  if (auto ep = client::parse_endpoint(co.url); !ep.ok()) {
    err = ep.error().message;
    return co;
  }
  std::string file = o.get("token-file");
  if (file.empty())
    if (const char* env = std::getenv("RCAN_TOKEN_FILE"); env && *env) file = env;
  if (!file.empty()) {
    auto t = read_file(file);
    if (!t.ok()) {
      err = t.error().message;
      return co;
    }
    std::string s = *t;
    while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == ' ')) s.pop_back();
    co.token = s;
  } else if (need_token) {
    err =
        "a token is required: --token-file F or RCAN_TOKEN_FILE (rcand prints both on its first "
        "run)";
    return co;
  }
  if (o.has("timeout")) {
    char* end = nullptr;
    const std::string value_text = o.get("timeout");  // outlives `end`
    long v = std::strtol(value_text.c_str(), &end, 10);
    if (!end || *end || v < 1 || v > 3600000) {
      err = "--timeout must be milliseconds (1..3600000)";
      return co;
    }
    co.timeout_ms = static_cast<int>(v);
  }
  co.ca_file = o.get("ca-file");
  co.insecure = o.has("insecure");
  return co;
}

bool want_json(const Options& o) { return o.has("json"); }

bool use_colour() {
  static const bool on = ::isatty(STDOUT_FILENO) == 1 && !std::getenv("NO_COLOR") &&
                         std::string(std::getenv("TERM") ? std::getenv("TERM") : "") != "dumb";
  return on;
}

namespace {
std::string style(const char* code, const std::string& s) {
  return use_colour() ? std::string("\x1b[") + code + "m" + s + "\x1b[0m" : s;
}
size_t visible_width(const std::string& s) {
  size_t n = 0;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '\x1b') {
      while (i < s.size() && s[i] != 'm') ++i;
      continue;
    }
    if ((static_cast<unsigned char>(s[i]) & 0xC0) != 0x80) ++n;  // count UTF-8 lead bytes
  }
  return n;
}
}  // namespace

std::string bold(const std::string& s) { return style("1", s); }
std::string red(const std::string& s) { return style("31", s); }
std::string green(const std::string& s) { return style("32", s); }
std::string yellow(const std::string& s) { return style("33", s); }
std::string dim(const std::string& s) { return style("2", s); }

int report_error(const std::string& verb, const client::ClientError& e, bool json) {
  if (json) {
    if (e.body.is_object()) {
      std::cout << json::dump(e.body) << "\n";
    } else {
      json::Object o{{"error_code", e.code},
                     {"error", e.message},
                     {"http_status", static_cast<int64_t>(e.http_status)}};
      std::cout << json::dump(json::Value(std::move(o))) << "\n";
    }
  }
  std::string line = "rcan " + verb + ": ";
  if (e.unreachable()) {
    line += e.message;
  } else {
    line += e.code + " (HTTP " + std::to_string(e.http_status) + "): " + e.message;
    if (!e.reason.empty() && e.message.find(e.reason) == std::string::npos)
      line += " [" + e.reason + "]";
    if (e.retry_after_s > 0) line += " — retry after " + std::to_string(e.retry_after_s) + " s";
  }
  std::fprintf(stderr, "%s\n", line.c_str());
  return e.unreachable() ? kExitUnreachable : kExitRefused;
}

void print_table(const std::vector<std::string>& header,
                 const std::vector<std::vector<std::string>>& rows) {
  std::vector<size_t> w(header.size(), 0);
  for (size_t i = 0; i < header.size(); ++i) w[i] = visible_width(header[i]);
  for (const auto& r : rows)
    for (size_t i = 0; i < r.size() && i < w.size(); ++i)
      w[i] = std::max(w[i], visible_width(r[i]));
  auto line = [&](const std::vector<std::string>& r, bool head) {
    std::string out;
    for (size_t i = 0; i < w.size(); ++i) {
      std::string cell = i < r.size() ? r[i] : "";
      if (head) cell = bold(cell);
      out += cell;
      if (i + 1 < w.size())
        out += std::string(w[i] - visible_width(i < r.size() ? r[i] : "") + 2, ' ');
    }
    while (!out.empty() && out.back() == ' ') out.pop_back();
    std::printf("%s\n", out.c_str());
  };
  line(header, true);
  for (const auto& r : rows) line(r, false);
}

std::string when(int64_t ms) {
  if (ms <= 0) return "-";
  std::time_t t = static_cast<std::time_t>(ms / 1000);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%d %H:%M:%S", &tm);
  char out[48];
  std::snprintf(out, sizeof out, "%s.%03dZ", b, static_cast<int>(ms % 1000));
  return out;
}

std::string brief(const json::Value& v, size_t max) {
  std::string s = v.is_string() ? v.as_string() : (v.is_null() ? "-" : json::dump(v));
  if (s.size() > max) s = s.substr(0, max - 1) + "…";
  return s;
}

bool help_requested(const Args& args, const char* help) {
  for (const auto& a : args)
    if (a == "--help" || a == "-h") {
      std::fputs(help, stdout);
      return true;
    }
  return false;
}

}  // namespace rcan::cli

// rcan estop | resume | status — talk to a running node over HTTP.
// The node's URL comes from --url or $RCAN_URL; the token from --token-file or
// $RCAN_TOKEN_FILE (rcand's first-run message sets both).
#include <arpa/inet.h>
#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>

#include "cli.h"
#include "node_http.h"
#include "rcan/errors.h"
#include "rcan/json.h"

namespace rcan::cli {

Result<Target> parse_url(const std::string& url) {
  std::string rest;
  if (url.rfind("http://", 0) == 0) rest = url.substr(7);
  else return Error(ErrorCode::kSchemaValidationFailed, "the URL must start with http:// (for https use curl for now)");
  if (auto slash = rest.find('/'); slash != std::string::npos) rest = rest.substr(0, slash);
  Target t;
  auto colon = rest.rfind(':');
  t.host = colon == std::string::npos ? rest : rest.substr(0, colon);
  t.port = colon == std::string::npos ? "80" : rest.substr(colon + 1);
  if (t.host.empty()) return Error(ErrorCode::kSchemaValidationFailed, "the URL has no host");
  return t;
}

// One HTTP/1.1 request; returns {status, body}.
Result<std::pair<int, std::string>> request(const Target& t, const std::string& method, const std::string& path,
                                            const std::string& body, const std::string& token) {
  addrinfo hints{}, *res = nullptr;
  hints.ai_socktype = SOCK_STREAM;
  if (getaddrinfo(t.host.c_str(), t.port.c_str(), &hints, &res) != 0 || !res)
    return Error(ErrorCode::kNotFound, "cannot resolve " + t.host);
  int fd = socket(res->ai_family, res->ai_socktype | SOCK_CLOEXEC, res->ai_protocol);
  int rc = fd >= 0 ? connect(fd, res->ai_addr, res->ai_addrlen) : -1;
  freeaddrinfo(res);
  if (rc != 0) {
    if (fd >= 0) close(fd);
    return Error(ErrorCode::kNotFound, "cannot connect to " + t.host + ":" + t.port + " (is rcand running?)");
  }
  std::string req = method + " " + path + " HTTP/1.1\r\nHost: " + t.host + "\r\nConnection: close\r\n";
  if (!token.empty()) req += "Authorization: Bearer " + token + "\r\n";
  req += "Content-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) + "\r\n\r\n" + body;
  if (send(fd, req.data(), req.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(req.size())) {
    close(fd);
    return Error(ErrorCode::kInternal, "send failed");
  }
  std::string resp;
  char buf[65536];
  while (true) {
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, 10000) <= 0) break;
    ssize_t k = recv(fd, buf, sizeof buf, 0);
    if (k <= 0) break;
    resp.append(buf, static_cast<size_t>(k));
  }
  close(fd);
  size_t end = resp.find("\r\n\r\n");
  if (resp.size() < 12 || end == std::string::npos) return Error(ErrorCode::kInternal, "no HTTP answer");
  return std::make_pair(std::atoi(resp.c_str() + 9), resp.substr(end + 4));
}

namespace {

int64_t now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

std::string token_from(const Options& o, bool required, std::string& err) {
  std::string file = o.get("token-file");
  if (file.empty()) {
    const char* env = std::getenv("RCAN_TOKEN_FILE");
    if (env) file = env;
  }
  if (file.empty()) {
    if (required) err = "a token is required: --token-file F or RCAN_TOKEN_FILE";
    return {};
  }
  auto t = read_file(file);
  if (!t.ok()) {
    err = t.error().message;
    return {};
  }
  std::string s = *t;
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == ' ')) s.pop_back();
  return s;
}

namespace {

int run(const char* verb, const Args& args) {
  std::string v = verb;
  if (!args.empty() && (args[0] == "--help" || args[0] == "-h")) {
    std::printf("usage: rcan %s [--url URL] [--token-file F]%s [--json]\n"
                "  URL defaults to $RCAN_URL, the token to $RCAN_TOKEN_FILE.\n"
                "  Exit: 0 done, 1 refused by the node (its error is printed), 2 usage or unreachable.\n",
                verb, v == "estop" ? " [--reason TEXT]" : "");
    return 0;
  }
  Options o(args, {"json"}, {"url", "token-file", "reason"});
  if (!o.ok()) return usage_error(v, o.error());
  if (!o.positional().empty()) return usage_error(v, "unexpected argument " + o.positional()[0]);
  std::string url = o.get("url");
  if (url.empty())
    if (const char* env = std::getenv("RCAN_URL")) url = env;
  if (url.empty()) url = "http://127.0.0.1:8080";
  auto target = parse_url(url);
  if (!target.ok()) return usage_error(v, target.error().message);
  std::string err;
  std::string token = token_from(o, v != "status", err);
  if (!err.empty()) return usage_error(v, err);
  Result<std::pair<int, std::string>> r = Error(ErrorCode::kInternal, "");
  if (v == "estop") {
    json::Object body;
    if (o.has("reason")) body.set("reason", o.get("reason"));
    r = request(*target, "POST", "/api/stop", json::dump(json::Value(body)), token);
  } else if (v == "resume") {
    json::Object m{{"version", "1.0.0"},
                   {"message_id", new_uuid_v4()},
                   {"type", "SAFETY"},
                   {"timestamp_ms", now_ms()},
                   {"payload", json::Object{{"safety_event", "RESUME"}}}};
    r = request(*target, "POST", "/rcan/v1/command", json::dump(json::Value(m)), token);
  } else {
    r = request(*target, "GET", "/rcan/v1/status", "", token);
  }
  if (!r.ok()) {
    std::fprintf(stderr, "rcan %s: %s\n", verb, r.error().message.c_str());
    return 2;
  }
  auto [status, body] = *r;
  if (o.has("json") || status != 200) {
    std::cout << body << "\n";
  } else if (v == "status") {
    auto j = json::parse(body);
    if (j.ok()) {
      auto s = [&](const char* k) {
        const json::Value* f = j->get(k);
        return f ? (f->is_string() ? f->as_string() : json::dump(*f)) : std::string("-");
      };
      std::printf("ruri:    %s\nrrn:     %s\nversion: %s\nestop:   %s\nmode:    %s\nsessions:%s\n", s("ruri").c_str(),
                  s("rrn").c_str(), s("rcan_version").c_str(), s("estop_active").c_str(), s("mode").c_str(),
                  (" " + s("active_sessions")).c_str());
    }
  } else {
    std::printf("%s: done (HTTP %d)\n", verb, status);
  }
  return status == 200 ? 0 : 1;
}

int estop_main(const Args& a) { return run("estop", a); }
int resume_main(const Args& a) { return run("resume", a); }
int status_main(const Args& a) { return run("status", a); }

const Registration kEstop{"estop", "latch ESTOP on a running node (POST /api/stop)", &estop_main};
const Registration kResume{"resume", "clear a latched ESTOP (LEASEE or above)", &resume_main};
const Registration kStatus{"status", "show a running node's status", &status_main};

}  // namespace
std::string node_url(const Options& o) {
  std::string url = o.get("url");
  if (url.empty())
    if (const char* env = std::getenv("RCAN_URL")) url = env;
  return url.empty() ? "http://127.0.0.1:8080" : url;
}

std::string node_token(const Options& o, bool required, std::string& err) { return token_from(o, required, err); }

Result<std::pair<int, std::string>> node_request(const std::string& url, const std::string& method,
                                                 const std::string& path, const std::string& body,
                                                 const std::string& token) {
  auto t = parse_url(url);
  if (!t.ok()) return t.error();
  return request(*t, method, path, body, token);
}

}  // namespace rcan::cli

// registry_bench — resolves per second from a real rcan-registry (docs/REGISTRY.md §Performance).
//
//   registry_bench --registry PATH [--robots N] [--clients C] [--seconds S]
//
// Starts rcan-registry (SQLite, rate limits off) in a temporary data directory, registers N
// robots with the admin key, then C client threads each hold one keep-alive connection and
// send GET /api/v1/resolve/<random registered RRN> for S seconds, checking every answer is 200.
// Prints resolves/s and the latency quantiles. Then the token authority: one client with a
// secret and a grant on the first robot; C threads send POST /oauth/token (client
// credentials, client_secret_post) on keep-alive connections for S seconds: tokens/s.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "bench_support.h"
#include "rcan/json.h"

namespace {

using namespace rcan;
namespace http = boost::beast::http;

struct Args {
  std::string registry;
  int robots = 1000, clients = 64;
  double seconds = 5;
};

int connect_loopback(uint16_t port) {
  int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd);
    return -1;
  }
  int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  return fd;
}

// One request and its answer on a keep-alive connection: the status, 0 on failure.
int exchange(int fd, const std::string& req, std::string& buf) {
  if (::send(fd, req.data(), req.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(req.size()))
    return 0;
  while (true) {
    size_t head = buf.find("\r\n\r\n");
    if (head != std::string::npos) {
      size_t cl = buf.find("Content-Length: ");
      if (cl == std::string::npos || cl > head) cl = buf.find("content-length: ");
      size_t len = cl == std::string::npos || cl > head
                       ? 0
                       : std::strtoul(buf.c_str() + cl + 16, nullptr, 10);
      if (buf.size() >= head + 4 + len) {
        int status = std::atoi(buf.c_str() + 9);
        buf.erase(0, head + 4 + len);
        return status;
      }
    }
    char tmp[16384];
    ssize_t n = ::recv(fd, tmp, sizeof tmp, 0);
    if (n <= 0) return 0;
    buf.append(tmp, static_cast<size_t>(n));
  }
}

struct ClientResult {
  std::vector<double> lat_us;
  uint64_t errors = 0;
};

void client(uint16_t port, const std::vector<std::string>& rrns, int64_t until_us, unsigned seed,
            ClientResult& out) {
  int fd = connect_loopback(port);
  if (fd < 0) {
    ++out.errors;
    return;
  }
  std::mt19937 rng(seed);
  std::uniform_int_distribution<size_t> pick(0, rrns.size() - 1);
  std::string buf;
  while (bench::mono_us() < until_us) {
    std::string req = "GET /api/v1/resolve/" + rrns[pick(rng)] +
                      " HTTP/1.1\r\nHost: 127.0.0.1\r\nAccept: application/json\r\n\r\n";
    int64_t t0 = bench::mono_us();
    int status = exchange(fd, req, buf);
    if (status != 200) {
      ++out.errors;
      if (status == 0) break;
      continue;
    }
    out.lat_us.push_back(static_cast<double>(bench::mono_us() - t0));
  }
  ::close(fd);
}

// POST /oauth/token on one keep-alive connection until `until_us`; every answer must be 200.
void token_client(uint16_t port, const std::string& form, int64_t until_us, ClientResult& out) {
  int fd = connect_loopback(port);
  if (fd < 0) {
    ++out.errors;
    return;
  }
  std::string req =
      "POST /oauth/token HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: "
      "application/x-www-form-urlencoded\r\nContent-Length: " +
      std::to_string(form.size()) + "\r\n\r\n" + form;
  std::string buf;
  while (bench::mono_us() < until_us) {
    int64_t t0 = bench::mono_us();
    int status = exchange(fd, req, buf);
    if (status != 200) {
      ++out.errors;
      if (status == 0) break;
      continue;
    }
    out.lat_us.push_back(static_cast<double>(bench::mono_us() - t0));
  }
  ::close(fd);
}

bool parse(int argc, char** argv, Args& a) {
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string k = argv[i], v = argv[i + 1];
    if (k == "--registry")
      a.registry = v;
    else if (k == "--robots")
      a.robots = std::max(1, std::atoi(v.c_str()));
    else if (k == "--clients")
      a.clients = std::max(1, std::atoi(v.c_str()));
    else if (k == "--seconds")
      a.seconds = std::max(0.1, std::atof(v.c_str()));
    else
      return false;
  }
  return !a.registry.empty();
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  if (!parse(argc, argv, a)) {
    std::fprintf(
        stderr, "usage: registry_bench --registry PATH [--robots N] [--clients C] [--seconds S]\n");
    return 2;
  }
  std::string dir =
      (std::filesystem::temp_directory_path() / ("registry-bench-" + std::to_string(getpid())))
          .string();
  uint16_t port = bench::free_port();
  bench::Child reg({a.registry, "--data-dir", dir, "--port", std::to_string(port), "--write-rate",
                    "0", "--address-write-rate", "0", "--read-rate", "0", "--io-threads", "2"},
                   "listening");
  if (bench::wait_ready(reg, port) < 0) {
    std::fprintf(stderr, "rcan-registry did not start:\n%s\n", reg.head().c_str());
    return 1;
  }
  std::string admin;
  {
    FILE* f = std::fopen((dir + "/admin.key").c_str(), "r");
    char b[256] = {};
    if (f != nullptr) {
      admin.assign(b, std::fread(b, 1, sizeof b - 1, f));
      std::fclose(f);
    }
  }
  std::vector<std::string> rrns;
  int64_t t0 = bench::mono_us();
  for (int i = 0; i < a.robots; ++i) {
    std::string out;
    std::string body =
        R"({"manufacturer":"bench","model":"arm","version":"v1","device_id":"unit-)" +
        std::to_string(i) + R"(","metadata":{"i":)" + std::to_string(i) + "}}";
    int st = bench::sync_http(port, http::verb::post, "/api/v1/robots", body, admin, &out);
    auto v = json::parse(out);
    if (st != 201 || !v.ok() || v->get("rrn") == nullptr) {
      std::fprintf(stderr, "register %d: %d %s\n", i, st, out.c_str());
      return 1;
    }
    rrns.push_back(v->get("rrn")->as_string());
  }
  double reg_s = static_cast<double>(bench::mono_us() - t0) / 1e6;
  std::printf("registered %d robots in %.2f s (%.0f/s, one connection per request)\n", a.robots,
              reg_s, a.robots / reg_s);

  std::vector<ClientResult> results(static_cast<size_t>(a.clients));
  std::vector<std::thread> threads;
  int64_t start = bench::mono_us();
  int64_t until = start + static_cast<int64_t>(a.seconds * 1e6);
  for (int c = 0; c < a.clients; ++c)
    threads.emplace_back(client, port, std::cref(rrns), until, 1234u + static_cast<unsigned>(c),
                         std::ref(results[static_cast<size_t>(c)]));
  for (auto& t : threads) t.join();
  double elapsed = static_cast<double>(bench::mono_us() - start) / 1e6;
  std::vector<double> all;
  uint64_t errors = 0;
  for (auto& r : results) {
    all.insert(all.end(), r.lat_us.begin(), r.lat_us.end());
    errors += r.errors;
  }
  std::sort(all.begin(), all.end());
  bench::ProcStat ps = bench::proc_stat(reg.pid());
  std::printf(
      "resolve: %d clients keep-alive, %.1f s: %zu answers, %.0f resolves/s, p50 %.0f us, "
      "p99 %.0f us, max %.0f us, errors %llu; registry RSS %ld kB, CPU %.1f s\n",
      a.clients, elapsed, all.size(), static_cast<double>(all.size()) / elapsed,
      bench::pct(all, 0.50), bench::pct(all, 0.99), all.empty() ? 0.0 : all.back(),
      static_cast<unsigned long long>(errors), ps.rss_kb, ps.cpu_s);

  // The token authority: client credentials.
  std::string out;
  int st = bench::sync_http(port, http::verb::post, "/api/v1/clients",
                            R"({"name":"bench","auth":"client_secret"})", admin, &out);
  auto cl = json::parse(out);
  if (st != 201 || !cl.ok()) {
    std::fprintf(stderr, "client: %d %s\n", st, out.c_str());
    return 1;
  }
  std::string id = cl->get("client_id")->as_string();
  std::string secret = cl->get("client_secret")->as_string();
  st = bench::sync_http(port, http::verb::post, "/api/v1/grants",
                        R"({"principal":")" + id + R"(","robot":")" + rrns[0] +
                            R"(","role":"user","scope":["status"]})",
                        admin, &out);
  if (st != 201) {
    std::fprintf(stderr, "grant: %d %s\n", st, out.c_str());
    return 1;
  }
  std::string form = "grant_type=client_credentials&client_id=" + id + "&client_secret=" + secret +
                     "&resource=" + rrns[0];
  int token_clients = std::min(a.clients, 16);
  std::vector<ClientResult> tok(static_cast<size_t>(token_clients));
  std::vector<std::thread> tthreads;
  int64_t tstart = bench::mono_us();
  int64_t tuntil = tstart + static_cast<int64_t>(a.seconds * 1e6);
  for (int c = 0; c < token_clients; ++c)
    tthreads.emplace_back(token_client, port, std::cref(form), tuntil,
                          std::ref(tok[static_cast<size_t>(c)]));
  for (auto& t : tthreads) t.join();
  double telapsed = static_cast<double>(bench::mono_us() - tstart) / 1e6;
  std::vector<double> tall;
  uint64_t terrors = 0;
  for (auto& r : tok) {
    tall.insert(tall.end(), r.lat_us.begin(), r.lat_us.end());
    terrors += r.errors;
  }
  std::sort(tall.begin(), tall.end());
  std::printf(
      "token (client credentials, audited): %d clients keep-alive, %.1f s: %zu tokens, %.0f "
      "tokens/s, p50 %.0f us, p99 %.0f us, errors %llu\n",
      token_clients, telapsed, tall.size(), static_cast<double>(tall.size()) / telapsed,
      bench::pct(tall, 0.50), bench::pct(tall, 0.99), static_cast<unsigned long long>(terrors));
  errors += terrors;
  reg.stop();
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  return errors == 0 && !all.empty() ? 0 : 1;
}

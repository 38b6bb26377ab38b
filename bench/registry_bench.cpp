// registry_bench — resolves per second from a real rcan-registry (docs/REGISTRY.md §Performance).
//
//   registry_bench --registry PATH [--robots N] [--clients C] [--seconds S]
//                  [--database SPEC] [--instances K]
//
// Starts K rcan-registry instances (rate limits off) on one database — SQLite in a temporary
// data directory by default; several instances need a PostgreSQL URL (bench/registry_pg_bench.sh
// starts a server) — and registers N robots with the admin key from 8 threads spread over the
// instances. Then the race: 50 more robots, each registered at once through every instance,
// must each get one RRN, and no RRN may be minted twice. Then C client threads (spread over
// the instances) each hold one keep-alive connection and send GET /api/v1/resolve/<random
// registered RRN> for S seconds, checking every answer is 200: resolves/s and the latency
// quantiles. Then the token authority: one client with a secret and a grant on the first
// robot; up to 16 threads send POST /oauth/token (client credentials, client_secret_post)
// for S seconds: tokens/s.
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
#include <memory>
#include <mutex>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "bench_support.h"
#include "rcan/crypto/keys.h"
#include "rcan/crypto/registry_proof.h"
#include "rcan/encoding.h"
#include "rcan/json.h"
#include "rcan/registry.h"

namespace {

using namespace rcan;
namespace http = boost::beast::http;

struct Args {
  std::string registry, database;
  int robots = 1000, clients = 64, instances = 1;
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
    else if (k == "--database")
      a.database = v;
    else if (k == "--instances")
      a.instances = std::clamp(std::atoi(v.c_str()), 1, 8);
    else
      return false;
  }
  return !a.registry.empty() && (a.instances == 1 || a.database.rfind("postgres", 0) == 0);
}

// Registers one robot through `port`; its RRN, or empty (and the answer on stderr).
std::string register_robot(uint16_t port, const std::string& admin, const std::string& device) {
  std::string out;
  std::string body =
      R"({"manufacturer":"bench","model":"arm","version":"v1","device_id":")" + device + R"("})";
  int st = bench::sync_http(port, http::verb::post, "/api/v1/robots", body, admin, &out);
  auto v = json::parse(out);
  if ((st != 201 && st != 200) || !v.ok() || v->get("rrn") == nullptr) {
    std::fprintf(stderr, "register %s: %d %s\n", device.c_str(), st, out.c_str());
    return {};
  }
  return v->get("rrn")->as_string();
}

// Registers a robot as rcand does — fresh identity keys and their proof of possession over the
// registry's challenge, its RURI in metadata — so that the registry issues tokens for it; its RRN,
// or empty.
std::string register_proven_robot(uint16_t port, const std::string& admin) {
  std::string out;
  int st = bench::sync_http(port, http::verb::get, "/api/v1/challenge", "", admin, &out);
  auto ch = json::parse(out);
  auto keys = rcan::keys::generate();
  if (st != 200 || !ch.ok() || !keys.ok()) {
    std::fprintf(stderr, "challenge: %d %s\n", st, out.c_str());
    return {};
  }
  const std::string id = json::string_field(*ch, "challenge_id");
  auto proof =
      rcan::registry::sign_proof(*keys, id,
                                 rcan::registry::proof_message(id, json::string_field(*ch, "nonce"),
                                                               "bench", "arm", "v1", "b0000001"));
  if (!proof.ok()) return {};
  json::Object body{{"manufacturer", "bench"},
                    {"model", "arm"},
                    {"version", "v1"},
                    {"device_id", "b0000001"},
                    {"metadata", json::Object{{"ruri", "rcan://local.rcan/bench/arm/b0000001"}}},
                    {"ed25519_public_key", rcan::base64url_encode(keys->pub.ed25519_pk)},
                    {"mldsa65_public_key", rcan::base64url_encode(keys->pub.mldsa65_pk)},
                    {"proof", proof->to_json()}};
  st = bench::sync_http(port, http::verb::post, "/api/v1/robots",
                        json::dump(json::Value(std::move(body))), admin, &out);
  auto v = json::parse(out);
  if (st != 201 || !v.ok()) {
    std::fprintf(stderr, "register with proof: %d %s\n", st, out.c_str());
    return {};
  }
  return json::string_field(*v, "rrn");
}

// Starts the instances (each with its own data directory under `root`) on a.database.
bool start_instances(const Args& a, const std::string& root,
                     std::vector<std::unique_ptr<bench::Child>>& regs, std::vector<uint16_t>& ports,
                     std::string& admin) {
  for (int i = 0; i < a.instances; ++i) {
    std::string dir = root + "/" + std::to_string(i);
    uint16_t port = bench::free_port();
    std::vector<std::string> cmd{a.registry,
                                 "--data-dir",
                                 dir,
                                 "--port",
                                 std::to_string(port),
                                 "--write-rate",
                                 "0",
                                 "--address-write-rate",
                                 "0",
                                 "--read-rate",
                                 "0",
                                 "--io-threads",
                                 "2"};
    if (!a.database.empty()) {
      cmd.push_back("--database");
      cmd.push_back(a.database);
    }
    regs.push_back(std::make_unique<bench::Child>(cmd, "listening"));
    if (bench::wait_ready(*regs.back(), port) < 0) {
      std::fprintf(stderr, "rcan-registry did not start:\n%s\n", regs.back()->head().c_str());
      return false;
    }
    ports.push_back(port);
    if (i == 0) {
      FILE* f = std::fopen((dir + "/admin.key").c_str(), "r");
      char b[256] = {};
      if (f != nullptr) {
        admin.assign(b, std::fread(b, 1, sizeof b - 1, f));
        std::fclose(f);
      }
    }
  }
  return true;
}

// The race: each of 50 robots registered at once through every instance (2 requests per
// instance). Adds the answers to `distinct`; returns how many robots got more than one RRN.
int race(const std::vector<uint16_t>& ports, const std::string& admin,
         std::set<std::string>& distinct) {
  constexpr int kRace = 50;
  const int instances = static_cast<int>(ports.size());
  std::vector<std::vector<std::string>> answers(kRace);
  std::mutex mu;
  std::vector<std::thread> ts;
  for (int i = 0; i < kRace; ++i)
    for (int k = 0; k < 2 * instances; ++k)
      ts.emplace_back([&, i, k] {
        std::string r = register_robot(ports[static_cast<size_t>(k % instances)], admin,
                                       "race-" + std::to_string(i));
        std::lock_guard<std::mutex> l(mu);
        answers[static_cast<size_t>(i)].push_back(r);
      });
  for (auto& t : ts) t.join();
  int split = 0;
  for (const auto& one_robot : answers) {
    std::set<std::string> one(one_robot.begin(), one_robot.end());
    if (one.size() != 1 || one.begin()->empty()) ++split;
    distinct.insert(one_robot.begin(), one_robot.end());
  }
  return split;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  if (!parse(argc, argv, a)) {
    std::fprintf(
        stderr,
        "usage: registry_bench --registry PATH [--robots N] [--clients C] [--seconds S]\n"
        "                      [--database SPEC] [--instances K (a postgresql:// database)]\n");
    return 2;
  }
  std::string root =
      (std::filesystem::temp_directory_path() / ("registry-bench-" + std::to_string(getpid())))
          .string();
  std::vector<std::unique_ptr<bench::Child>> regs;
  std::vector<uint16_t> ports;
  std::string admin;  // the first instance's admin key (every instance takes it: one database)
  if (!start_instances(a, root, regs, ports, admin)) return 1;
  const uint16_t port = ports[0];
  std::printf("%d instance(s) on %s\n", a.instances,
              a.database.empty() ? "SQLite" : a.database.substr(0, a.database.find(':')).c_str());

  // N robots from 8 threads, spread over the instances.
  std::vector<std::string> rrns(static_cast<size_t>(a.robots));
  std::atomic<int> next{0}, failed{0};
  int64_t t0 = bench::mono_us();
  {
    std::vector<std::thread> ts;
    for (int t = 0; t < 8; ++t)
      ts.emplace_back([&, t] {
        for (int i; (i = next++) < a.robots;) {
          std::string r = register_robot(ports[static_cast<size_t>((i + t) % a.instances)], admin,
                                         "unit-" + std::to_string(i));
          if (r.empty()) ++failed;
          rrns[static_cast<size_t>(i)] = r;
        }
      });
    for (auto& t : ts) t.join();
  }
  double reg_s = static_cast<double>(bench::mono_us() - t0) / 1e6;
  if (failed > 0) return 1;
  std::printf("registered %d robots in %.2f s (%.0f/s, 8 threads, one connection per request)\n",
              a.robots, reg_s, a.robots / reg_s);

  // The race.
  constexpr int kRace = 50;
  std::set<std::string> distinct(rrns.begin(), rrns.end());
  const int race_split = race(ports, admin, distinct);
  const bool unique = distinct.size() == static_cast<size_t>(a.robots + kRace);
  std::printf(
      "race: %d robots each registered by %d concurrent requests over %d instance(s): %d got "
      "more than one RRN; %zu distinct RRNs for %d robots (%s)\n",
      kRace, 2 * a.instances, a.instances, race_split, distinct.size(), a.robots + kRace,
      unique && race_split == 0 ? "no duplicate" : "DUPLICATES");
  if (!unique || race_split != 0) return 1;

  std::vector<ClientResult> results(static_cast<size_t>(a.clients));
  std::vector<std::thread> threads;
  int64_t start = bench::mono_us();
  int64_t until = start + static_cast<int64_t>(a.seconds * 1e6);
  for (int c = 0; c < a.clients; ++c)
    threads.emplace_back(client, ports[static_cast<size_t>(c % a.instances)], std::cref(rrns),
                         until, 1234u + static_cast<unsigned>(c),
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
  long rss_kb = 0;
  double cpu_s = 0;
  for (auto& r : regs) {
    bench::ProcStat ps = bench::proc_stat(r->pid());
    rss_kb += ps.rss_kb;
    cpu_s += ps.cpu_s;
  }
  std::printf(
      "resolve: %d clients keep-alive, %.1f s: %zu answers, %.0f resolves/s, p50 %.0f us, "
      "p99 %.0f us, max %.0f us, errors %llu; registry RSS %ld kB, CPU %.1f s (all instances)\n",
      a.clients, elapsed, all.size(), static_cast<double>(all.size()) / elapsed,
      bench::pct(all, 0.50), bench::pct(all, 0.99), all.empty() ? 0.0 : all.back(),
      static_cast<unsigned long long>(errors), rss_kb, cpu_s);

  // The token authority: client credentials, for a robot that proved its keys (the registry
  // issues no robot token for a record that did not).
  const std::string proven = register_proven_robot(port, admin);
  if (proven.empty()) return 1;
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
                        R"({"principal":")" + id + R"(","robot":")" + proven +
                            R"(","role":"user","scope":["status"]})",
                        admin, &out);
  if (st != 201) {
    std::fprintf(stderr, "grant: %d %s\n", st, out.c_str());
    return 1;
  }
  std::string form = "grant_type=client_credentials&client_id=" + id + "&client_secret=" + secret +
                     "&resource=" + proven;
  int token_clients = std::min(a.clients, 16);
  std::vector<ClientResult> tok(static_cast<size_t>(token_clients));
  std::vector<std::thread> tthreads;
  int64_t tstart = bench::mono_us();
  int64_t tuntil = tstart + static_cast<int64_t>(a.seconds * 1e6);
  for (int c = 0; c < token_clients; ++c)
    tthreads.emplace_back(token_client, ports[static_cast<size_t>(c % a.instances)],
                          std::cref(form), tuntil, std::ref(tok[static_cast<size_t>(c)]));
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
  for (auto& r : regs) r->stop();
  std::error_code ec;
  std::filesystem::remove_all(root, ec);
  return errors == 0 && !all.empty() ? 0 : 1;
}

// This node's `node` block and its listeners: `server` (HTTP and WebSocket, or the
// OpenCastor rcan_protocol.port), `grpc` and `udp` (docs/CONFIG.md §node and server, §grpc
// and udp), and `dashboard` (§dashboard).
#include <regex>
#include <set>

#include "config/blocks/blocks.h"
#include "runtime/http_client.h"

namespace rcan::config::internal {
namespace {

using R = Rows<NodeConfig>;

bool host_ok(const std::string& bind) {
  static const std::regex bind_re(R"(^[A-Za-z0-9.:_-]{1,255}$)");
  return std::regex_match(bind, bind_re);
}

Table<NodeConfig> node_rows() {
  return {
      R::read("data_dir", Str(),
              [](const At& dd, NodeConfig& c, Ctx& x) {
                if (dd) {
                  if (dd.str().empty()) fail(dd.path, "must not be empty", "invalid_value");
                  c.data_dir = resolve_path(dd.str(), x.opts.base_dir);
                } else if (!x.opts.default_data_dir.empty()) {
                  c.data_dir = x.opts.default_data_dir;
                } else {
                  Result<std::string> d = default_data_dir();
                  if (!d.ok()) fail("node.data_dir", d.error().message, "missing_key");
                  c.data_dir = *d;
                }
              })
          .default_text("`default_data_dir()`: `$RCAND_DATA_DIR`, else `$XDG_DATA_HOME/rcand` "
                        "(absolute only), else `$HOME/.local/share/rcand`, else the passwd home")
          .doc("the node's state: keys, audit log, latch file, tokens; `--data-dir` overrides"),
      R::field("log_level", Enum({"trace", "debug", "info", "warn", "error"}),
               &NodeConfig::log_level)
          .doc("the log's threshold"),
  };
}

// server.tls and grpc.tls: the certificate and key are required when enabled.
Table<TlsConfig> tls_rows() {
  using T = Rows<TlsConfig>;
  return {
      T::field("enabled", Bool(), &TlsConfig::enabled).doc("TLS on this listener"),
      T::path("cert_file", Str(), &TlsConfig::cert_file)
          .doc("PEM certificate chain; required when `enabled`"),
      T::path("key_file", Str(), &TlsConfig::key_file)
          .doc("PEM private key; required when `enabled`"),
      T::check([](const At& tls, TlsConfig& t, Ctx&) {
        if (t.enabled && t.cert_file.empty())
          fail(tls["cert_file"].path, "required when tls.enabled is true", "missing_key");
        if (t.enabled && t.key_file.empty())
          fail(tls["key_file"].path, "required when tls.enabled is true", "missing_key");
      }),
  };
}

Table<ServerLimits> limits_rows() {
  using L = Rows<ServerLimits>;
  return {
      L::field("max_body_bytes", Int(1024, 64 << 20), &ServerLimits::max_body_bytes)
          .doc("the largest request body (and WebSocket and gRPC message)"),
      L::field("max_header_bytes", Int(1024, 1 << 20), &ServerLimits::max_header_bytes)
          .doc("the largest request header"),
      L::field("read_timeout_ms", Int(100, 600'000), &ServerLimits::read_timeout_ms)
          .doc("how long a request may take to arrive"),
      L::field("idle_timeout_ms", Int(100, 86'400'000), &ServerLimits::idle_timeout_ms)
          .doc("keep-alive wait of an authenticated connection"),
      L::field("max_connections", Int(1, 1'000'000), &ServerLimits::max_connections)
          .doc("connections open at once"),
      L::field("max_connections_per_address", Int(0, 1'000'000),
               &ServerLimits::max_connections_per_address)
          .doc("connections open at once from one IP address (loopback included), 0: no limit; the "
               "next closes the oldest of them that has not authenticated and waits for a request, "
               "else takes the reserve (a stop only), else is answered 503 "
               "`too_many_connections_from_address` (docs/TRANSPORT.md §Connection limits). Behind "
               "a reverse proxy every client has the proxy's address: raise it, or set 0 and limit "
               "in the proxy"),
      L::field("reserved_connections", Int(0, 1024), &ServerLimits::reserved_connections)
          .doc("connections accepted over `max_connections` (or over "
               "`max_connections_per_address`) when no idle connection without a credential can be "
               "closed, that may carry only a stop (`POST /api/stop`, or a stream that sends "
               "SAFETY messages); at most 2 per address"),
      L::field("unauthenticated_idle_timeout_ms", Int(100, 86'400'000),
               &ServerLimits::unauthenticated_idle_timeout_ms)
          .doc(
              "keep-alive wait of a connection that has not yet presented a valid credential (then "
              "`idle_timeout_ms`); also the deadline for the one request of a reserve connection"),
  };
}

Table<ServerConfig> server_rows() {
  using S = Rows<ServerConfig>;
  return {
      S::read("port", Int(1, 65535),
              [](const At& a, ServerConfig& s, Ctx& x) {
                At proto = x.root["rcan_protocol"]["port"];
                same_or_fail(a, a.u32(0), proto, proto.u32(0));
                if (At p = a ? a : proto) assign(p, s.port);
              })
          .default_of(&ServerConfig::port)
          .doc("the HTTP and WebSocket port (seed, PROFILE §10; the OpenCastor schema's 8000 is "
               "not used); alias `rcan_protocol.port` (both, different: error); `--port` "
               "overrides (`--port 0`: any free port)"),
      S::read("bind", Str(256),
              [](const At& a, ServerConfig& s, Ctx&) {
                if (a) s.bind_address = a.str();
                if (!host_ok(s.bind_address))
                  fail(a.path,
                       "expected an IP address or host name, got \"" + printable(s.bind_address) +
                           "\"",
                       "invalid_value");
              })
          .default_of(&ServerConfig::bind_address)
          .doc("IP address or host name to listen on; `0.0.0.0` to expose the node (below)"),
      S::field("io_threads", Int(1, 64), &ServerConfig::io_threads)
          .doc("threads serving the listeners"),
      S::read("enable_mdns", Bool(),
              [](const At& a, ServerConfig& s, Ctx& x) {
                At proto = x.root["rcan_protocol"]["enable_mdns"];
                same_or_fail(a, a.flag(false), proto, proto.flag(false));
                s.enable_mdns = a ? a.flag(false) : proto.flag(false);
              })
          .default_of(&ServerConfig::enable_mdns)
          .doc("advertise `_rcan._tcp` through Avahi (docs/NODE.md §Discovery; the embedded "
               "simulator: true); alias `rcan_protocol.enable_mdns`"),
      S::block("tls", tls_rows(), &ServerConfig::tls),
      S::block("limits", limits_rows(), &ServerConfig::limits),
  };
}

Table<GrpcConfig> grpc_rows() {
  using G = Rows<GrpcConfig>;
  // grpc.tls: server.tls's keys (into GrpcConfig::tls) and the client CA.
  Table<GrpcConfig> tls = lift(tls_rows(), &GrpcConfig::tls);
  tls.push_back(G::path("client_ca_file", Str(), &GrpcConfig::client_ca_file)
                    .doc("PEM path; needs `tls.enabled`: clients must present a certificate signed "
                         "by it (the bearer token is still required)"));
  tls.push_back(G::check([](const At& t, GrpcConfig& g, Ctx&) {
    if (!g.tls.enabled && !g.client_ca_file.empty())
      fail(t["client_ca_file"].path, "needs tls.enabled: true", "invalid_value");
  }));
  return {
      G::field("enabled", Bool(), &GrpcConfig::enabled)
          .doc("the gRPC listener (docs/TRANSPORT.md §gRPC)"),
      G::field("port", Int(0, 65535), &GrpcConfig::port)
          .doc("0: any free port (logged as `grpc.listening`); must differ from `server.port`"),
      G::read("bind", Str(256),
              [](const At& a, GrpcConfig& g, Ctx&) {
                if (a) g.bind_address = a.str();
                if (!host_ok(g.bind_address))
                  fail(a.path, "expected an IP address or host name", "invalid_value");
              })
          .default_of(&GrpcConfig::bind_address)
          .doc("IP address or host name to listen on"),
      G::field("max_streams", Int(1, 100'000), &GrpcConfig::max_streams)
          .doc("open `Stream` calls at once"),
      G::path("module", Str(), &GrpcConfig::module)
          .doc("path of the gRPC module `librcand_grpc.so` (relative: to the config file's "
               "directory); loaded only when `grpc.enabled` (docs/TRANSPORT.md §The gRPC module); "
               "empty: beside `rcand`, then `../lib/rcan/`"),
      G::block("tls", std::move(tls)),
  };
}

Table<UdpConfig> udp_rows() {
  using U = Rows<UdpConfig>;
  return {
      U::field("enabled", Bool(), &UdpConfig::enabled)
          .doc("the UDP listener (docs/TRANSPORT.md §UDP); on with both `heartbeat` and "
               "`discovery` off is an error"),
      U::field("port", Int(0, 65535), &UdpConfig::port)
          .doc("0: any free port (logged as `udp.listening`)"),
      U::read("bind", Str(256),
              [](const At& a, UdpConfig& u, Ctx&) {
                if (a) u.bind_address = a.str();
                if (!host_ok(u.bind_address))
                  fail(a.path, "expected an IP address", "invalid_value");
              })
          .default_of(&UdpConfig::bind_address)
          .doc("IP address; `0.0.0.0` to hear broadcast DISCOVERs"),
      U::field("heartbeat", Bool(), &UdpConfig::heartbeat)
          .doc("per-session keys in GRANTED, HEARTBEAT datagrams"),
      U::field("discovery", Bool(), &UdpConfig::discovery).doc("DISCOVER answered by ANNOUNCE"),
      U::field("discovery_per_source_per_min", Int(1, 6000),
               &UdpConfig::discovery_per_source_per_min)
          .doc("answers per source address per minute (burst up to 5)"),
      U::check([](const At& udp, UdpConfig& u, Ctx&) {
        if (u.enabled && !u.heartbeat && !u.discovery)
          fail(udp["enabled"].path, "udp is enabled but both heartbeat and discovery are off",
               "invalid_value");
      }),
  };
}

Table<DashboardConfig> dashboard_rows() {
  using D = Rows<DashboardConfig>;
  return {
      D::read("robots", Arr(Str(512), 64),
              [](const At& a, DashboardConfig& d, Ctx&) {
                d.robots = a.strs();
                std::set<std::string> seen;
                for (size_t i = 0; i < d.robots.size(); ++i) {
                  auto u = parse_web_url(d.robots[i]);
                  if (!u.ok() || u->path != "/")
                    fail(a[i].path,
                         "expected http://host[:port] or https://host[:port] (no path), got \"" +
                             printable(d.robots[i]) + "\"",
                         "invalid_value");
                  if (!seen.insert(d.robots[i]).second)
                    fail(a[i].path, "listed twice", "invalid_value");
                }
              })
          .default_of(&DashboardConfig::robots)
          .doc("the other nodes, at most 64 `http://host[:port]` or `https://host[:port]` (no "
               "path, none twice)"),
      D::path("ca_file", Str(), &DashboardConfig::ca_file)
          .doc("PEM path: the CA for `https://` robots; empty: the system's trust anchors"),
      D::field("mdns", Bool(), &DashboardConfig::mdns)
          .doc("also list the rcand nodes announcing `_rcan._tcp` on this node's networks (through "
               "Avahi, IPv4); listed with their state and a link, never sent a stop or a token"),
      D::field("poll_ms", Int(250, 600'000), &DashboardConfig::poll_ms)
          .doc("how often each robot's `GET /api/discovery` is read"),
      D::field("stop_timeout_ms", Int(100, 60'000), &DashboardConfig::stop_timeout_ms)
          .doc("how long a relayed ESTOP waits for a robot's answer"),
  };
}

}  // namespace

Table<NodeConfig> server_blocks() {
  return {
      R::block("node", node_rows()),
      R::block("server", server_rows(), &NodeConfig::server),
      R::block("grpc", grpc_rows(), &NodeConfig::grpc),
      R::block("udp", udp_rows(), &NodeConfig::udp),
      R::block("dashboard", dashboard_rows(), &NodeConfig::dashboard),
      R::check([](const At& root, NodeConfig& c, Ctx&) {
        if (c.grpc.enabled && c.grpc.port != 0 && c.grpc.port == c.server.port)
          fail(root["grpc"]["port"].path,
               "must differ from server.port (" + std::to_string(c.server.port) + ")",
               "invalid_value");
      }),
  };
}

}  // namespace rcan::config::internal

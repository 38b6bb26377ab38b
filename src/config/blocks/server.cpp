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
              }),
      R::field("log_level", Enum({"trace", "debug", "info", "warn", "error"}),
               &NodeConfig::log_level),
  };
}

// server.tls and grpc.tls: the certificate and key are required when enabled.
Table<TlsConfig> tls_rows() {
  using T = Rows<TlsConfig>;
  return {
      T::field("enabled", Bool(), &TlsConfig::enabled),
      T::path("cert_file", Str(), &TlsConfig::cert_file),
      T::path("key_file", Str(), &TlsConfig::key_file),
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
      L::field("max_body_bytes", Int(1024, 64 << 20), &ServerLimits::max_body_bytes),
      L::field("max_header_bytes", Int(1024, 1 << 20), &ServerLimits::max_header_bytes),
      L::field("read_timeout_ms", Int(100, 600'000), &ServerLimits::read_timeout_ms),
      L::field("idle_timeout_ms", Int(100, 86'400'000), &ServerLimits::idle_timeout_ms),
      L::field("max_connections", Int(1, 1'000'000), &ServerLimits::max_connections),
      L::field("max_connections_per_address", Int(0, 1'000'000),
               &ServerLimits::max_connections_per_address),
      L::field("reserved_connections", Int(0, 1024), &ServerLimits::reserved_connections),
      L::field("unauthenticated_idle_timeout_ms", Int(100, 86'400'000),
               &ServerLimits::unauthenticated_idle_timeout_ms),
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
              }),
      S::read("bind", Str(256),
              [](const At& a, ServerConfig& s, Ctx&) {
                if (a) s.bind_address = a.str();
                if (!host_ok(s.bind_address))
                  fail(a.path,
                       "expected an IP address or host name, got \"" + printable(s.bind_address) +
                           "\"",
                       "invalid_value");
              }),
      S::field("io_threads", Int(1, 64), &ServerConfig::io_threads),
      S::read("enable_mdns", Bool(),
              [](const At& a, ServerConfig& s, Ctx& x) {
                At proto = x.root["rcan_protocol"]["enable_mdns"];
                same_or_fail(a, a.flag(false), proto, proto.flag(false));
                s.enable_mdns = a ? a.flag(false) : proto.flag(false);
              }),
      S::block("tls", tls_rows(), &ServerConfig::tls),
      S::block("limits", limits_rows(), &ServerConfig::limits),
  };
}

Table<GrpcConfig> grpc_rows() {
  using G = Rows<GrpcConfig>;
  // grpc.tls: server.tls's keys (into GrpcConfig::tls) and the client CA.
  Table<GrpcConfig> tls = lift(tls_rows(), &GrpcConfig::tls);
  tls.push_back(G::path("client_ca_file", Str(), &GrpcConfig::client_ca_file));
  tls.push_back(G::check([](const At& t, GrpcConfig& g, Ctx&) {
    if (!g.tls.enabled && !g.client_ca_file.empty())
      fail(t["client_ca_file"].path, "needs tls.enabled: true", "invalid_value");
  }));
  return {
      G::field("enabled", Bool(), &GrpcConfig::enabled),
      G::field("port", Int(0, 65535), &GrpcConfig::port),
      G::read("bind", Str(256),
              [](const At& a, GrpcConfig& g, Ctx&) {
                if (a) g.bind_address = a.str();
                if (!host_ok(g.bind_address))
                  fail(a.path, "expected an IP address or host name", "invalid_value");
              }),
      G::field("max_streams", Int(1, 100'000), &GrpcConfig::max_streams),
      G::path("module", Str(), &GrpcConfig::module),
      G::block("tls", std::move(tls)),
  };
}

Table<UdpConfig> udp_rows() {
  using U = Rows<UdpConfig>;
  return {
      U::field("enabled", Bool(), &UdpConfig::enabled),
      U::field("port", Int(0, 65535), &UdpConfig::port),
      U::read("bind", Str(256),
              [](const At& a, UdpConfig& u, Ctx&) {
                if (a) u.bind_address = a.str();
                if (!host_ok(u.bind_address))
                  fail(a.path, "expected an IP address", "invalid_value");
              }),
      U::field("heartbeat", Bool(), &UdpConfig::heartbeat),
      U::field("discovery", Bool(), &UdpConfig::discovery),
      U::field("discovery_per_source_per_min", Int(1, 6000),
               &UdpConfig::discovery_per_source_per_min),
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
              }),
      D::path("ca_file", Str(), &DashboardConfig::ca_file),
      D::field("mdns", Bool(), &DashboardConfig::mdns),
      D::field("poll_ms", Int(250, 600'000), &DashboardConfig::poll_ms),
      D::field("stop_timeout_ms", Int(100, 60'000), &DashboardConfig::stop_timeout_ms),
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

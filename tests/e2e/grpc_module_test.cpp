// The gRPC transport as a loadable module (docs/TRANSPORT.md §The gRPC module): a node without
// gRPC maps neither gRPC, protobuf, absl nor the module (nor Avahi/D-Bus without a system bus);
// a node with gRPC loads librcand_grpc.so from beside rcand; a missing or broken module is a
// clear start-up error naming what was tried.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "configured_node.h"
#include "rcan/crypto/ed25519.h"
#include "rcand_daemon.h"
#include "test_support.h"

namespace rcan {
namespace {

namespace fs = std::filesystem;

std::string maps_of(pid_t pid) { return test::read_file("/proc/" + std::to_string(pid) + "/maps"); }

// A configured robot whose `grpc` block is `grpc_yaml`, run by `rcand`; returns its exit code
// and stderr (it is expected to refuse to start).
struct StartResult {
  int exit_code = -1;
  std::string err;
};
StartResult start_configured(const test::TempDir& dir, const std::string& rcand,
                             const std::string& grpc_yaml) {
  std::string data = dir.file("data");
  fs::create_directories(data);
  EXPECT_EQ(test::run_cli({"keys", "generate", "--dir", data + "/keys"}).exit_code, 0);
  EXPECT_EQ(test::run_cli({"audit", "new-secret", "--out", data + "/audit.secret"}).exit_code, 0);
  Bytes seed = ed25519::random_seed();
  auto pk = ed25519::public_key_from_seed(seed);
  EXPECT_TRUE(pk.ok());
  auto pem = ed25519::public_key_to_pem(*pk);
  EXPECT_TRUE(pem.ok());
  std::ofstream(dir.file("issuer.pub.pem")) << *pem;
  std::string cfg = dir.file("robot.rcan.yaml");
  std::ofstream(cfg)
      << "rcan_version: \"1.2\"\nruri: rcan://local.rcan/acme/rover/0a1b2c3d\n"
      << "robot:\n  name: test-rover\n  manufacturer: acme\n  model: rover\n  type: mobile\n"
      << "security:\n  jwt:\n    issuers:\n      - issuer: test.local\n        key_file: "
      << dir.file("issuer.pub.pem") << "\n"
      << grpc_yaml;
  test::RunResult r = test::run({rcand, "--config", cfg, "--port", "0", "--data-dir", data});
  return {r.exit_code, r.err};
}

TEST(GrpcModule, NodeWithoutGrpcMapsNoGrpcProtobufAbslAvahiOrDbus) {
  test::TempDir dir;
  // No D-Bus system bus: mDNS (on in the embedded default) reports itself unavailable and
  // Avahi is never loaded.
  test::RcandDaemon d(dir.path() + "/node", {},
                      {"DBUS_SYSTEM_BUS_ADDRESS=unix:path=" + dir.path() + "/no-bus"});
  ASSERT_NE(d.port(), 0);
  EXPECT_EQ(test::http(d.port(), "GET", "/healthz").status, 200);
  std::string maps = maps_of(d.proc().pid());
  ASSERT_NE(maps.find("libcrypto"), std::string::npos) << maps;  // the maps are the node's
  for (const char* lib :
       {"librcand_grpc", "libgrpc", "libprotobuf", "libabsl", "libupb", "libavahi", "libdbus"})
    EXPECT_EQ(maps.find(lib), std::string::npos) << lib << " is mapped:\n" << maps;
  d.proc().drain(200);
  EXPECT_NE(d.proc().err().find("no D-Bus system bus"), std::string::npos) << d.proc().err();
}

TEST(GrpcModule, EnabledGrpcLoadsTheModuleFromBesideRcand) {
  test::ConfiguredNode node;  // gRPC on, port 0
  ASSERT_NE(node.grpc_port(), 0) << node.proc().err();
  std::string maps = maps_of(node.proc().pid());
  std::string module = (fs::path(RCAND_PATH).parent_path() / "librcand_grpc.so").string();
  EXPECT_NE(maps.find(fs::canonical(module).string()), std::string::npos) << maps;
  EXPECT_NE(maps.find("libgrpc"), std::string::npos) << maps;
}

TEST(GrpcModule, MissingModuleIsAClearStartupError) {
  // An rcand with no module beside it (nor in ../lib/rcan).
  test::TempDir dir;
  fs::create_directories(dir.file("bin"));
  std::string rcand = dir.file("bin/rcand");
  fs::copy_file(RCAND_PATH, rcand);
  fs::permissions(rcand, fs::perms::owner_all);
  StartResult r = start_configured(dir, rcand, "grpc:\n  enabled: true\n  port: 0\n");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("grpc.enabled is true but the gRPC module librcand_grpc.so was not found"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find(dir.file("bin/librcand_grpc.so")), std::string::npos) << r.err;

  // The same rcand without gRPC starts (and is stopped at once).
  test::TempDir dir2;
  test::Process p;
  ASSERT_TRUE(p.start({rcand, "--data-dir", dir2.file("node"), "--port", "0"}));
  EXPECT_TRUE(p.wait_for_line("\"event\":\"listening\"", 30000).has_value()) << p.err();
  p.stop(SIGTERM, 10000);
}

TEST(GrpcModule, ConfiguredModulePathIsUsedAndABadOneRefused) {
  test::TempDir dir;
  StartResult missing = start_configured(
      dir, RCAND_PATH,
      "grpc:\n  enabled: true\n  port: 0\n  module: " + dir.file("none.so") + "\n");
  EXPECT_EQ(missing.exit_code, 1) << missing.err;
  EXPECT_NE(missing.err.find("was not found (looked in: " + dir.file("none.so") + ")"),
            std::string::npos)
      << missing.err;

  test::TempDir dir2;
  std::ofstream(dir2.file("junk.so")) << "not a shared object\n";
  StartResult junk = start_configured(
      dir2, RCAND_PATH,
      "grpc:\n  enabled: true\n  port: 0\n  module: " + dir2.file("junk.so") + "\n");
  EXPECT_EQ(junk.exit_code, 1) << junk.err;
  EXPECT_NE(junk.err.find("cannot load the gRPC module " + dir2.file("junk.so")), std::string::npos)
      << junk.err;

  // A shared library that is not an rcand module: libc (this test's own, from its maps).
  std::string self_maps = maps_of(::getpid());
  size_t at = self_maps.find("libc.so.6");
  ASSERT_NE(at, std::string::npos);
  size_t from = self_maps.rfind(' ', at) + 1;
  std::string libc = self_maps.substr(from, self_maps.find('\n', at) - from);
  test::TempDir dir3;
  StartResult foreign = start_configured(
      dir3, RCAND_PATH, "grpc:\n  enabled: true\n  port: 0\n  module: " + libc + "\n");
  EXPECT_EQ(foreign.exit_code, 1) << foreign.err;
  EXPECT_NE(foreign.err.find("is not an rcand gRPC module"), std::string::npos) << foreign.err;
}

}  // namespace
}  // namespace rcan

// librcand_grpc.so's entry point (grpc_module.h): wraps GrpcServer in the GrpcTransport interface.
#include "node/bindings/grpc_module.h"

#include <memory>
#include <new>

namespace rcan::node {
namespace {

class ModuleTransport final : public GrpcTransport {
 public:
  ModuleTransport(GrpcOptions opt, Node& node) : server_(std::move(opt), node) {}
  Result<uint16_t> start() override { return server_.start(); }
  void stop(int drain_ms) override { server_.stop(drain_ms); }
  GrpcStats stats() const override { return server_.stats(); }

 private:
  GrpcServer server_;
};

}  // namespace
}  // namespace rcan::node

extern "C" __attribute__((visibility("default"))) rcan::node::GrpcTransport*
rcan_grpc_module_create(int abi, const rcan::node::GrpcOptions* opt, rcan::node::Node* node) {
  if (abi != rcan::node::kGrpcModuleAbi || !opt || !node) return nullptr;
  return new (std::nothrow) rcan::node::ModuleTransport(*opt, *node);
}

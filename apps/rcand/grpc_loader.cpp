#include "grpc_loader.h"

#include <dlfcn.h>
#include <unistd.h>

#include <filesystem>

#include "rcan/errors.h"
#include "runtime/log.h"

namespace rcan::rcand {

namespace fs = std::filesystem;

std::vector<std::string> grpc_module_candidates(const std::string& configured) {
  if (!configured.empty()) return {configured};
  std::vector<std::string> out;
  std::error_code ec;
  fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec && exe.has_parent_path()) {
    fs::path dir = exe.parent_path();
    out.push_back((dir / kGrpcModuleFile).string());
    out.push_back(
        (dir.parent_path() / "lib" / "rcan" / kGrpcModuleFile).lexically_normal().string());
  }
  return out;
}

Result<std::unique_ptr<node::GrpcTransport>> load_grpc_transport(const std::string& configured,
                                                                 const node::GrpcOptions& opt,
                                                                 node::Node& node) {
  std::vector<std::string> candidates = grpc_module_candidates(configured);
  std::string tried;
  for (const std::string& path : candidates) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) {
      tried += (tried.empty() ? "" : ", ") + path;
      continue;
    }
    // Never closed: gRPC's threads and globals live until the process ends.
    void* handle = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
      const char* why = ::dlerror();
      return Error(ErrorCode::kInternal,
                   "cannot load the gRPC module " + path + ": " + (why ? why : "dlopen failed"));
    }
    auto create = reinterpret_cast<RcanGrpcModuleCreate>(::dlsym(handle, RCAN_GRPC_MODULE_ENTRY));
    if (!create)
      return Error(ErrorCode::kInternal,
                   path + " is not an rcand gRPC module (no " RCAN_GRPC_MODULE_ENTRY ")");
    node::GrpcTransport* t = create(node::kGrpcModuleAbi, &opt, &node);
    if (!t)
      return Error(ErrorCode::kInternal, "the gRPC module " + path +
                                             " was built for another rcand (ABI " +
                                             std::to_string(node::kGrpcModuleAbi) + " expected)");
    rcan::log(rcan::LogLevel::kDebug, "grpc.module", json::Object{{"path", path}});
    return std::unique_ptr<node::GrpcTransport>(t);
  }
  return Error(ErrorCode::kInternal,
               "grpc.enabled is true but the gRPC module " + std::string(kGrpcModuleFile) +
                   " was not found (looked in: " + (tried.empty() ? "nowhere" : tried) +
                   "); build the rcand_grpc target, install it beside rcand, or set grpc.module");
}

}  // namespace rcan::rcand

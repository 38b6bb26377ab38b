// Loading the gRPC transport module (librcand_grpc.so, src/node/bindings/grpc_module.h) on demand:
// rcand maps gRPC, protobuf and absl only when the config enables gRPC. docs/TRANSPORT.md.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "node/bindings/grpc_module.h"
#include "rcan/result.h"

namespace rcan::rcand {

inline constexpr const char* kGrpcModuleFile = "librcand_grpc.so";

// Where the module is looked for, in order: `configured` (grpc.module) alone when it is set;
// otherwise beside the executable (/proc/self/exe), then ../lib/rcan/ relative to it.
std::vector<std::string> grpc_module_candidates(const std::string& configured);

// dlopen()s the first candidate that exists and creates a transport. Errors (INTERNAL) name
// the paths tried, or the loader's message (missing library, wrong ABI version).
Result<std::unique_ptr<node::GrpcTransport>> load_grpc_transport(const std::string& configured,
                                                                 const node::GrpcOptions& opt,
                                                                 node::Node& node);

}  // namespace rcan::rcand

# Code generation for proto/rcan.proto and the rcan_grpc library.
find_package(PkgConfig REQUIRED)
pkg_check_modules(GRPCPP REQUIRED IMPORTED_TARGET grpc++ protobuf)
find_program(RCAN_PROTOC protoc REQUIRED)
find_program(RCAN_GRPC_CPP_PLUGIN grpc_cpp_plugin REQUIRED)

set(RCAN_PROTO_DIR ${PROJECT_SOURCE_DIR}/proto)
set(RCAN_PROTO_GEN ${PROJECT_BINARY_DIR}/gen)
set(RCAN_PROTO_OUT
  ${RCAN_PROTO_GEN}/rcan.pb.cc ${RCAN_PROTO_GEN}/rcan.pb.h
  ${RCAN_PROTO_GEN}/rcan.grpc.pb.cc ${RCAN_PROTO_GEN}/rcan.grpc.pb.h)
add_custom_command(
  OUTPUT ${RCAN_PROTO_OUT}
  COMMAND ${CMAKE_COMMAND} -E make_directory ${RCAN_PROTO_GEN}
  COMMAND ${RCAN_PROTOC} -I ${RCAN_PROTO_DIR} --cpp_out=${RCAN_PROTO_GEN}
          --grpc_out=${RCAN_PROTO_GEN} --plugin=protoc-gen-grpc=${RCAN_GRPC_CPP_PLUGIN}
          ${RCAN_PROTO_DIR}/rcan.proto
  DEPENDS ${RCAN_PROTO_DIR}/rcan.proto
  COMMENT "protoc: proto/rcan.proto"
  VERBATIM)

# Generated code: compiled once, without the project's warning flags; position-independent,
# since it also goes into the loadable module below.
add_library(rcan_proto STATIC ${RCAN_PROTO_GEN}/rcan.pb.cc ${RCAN_PROTO_GEN}/rcan.grpc.pb.cc)
set_target_properties(rcan_proto PROPERTIES POSITION_INDEPENDENT_CODE ON)
target_include_directories(rcan_proto SYSTEM PUBLIC ${RCAN_PROTO_GEN})
target_link_libraries(rcan_proto PUBLIC PkgConfig::GRPCPP)

# The message conversion (src/transport/grpc_convert.cpp) and the node's gRPC binding
# (src/node/bindings/grpc_*.cpp), compiled once (PIC) for two consumers.
set(RCAN_GRPC_SOURCES ${PROJECT_SOURCE_DIR}/src/transport/grpc_convert.cpp
    ${PROJECT_SOURCE_DIR}/src/node/bindings/grpc_module.cpp ${PROJECT_SOURCE_DIR}/src/node/bindings/grpc_server.cpp)
add_library(rcan_grpc_objects OBJECT ${RCAN_GRPC_SOURCES})
set_target_properties(rcan_grpc_objects PROPERTIES POSITION_INDEPENDENT_CODE ON)
target_link_libraries(rcan_grpc_objects PUBLIC rcan_proto PRIVATE rcan_node_bindings rcan_node_api rcan_node_services rcan_transport rcan_warnings)

# rcan_grpc: the gRPC transport linked statically with the node (the gRPC tests and fuzz target).
add_library(rcan_grpc STATIC $<TARGET_OBJECTS:rcan_grpc_objects>)
target_link_libraries(rcan_grpc PUBLIC rcan_node_bindings rcan_node_api rcan_node_services rcan_transport rcan_proto)

# librcand_grpc.so: the gRPC transport as the module rcand dlopen()s when grpc.enabled is true
# (src/node/bindings/grpc_module.h, apps/rcand/grpc_loader.cpp). It links gRPC and protobuf but not
# the node: Node, json, logs… resolve against the rcand executable (ENABLE_EXPORTS). Placed
# beside rcand; installed into lib/rcan/ (found relative to rcand, docs/TRANSPORT.md).
add_library(rcand_grpc MODULE $<TARGET_OBJECTS:rcan_grpc_objects>)
target_link_libraries(rcand_grpc PRIVATE rcan_proto)
set_target_properties(rcand_grpc PROPERTIES LIBRARY_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/bin)

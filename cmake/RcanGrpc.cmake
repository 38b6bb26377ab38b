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

# Generated code: compiled once, without the project's warning flags.
add_library(rcan_proto STATIC ${RCAN_PROTO_GEN}/rcan.pb.cc ${RCAN_PROTO_GEN}/rcan.grpc.pb.cc)
target_include_directories(rcan_proto SYSTEM PUBLIC ${RCAN_PROTO_GEN})
target_link_libraries(rcan_proto PUBLIC PkgConfig::GRPCPP)

file(GLOB RCAN_GRPC_SOURCES CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/src/transport/grpc_*.cpp)
add_library(rcan_grpc STATIC ${RCAN_GRPC_SOURCES})
target_link_libraries(rcan_grpc PUBLIC rcan_node rcan_proto PRIVATE rcan_warnings)

# rcan_registry: the registry's HTTP API (src/registry/api, docs/REGISTRY.md) over the storage
# library rcan_registry_store (cmake/RcanRegistry.cmake), and the daemon rcan-registry
# (apps/rcan-registry).
file(GLOB RCAN_REGISTRY_API_SOURCES CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/src/registry/api/*.cpp)
add_library(rcan_registry STATIC ${RCAN_REGISTRY_API_SOURCES})
target_include_directories(rcan_registry PUBLIC ${PROJECT_SOURCE_DIR}/src)
target_link_libraries(rcan_registry PUBLIC rcan_registry_store rcan_transport rcan_runtime rcan PRIVATE rcan_warnings)

file(GLOB RCAN_REGISTRY_APP_SOURCES CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/apps/rcan-registry/*.cpp)
add_executable(rcan-registry ${RCAN_REGISTRY_APP_SOURCES})
set_target_properties(rcan-registry PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/bin)
target_link_libraries(rcan-registry PRIVATE rcan_registry yaml-cpp rcan_warnings)

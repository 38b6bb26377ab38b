# rcan_registry: the registry's HTTP API (src/registry/api, docs/REGISTRY.md) over the storage
# library rcan_registry_store (cmake/RcanRegistry.cmake), and the daemon rcan-registry
# (apps/rcan-registry).
rcan_add_library(rcan_registry src/registry/api address.cpp admin_routes.cpp authority.cpp
  authority_routes.cpp body.cpp oauth_form.cpp oauth_routes.cpp rate_limit.cpp registry_api.cpp
  robots_routes.cpp routes.cpp sync.cpp sync_routes.cpp webhook_routes.cpp webhooks.cpp)
target_include_directories(rcan_registry PUBLIC ${PROJECT_SOURCE_DIR}/src)
target_link_libraries(rcan_registry PUBLIC rcan_registry_store rcan_transport rcan_runtime rcan)

add_executable(rcan-registry ${PROJECT_SOURCE_DIR}/apps/rcan-registry/main.cpp
  ${PROJECT_SOURCE_DIR}/apps/rcan-registry/daemon.cpp ${PROJECT_SOURCE_DIR}/apps/rcan-registry/setup.cpp)
set_target_properties(rcan-registry PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/bin)
target_link_libraries(rcan-registry PRIVATE rcan_registry yaml-cpp rcan_warnings)

# rcan-registry's storage (src/registry/store.h, docs/REGISTRY.md): the SQLite backend (the
# embedded default, one instance) and the PostgreSQL backend (several instances on one
# database). Its own library: nothing else in the project links SQLite.
pkg_check_modules(SQLITE3 REQUIRED IMPORTED_TARGET sqlite3)
add_library(rcan_registry_store STATIC
  ${PROJECT_SOURCE_DIR}/src/registry/store.cpp
  ${PROJECT_SOURCE_DIR}/src/registry/authority_store.cpp
  ${PROJECT_SOURCE_DIR}/src/registry/sqlite_store.cpp
  ${PROJECT_SOURCE_DIR}/src/registry/pg_store.cpp)
target_include_directories(rcan_registry_store PUBLIC ${PROJECT_SOURCE_DIR}/src)
target_link_libraries(rcan_registry_store PUBLIC rcan PRIVATE PkgConfig::SQLITE3 PkgConfig::LIBPQ
  Threads::Threads rcan_warnings)

// The registry's storage in PostgreSQL (store.h).
#include "registry/store.h"

namespace rcan::registry {

Result<std::unique_ptr<Store>> open_postgres(const std::string&, const StoreOptions&) {
  return Error(ErrorCode::kNotImplemented, "the PostgreSQL backend is not built yet");
}

}  // namespace rcan::registry

#include "node/discovery/avahi_dl.h"

#include <dlfcn.h>

namespace rcan::node {

namespace {

struct Loaded {
  AvahiApi api;
  std::string error;
  bool ok = false;
};

Loaded load() {
  Loaded l;
  // libavahi-client needs libavahi-common (its DT_NEEDED); the common functions are found
  // through the client's handle as well, since dlsym searches a handle's dependencies.
  void* h = ::dlopen("libavahi-client.so.3", RTLD_NOW | RTLD_LOCAL);
  if (!h) {
    const char* why = ::dlerror();
    l.error = std::string("cannot load libavahi-client.so.3: ") + (why ? why : "dlopen failed");
    return l;
  }
#define RCAN_AVAHI_SYM(name)                                                       \
  l.api.name = reinterpret_cast<decltype(l.api.name)>(::dlsym(h, "avahi_" #name)); \
  if (!l.api.name) {                                                               \
    l.error = "libavahi-client.so.3 has no avahi_" #name;                          \
    return l;                                                                      \
  }
  RCAN_AVAHI_FUNCTIONS(RCAN_AVAHI_SYM)
#undef RCAN_AVAHI_SYM
  l.ok = true;
  return l;
}

}  // namespace

const AvahiApi* avahi_api(std::string* error) {
  static const Loaded loaded = load();
  if (!loaded.ok) {
    if (error) *error = loaded.error;
    return nullptr;
  }
  return &loaded.api;
}

}  // namespace rcan::node

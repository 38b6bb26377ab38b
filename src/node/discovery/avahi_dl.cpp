#include "node/discovery/avahi_dl.h"

#include <dlfcn.h>
#include <sys/stat.h>

#include <cstdlib>

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

// The socket Avahi's client would use: DBUS_SYSTEM_BUS_ADDRESS when it names a unix:path=,
// else the standard one. Other address forms are tried as given.
bool system_bus_present(std::string& why) {
  std::string path = "/run/dbus/system_bus_socket";
  if (const char* a = std::getenv("DBUS_SYSTEM_BUS_ADDRESS"); a && *a) {
    std::string addr = a;
    if (addr.rfind("unix:", 0) != 0) return true;
    size_t p = addr.find("path=");
    if (p == std::string::npos) return true;  // unix:abstract=…, unix:runtime=yes…
    size_t end = addr.find_first_of(",;", p);
    path = addr.substr(p + 5, end == std::string::npos ? std::string::npos : end - p - 5);
  }
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) return true;
  why = "no D-Bus system bus at " + path;
  return false;
}

const AvahiApi* avahi_api(std::string* error) {
  static const Loaded loaded = load();
  if (!loaded.ok) {
    if (error) *error = loaded.error;
    return nullptr;
  }
  return &loaded.api;
}

}  // namespace rcan::node

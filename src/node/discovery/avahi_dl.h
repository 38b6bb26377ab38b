// libavahi-client loaded on first use (dlopen), so that a node without mDNS maps neither Avahi
// nor D-Bus/libsystemd and their dependencies (docs/NODE.md §Discovery). Only the functions
// src/node/discovery/mdns.cpp calls; each has the exact type of its declaration in the Avahi
// headers.
#pragma once

#include <avahi-client/client.h>
#include <avahi-client/lookup.h>
#include <avahi-client/publish.h>
#include <avahi-common/address.h>
#include <avahi-common/alternative.h>
#include <avahi-common/error.h>
#include <avahi-common/malloc.h>
#include <avahi-common/strlst.h>
#include <avahi-common/thread-watch.h>

#include <string>

namespace rcan::node {

struct AvahiApi {
#define RCAN_AVAHI_FN(name) decltype(&::avahi_##name) name = nullptr;
// One function a line (the formatter reflows a packed list differently on each pass).
#define RCAN_AVAHI_FUNCTIONS(X)            \
  X(strerror)                              \
  X(free)                                  \
  X(alternative_service_name)              \
  X(string_list_add)                       \
  X(string_list_free)                      \
  X(threaded_poll_new)                     \
  X(threaded_poll_start)                   \
  X(threaded_poll_stop)                    \
  X(threaded_poll_free)                    \
  X(threaded_poll_lock)                    \
  X(threaded_poll_unlock)                  \
  X(threaded_poll_get)                     \
  X(client_new)                            \
  X(client_free)                           \
  X(client_errno)                          \
  X(entry_group_new)                       \
  X(entry_group_is_empty)                  \
  X(entry_group_add_service_strlst)        \
  X(entry_group_update_service_txt_strlst) \
  X(entry_group_commit)                    \
  X(entry_group_reset)                     \
  X(entry_group_get_client)                \
  X(service_browser_new)                   \
  X(service_browser_free)                  \
  X(service_resolver_new)                  \
  X(service_resolver_free)                 \
  X(address_snprint)                       \
  X(string_list_get_next)                  \
  X(string_list_get_text)                  \
  X(string_list_get_size)
  RCAN_AVAHI_FUNCTIONS(RCAN_AVAHI_FN)
#undef RCAN_AVAHI_FN
};

// The loaded API, or nullptr with *error saying why (library or symbol missing). Loaded once,
// never unloaded; thread-safe.
const AvahiApi* avahi_api(std::string* error = nullptr);

// Whether the D-Bus system bus Avahi is reached through exists ($DBUS_SYSTEM_BUS_ADDRESS or
// /run/dbus/system_bus_socket); otherwise false with `why`.
bool system_bus_present(std::string& why);

}  // namespace rcan::node

// Browsing _rcan._tcp through the Avahi daemon (D-Bus), for rcan::client::discover.
#include <avahi-client/client.h>
#include <avahi-client/lookup.h>
#include <avahi-common/error.h>
#include <avahi-common/malloc.h>
#include <avahi-common/simple-watch.h>
#include <net/if.h>

#include <chrono>

#include "base/clock.h"
#include "rcan/client.h"

namespace rcan::client {
namespace {

struct BrowseState {
  AvahiSimplePoll* poll = nullptr;
  std::vector<MdnsService> found;
  int outstanding = 0;
  bool all_for_now = false;
  std::string failure;
};

void on_resolved(AvahiServiceResolver* r, AvahiIfIndex iface, AvahiProtocol,
                 AvahiResolverEvent event, const char* name, const char*, const char*,
                 const char* host, const AvahiAddress* a, uint16_t port, AvahiStringList* txt,
                 AvahiLookupResultFlags flags, void* data) {
  auto* st = static_cast<BrowseState*>(data);
  if (event == AVAHI_RESOLVER_FOUND && a) {
    MdnsService s;
    s.name = name ? name : "";
    s.hostname = host ? host : "";
    char addr[AVAHI_ADDRESS_STR_MAX];
    avahi_address_snprint(addr, sizeof addr, a);
    s.address = addr;
    s.port = port;
    s.local = (flags & AVAHI_LOOKUP_RESULT_LOCAL) != 0;
    char ifname[IF_NAMESIZE] = {0};
    if (iface >= 0 && if_indextoname(static_cast<unsigned>(iface), ifname)) s.interface = ifname;
    for (AvahiStringList* l = txt; l; l = avahi_string_list_get_next(l))
      s.txt.emplace_back(reinterpret_cast<const char*>(avahi_string_list_get_text(l)),
                         avahi_string_list_get_size(l));
    st->found.push_back(std::move(s));
  }
  --st->outstanding;
  avahi_service_resolver_free(r);
}

void on_browse(AvahiServiceBrowser* b, AvahiIfIndex iface, AvahiProtocol proto,
               AvahiBrowserEvent event, const char* name, const char* type, const char* domain,
               AvahiLookupResultFlags, void* data) {
  auto* st = static_cast<BrowseState*>(data);
  AvahiClient* c = avahi_service_browser_get_client(b);
  switch (event) {
    case AVAHI_BROWSER_NEW:
      if (avahi_service_resolver_new(c, iface, proto, name, type, domain, AVAHI_PROTO_INET,
                                     static_cast<AvahiLookupFlags>(0), on_resolved, st))
        ++st->outstanding;
      break;
    case AVAHI_BROWSER_ALL_FOR_NOW:
      st->all_for_now = true;
      break;
    case AVAHI_BROWSER_FAILURE:
      st->failure = avahi_strerror(avahi_client_errno(c));
      avahi_simple_poll_quit(st->poll);
      break;
    default:
      break;
  }
}

void on_client(AvahiClient* c, AvahiClientState state, void* data) {
  auto* st = static_cast<BrowseState*>(data);
  if (state == AVAHI_CLIENT_FAILURE) {
    st->failure = avahi_strerror(avahi_client_errno(c));
    avahi_simple_poll_quit(st->poll);
  }
}

}  // namespace

Result<std::vector<MdnsService>> browse_mdns(int timeout_ms) {
  BrowseState st;
  st.poll = avahi_simple_poll_new();
  if (!st.poll) {
    ClientError e;
    e.code = "MDNS_UNAVAILABLE";
    e.message = "cannot create the Avahi poll object";
    return e;
  }
  int err = 0;
  AvahiClient* client = avahi_client_new(avahi_simple_poll_get(st.poll),
                                         static_cast<AvahiClientFlags>(0), on_client, &st, &err);
  if (!client) {
    avahi_simple_poll_free(st.poll);
    ClientError e;
    e.code = "MDNS_UNAVAILABLE";
    e.message = std::string("mDNS browsing needs the Avahi daemon: ") + avahi_strerror(err);
    return e;
  }
  AvahiServiceBrowser* browser =
      avahi_service_browser_new(client, AVAHI_IF_UNSPEC, AVAHI_PROTO_INET, "_rcan._tcp", nullptr,
                                static_cast<AvahiLookupFlags>(0), on_browse, &st);
  if (!browser) st.failure = avahi_strerror(avahi_client_errno(client));
  auto deadline = steady_now() + std::chrono::milliseconds(timeout_ms);
  while (browser && st.failure.empty()) {
    auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - steady_now()).count();
    if (left <= 0) break;
    // Done early once the daemon has said "all for now" and every resolution finished.
    if (st.all_for_now && st.outstanding == 0 && !st.found.empty()) break;
    if (avahi_simple_poll_iterate(st.poll, static_cast<int>(std::min<int64_t>(left, 100))) != 0)
      break;
  }
  if (browser) avahi_service_browser_free(browser);
  avahi_client_free(client);  // frees outstanding resolvers too
  avahi_simple_poll_free(st.poll);
  if (!st.failure.empty()) {
    ClientError e;
    e.code = "MDNS_UNAVAILABLE";
    e.message = "mDNS browsing failed: " + st.failure;
    return e;
  }
  return st.found;
}

}  // namespace rcan::client

// MdnsBrowser on libavahi-client's threaded poll (src/node/discovery/mdns_browse.h). Avahi's
// callbacks run on its poll thread holding the poll lock; what they find goes into a map under
// the browser's own mutex, which robots() reads from the HTTP threads.
#include "node/discovery/mdns_browse.h"

#include <net/if.h>

#include "node/discovery/avahi_dl.h"
#include "rcan/mdns_txt.h"
#include "runtime/log.h"

namespace rcan::node {

namespace {
const AvahiApi& av() { return *avahi_api(); }
constexpr const char* kServiceType = "_rcan._tcp";
}  // namespace

struct MdnsBrowser::Impl {
  AvahiThreadedPoll* poll = nullptr;
  AvahiClient* client = nullptr;  // poll thread (under the poll lock)
  AvahiServiceBrowser* browser = nullptr;
  // One resolver per announced service, kept while it is announced: Avahi reports its TXT
  // record again when it changes (a robot's status). Poll thread only.
  std::map<std::string, AvahiServiceResolver*> resolvers;
  mutable Mutex mu;
  std::map<std::string, MdnsRobot> found GUARDED_BY(mu);  // "<interface index>/<instance>"
  std::string why GUARDED_BY(mu);

  void set_unavailable(const std::string& reason) EXCLUDES(mu) {
    {
      MutexLock lock(mu);
      if (why == reason) return;
      why = reason;
      found.clear();
    }
    log(LogLevel::kWarn, "mdns_browse_unavailable", json::Object{{"reason", reason}});
  }
  void clear() EXCLUDES(mu) {
    MutexLock lock(mu);
    found.clear();
  }

  void drop_lookups() {
    for (auto& [k, r] : resolvers) av().service_resolver_free(r);
    resolvers.clear();
    if (browser) av().service_browser_free(browser);
    browser = nullptr;
  }

  static std::string key(AvahiIfIndex iface, const char* name) {
    return std::to_string(iface) + "/" + (name ? name : "");
  }

  static void client_cb(AvahiClient* c, AvahiClientState state, void* data) {
    auto* im = static_cast<Impl*>(data);
    im->client = c;
    if (state == AVAHI_CLIENT_S_RUNNING) {
      if (!im->browser)
        im->browser =
            av().service_browser_new(c, AVAHI_IF_UNSPEC, AVAHI_PROTO_INET, kServiceType, nullptr,
                                     static_cast<AvahiLookupFlags>(0), &Impl::browse_cb, im);
      if (!im->browser)
        im->set_unavailable(std::string("cannot browse: ") + av().strerror(av().client_errno(c)));
      else {
        MutexLock lock(im->mu);
        im->why.clear();
      }
      return;
    }
    if (state == AVAHI_CLIENT_CONNECTING || state == AVAHI_CLIENT_FAILURE) {
      // The daemon went away (it restarts): what it told us is stale, and its browser with it.
      im->drop_lookups();
      im->set_unavailable(state == AVAHI_CLIENT_FAILURE
                              ? std::string("Avahi failed: ") + av().strerror(av().client_errno(c))
                              : std::string("waiting for the Avahi daemon"));
    }
  }

  static void browse_cb(AvahiServiceBrowser*, AvahiIfIndex iface, AvahiProtocol proto,
                        AvahiBrowserEvent event, const char* name, const char* type,
                        const char* domain, AvahiLookupResultFlags, void* data) {
    auto* im = static_cast<Impl*>(data);
    switch (event) {
      case AVAHI_BROWSER_NEW: {
        const std::string k = key(iface, name);
        if (im->resolvers.count(k) || im->resolvers.size() >= 1024) break;
        AvahiServiceResolver* r = av().service_resolver_new(
            im->client, iface, proto, name, type, domain, AVAHI_PROTO_INET,
            static_cast<AvahiLookupFlags>(0), &Impl::resolve_cb, im);
        if (r)
          im->resolvers[k] = r;
        else
          log(LogLevel::kWarn, "mdns_browse_resolve_failed",
              json::Object{{"instance", name ? name : ""},
                           {"reason", av().strerror(av().client_errno(im->client))}});
        break;
      }
      case AVAHI_BROWSER_REMOVE: {
        const std::string k = key(iface, name);
        if (auto it = im->resolvers.find(k); it != im->resolvers.end()) {
          av().service_resolver_free(it->second);
          im->resolvers.erase(it);
        }
        MutexLock lock(im->mu);
        im->found.erase(k);
        break;
      }
      case AVAHI_BROWSER_FAILURE:
        im->set_unavailable(std::string("browsing failed: ") +
                            av().strerror(av().client_errno(im->client)));
        break;
      case AVAHI_BROWSER_ALL_FOR_NOW:
      case AVAHI_BROWSER_CACHE_EXHAUSTED:
        break;
    }
  }

  static void resolve_cb(AvahiServiceResolver*, AvahiIfIndex iface, AvahiProtocol,
                         AvahiResolverEvent event, const char* name, const char*, const char*,
                         const char*, const AvahiAddress* a, uint16_t port, AvahiStringList* txt,
                         AvahiLookupResultFlags, void* data) {
    auto* im = static_cast<Impl*>(data);
    if (event == AVAHI_RESOLVER_FOUND && a) {
      MdnsRobot m;
      m.instance = name ? name : "";
      char addr[AVAHI_ADDRESS_STR_MAX] = {0};
      av().address_snprint(addr, sizeof addr, a);
      m.address = addr;
      m.port = port;
      char ifname[IF_NAMESIZE] = {0};
      if (iface >= 0 && if_indextoname(static_cast<unsigned>(iface), ifname)) m.interface = ifname;
      std::vector<std::string> items;
      for (AvahiStringList* l = txt; l; l = av().string_list_get_next(l))
        items.emplace_back(reinterpret_cast<const char*>(av().string_list_get_text(l)),
                           av().string_list_get_size(l));
      m.txt = parse_txt(items);
      m.tls = txt_says_tls(m.txt);
      MutexLock lock(im->mu);
      im->found[key(iface, name)] = std::move(m);
    }
    // The resolver stays: it reports the TXT record again when it changes (freed on REMOVE).
  }
};

MdnsBrowser::MdnsBrowser() : impl_(std::make_unique<Impl>()) {}

MdnsBrowser::~MdnsBrowser() { stop(); }

void MdnsBrowser::start() {
  Impl* im = impl_.get();
  if (im->poll) return;
  std::string why;
  if (!system_bus_present(why)) return im->set_unavailable("cannot reach D-Bus/Avahi: " + why);
  if (!avahi_api(&why)) return im->set_unavailable(why);
  im->poll = av().threaded_poll_new();
  if (!im->poll) return im->set_unavailable("cannot create the Avahi poll thread");
  av().threaded_poll_start(im->poll);
  av().threaded_poll_lock(im->poll);
  int err = 0;
  // AVAHI_CLIENT_NO_FAIL: no daemon yet (or a restart) leaves the client waiting for one.
  AvahiClient* c = av().client_new(av().threaded_poll_get(im->poll), AVAHI_CLIENT_NO_FAIL,
                                   &Impl::client_cb, im, &err);
  if (c) im->client = c;
  av().threaded_poll_unlock(im->poll);
  if (!c) im->set_unavailable(std::string("cannot reach D-Bus/Avahi: ") + av().strerror(err));
}

void MdnsBrowser::stop() {
  Impl* im = impl_.get();
  if (!im->poll) return;
  av().threaded_poll_stop(im->poll);
  im->drop_lookups();
  if (im->client) av().client_free(im->client);
  im->client = nullptr;
  av().threaded_poll_free(im->poll);
  im->poll = nullptr;
  im->clear();
}

std::vector<MdnsRobot> MdnsBrowser::robots() const {
  MutexLock lock(impl_->mu);
  std::vector<MdnsRobot> out;
  out.reserve(impl_->found.size());
  for (const auto& [k, m] : impl_->found) out.push_back(m);
  return out;
}

std::string MdnsBrowser::unavailable() const {
  MutexLock lock(impl_->mu);
  return impl_->why;
}

}  // namespace rcan::node

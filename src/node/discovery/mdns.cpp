// MdnsAdvertiser on libavahi-client's threaded poll (src/node/discovery/mdns.h).
#include "node/discovery/mdns.h"

#include <pthread.h>

#include <chrono>

#include "base/clock.h"
#include "base/thread_annotations.h"
#include "node/discovery/avahi_dl.h"
#include "node/services/node_services.h"
#include "runtime/log.h"

namespace rcan::node {

namespace {
// Avahi, loaded by start() (avahi_dl.h); nothing below runs before it has loaded.
const AvahiApi& av() { return *avahi_api(); }

}  // namespace

struct MdnsAdvertiser::Impl {
  MdnsInfo info;
  AvahiThreadedPoll* poll = nullptr;
  AvahiClient* client = nullptr;
  AvahiEntryGroup* group = nullptr;
  std::string name;
  std::string status;  // wanted status (watcher thread writes under the poll lock)
  bool established = false;
  bool said_unavailable = false;
  std::function<void()> on_stop;

  std::thread watcher;
  Mutex mu;
  CondVar cv;
  bool stopping GUARDED_BY(mu) = false;
  bool poked GUARDED_BY(mu) = false;

  mutable Mutex pub_mu;
  std::string published GUARDED_BY(pub_mu);

  AvahiStringList* txt_list() const {
    AvahiStringList* l = nullptr;
    for (auto it = info.txt.rbegin(); it != info.txt.rend(); ++it)
      l = av().string_list_add(l, it->c_str());
    l = av().string_list_add(l, ("status=" + status).c_str());
    return l;
  }

  void set_published(const std::string& s) EXCLUDES(pub_mu) {
    MutexLock lock(pub_mu);
    published = s;
  }

  void unavailable(const std::string& why) {
    if (said_unavailable) return;
    said_unavailable = true;
    log(LogLevel::kWarn, "mdns_unavailable",
        json::Object{{"error", why},
                     {"note",
                      "the node keeps running; it is not discoverable over mDNS until an Avahi "
                      "daemon runs"}});
  }

  // Poll thread (or under the poll lock).
  void create_services(AvahiClient* c) {
    if (!group) {
      group = av().entry_group_new(c, &Impl::group_cb, this);
      if (!group) {
        unavailable(std::string("cannot create an entry group: ") +
                    av().strerror(av().client_errno(c)));
        return;
      }
    }
    if (!av().entry_group_is_empty(group)) return;
    while (true) {
      AvahiStringList* txt = txt_list();
      int r = av().entry_group_add_service_strlst(group, AVAHI_IF_UNSPEC, AVAHI_PROTO_UNSPEC,
                                                  static_cast<AvahiPublishFlags>(0), name.c_str(),
                                                  "_rcan._tcp", nullptr, nullptr, info.port, txt);
      av().string_list_free(txt);
      if (r == AVAHI_ERR_COLLISION) {
        rename();
        av().entry_group_reset(group);
        continue;
      }
      if (r < 0) {
        log(LogLevel::kWarn, "mdns_publish_failed", json::Object{{"error", av().strerror(r)}});
        return;
      }
      break;
    }
    if (int r = av().entry_group_commit(group); r < 0)
      log(LogLevel::kWarn, "mdns_publish_failed", json::Object{{"error", av().strerror(r)}});
  }

  void rename() {
    char* n = av().alternative_service_name(name.c_str());
    log(LogLevel::kInfo, "mdns_name_collision",
        json::Object{{"name", name}, {"renamed_to", n ? n : ""}});
    if (n) {
      name = n;
      av().free(n);
    }
  }

  void update_txt() {
    if (!group || !established) return;
    AvahiStringList* txt = txt_list();
    int r = av().entry_group_update_service_txt_strlst(group, AVAHI_IF_UNSPEC, AVAHI_PROTO_UNSPEC,
                                                       static_cast<AvahiPublishFlags>(0),
                                                       name.c_str(), "_rcan._tcp", nullptr, txt);
    av().string_list_free(txt);
    if (r < 0) {
      log(LogLevel::kWarn, "mdns_update_failed", json::Object{{"error", av().strerror(r)}});
      return;
    }
    set_published(status);
    log(LogLevel::kDebug, "mdns_status", json::Object{{"name", name}, {"status", status}});
  }

  static void group_cb(AvahiEntryGroup* g, AvahiEntryGroupState state, void* data) {
    auto* self = static_cast<Impl*>(data);
    self->group = g;
    switch (state) {
      case AVAHI_ENTRY_GROUP_ESTABLISHED:
        self->established = true;
        self->set_published(self->status);
        log(LogLevel::kInfo, "mdns_advertising",
            json::Object{{"service", "_rcan._tcp"},
                         {"name", self->name},
                         {"port", static_cast<int64_t>(self->info.port)},
                         {"status", self->status}});
        break;
      case AVAHI_ENTRY_GROUP_COLLISION:
        self->established = false;
        self->rename();
        av().entry_group_reset(g);
        self->create_services(av().entry_group_get_client(g));
        break;
      case AVAHI_ENTRY_GROUP_FAILURE:
        self->established = false;
        log(LogLevel::kWarn, "mdns_publish_failed",
            json::Object{
                {"error", av().strerror(av().client_errno(av().entry_group_get_client(g)))}});
        break;
      default:
        break;
    }
  }

  static void client_cb(AvahiClient* c, AvahiClientState state, void* data) {
    auto* self = static_cast<Impl*>(data);
    switch (state) {
      case AVAHI_CLIENT_S_RUNNING:
        if (self->said_unavailable) log(LogLevel::kInfo, "mdns_available", json::Object{});
        self->said_unavailable = false;
        self->create_services(c);
        break;
      case AVAHI_CLIENT_S_COLLISION:
      case AVAHI_CLIENT_S_REGISTERING:
        self->established = false;
        if (self->group) av().entry_group_reset(self->group);
        break;
      case AVAHI_CLIENT_CONNECTING:
        self->unavailable("no Avahi daemon is running (waiting for one)");
        break;
      case AVAHI_CLIENT_FAILURE:
        self->established = false;
        self->unavailable(av().client_errno(c) == AVAHI_ERR_DISCONNECTED
                              ? "the Avahi daemon went away (waiting for it)"
                              : av().strerror(av().client_errno(c)));
        // Drop the client (only once avahi_client_new has returned it); the watcher thread
        // creates a new one within 5 s, which waits for the daemon to come back.
        if (c == self->client) {
          av().client_free(c);
          self->client = nullptr;
          self->group = nullptr;
        }
        break;
    }
  }
};

MdnsAdvertiser::MdnsAdvertiser(MdnsInfo info) : impl_(std::make_unique<Impl>()) {
  impl_->info = std::move(info);
  impl_->name = impl_->info.name.empty() ? "rcan-robot" : impl_->info.name;
  impl_->status = impl_->info.status ? impl_->info.status() : "available";
}

MdnsAdvertiser::~MdnsAdvertiser() { stop(); }

void MdnsAdvertiser::start() {
  Impl* im = impl_.get();
  if (im->watcher.joinable()) return;
  // Avahi is loaded (and its poll thread started) once a D-Bus system bus exists: without one
  // it cannot be reached, and a node that never finds one never maps Avahi and D-Bus.
  auto ready = [im]() -> bool {
    if (im->poll) return true;
    std::string why;
    if (!system_bus_present(why)) {
      im->unavailable("cannot reach D-Bus/Avahi: " + why);
      return false;
    }
    if (!avahi_api(&why)) {
      im->unavailable(why);
      return false;
    }
    im->poll = av().threaded_poll_new();
    if (!im->poll) {
      im->unavailable("cannot create the Avahi poll thread");
      return false;
    }
    av().threaded_poll_start(im->poll);
    return true;
  };
  // Connects (or retries every 5 s while D-Bus/Avahi are absent), under the poll lock.
  auto connect = [im, ready](bool first) {
    if (!ready()) return;
    av().threaded_poll_lock(im->poll);
    if (!im->client) {
      int err = 0;
      im->client = av().client_new(av().threaded_poll_get(im->poll), AVAHI_CLIENT_NO_FAIL,
                                   &Impl::client_cb, im, &err);
      if (!im->client && first)
        im->unavailable(std::string("cannot reach D-Bus/Avahi: ") + av().strerror(err));
    }
    av().threaded_poll_unlock(im->poll);
  };
  connect(true);
  im->watcher = std::thread([im, connect] {
    pthread_setname_np(pthread_self(), "mdns-watch");
    ReleasableMutexLock lock(im->mu);
    auto next_try = steady_now() + std::chrono::seconds(5);
    while (!im->stopping) {
      const auto until = steady_now() + std::chrono::seconds(1);
      while (!im->stopping && !im->poked) {
        if (im->cv.wait_until(im->mu, until) == std::cv_status::timeout) break;
      }
      if (im->stopping) break;
      im->poked = false;
      lock.unlock();
      if (steady_now() >= next_try) {
        connect(false);
        next_try = steady_now() + std::chrono::seconds(5);
      }
      if (!im->poll) {
        lock.lock();
        continue;
      }
      std::string s = im->info.status ? im->info.status() : "available";
      av().threaded_poll_lock(im->poll);
      if (s != im->status) {
        im->status = s;
        im->update_txt();
      }
      av().threaded_poll_unlock(im->poll);
      lock.lock();
    }
  });
}

void MdnsAdvertiser::poke() {
  {
    MutexLock lock(impl_->mu);
    impl_->poked = true;
  }
  impl_->cv.notify_one();
}

void MdnsAdvertiser::stop() {
  Impl* im = impl_.get();
  if (im->on_stop) {
    im->on_stop();
    im->on_stop = nullptr;
  }
  {
    MutexLock lock(im->mu);
    im->stopping = true;
  }
  im->cv.notify_one();
  if (im->watcher.joinable()) im->watcher.join();
  if (im->poll) {
    av().threaded_poll_stop(im->poll);
    if (im->client) av().client_free(im->client);  // frees the entry group: goodbye packets
    im->client = nullptr;
    im->group = nullptr;
    av().threaded_poll_free(im->poll);
    im->poll = nullptr;
  }
}

void MdnsAdvertiser::set_on_stop(std::function<void()> fn) { impl_->on_stop = std::move(fn); }

std::string MdnsAdvertiser::published_status() const {
  MutexLock lock(impl_->pub_mu);
  return impl_->published;
}

MdnsInfo mdns_info_for(NodeServices& services, bool tls) {
  MdnsInfo info;
  const NodeSettings& s = services.settings;
  info.name = s.name;
  info.port = s.port;
  std::string caps;
  for (const auto& c : s.capabilities) caps += (caps.empty() ? "" : ",") + c;
  info.txt = {"ruri=" + s.ruri, "model=" + s.model,
              "caps=" + caps,   "roles=creator,owner,leasee,user,guest",
              "role=GUEST",     "version=" + s.rcan_version,
              "name=" + s.name};
  if (!s.ruri_sdk.empty()) info.txt.push_back("ruri_sdk=" + s.ruri_sdk);
  if (!s.rrn.empty()) info.txt.push_back("rrn=" + s.rrn);
  if (tls) info.txt.push_back("tls=1");
  NodeServices* svc = &services;
  info.status = [svc] { return status_word(*svc); };
  return info;
}

std::string status_word(NodeServices& svc) {
  if (svc.act.estop_active()) return "estop";
  if (svc.control.sessions().controller(svc.clock.mono_ms())) return "claimed";
  return "available";
}

std::unique_ptr<MdnsAdvertiser> start_mdns(NodeServices& services, bool tls) {
  auto adv = std::make_unique<MdnsAdvertiser>(mdns_info_for(services, tls));
  // The EventBus may still call a copy of the subscriber while the advertiser stops: the
  // subscriber reaches it only through this guarded pointer, cleared at stop().
  struct Target {
    explicit Target(MdnsAdvertiser* a) : adv(a) {}
    Mutex mu;
    MdnsAdvertiser* adv GUARDED_BY(mu);
  };
  auto target = std::make_shared<Target>(adv.get());
  uint64_t sub = services.events.subscribe([target](const Event&) {
    MutexLock lock(target->mu);
    if (target->adv) target->adv->poke();
  });
  NodeServices* svc = &services;
  adv->set_on_stop([svc, sub, target] {
    svc->events.unsubscribe(sub);
    MutexLock lock(target->mu);
    target->adv = nullptr;
  });
  adv->start();
  return adv;
}

}  // namespace rcan::node

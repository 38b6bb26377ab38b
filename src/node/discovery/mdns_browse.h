// MdnsBrowser — the rcand nodes announcing `_rcan._tcp` on the node's networks (config
// `dashboard.mdns`, docs/DASHBOARD.md §Robots), for the dashboard's Robots view: each one's
// address and the TXT keys it announces (name, ruri, model, version, status). IPv4 only (one
// entry per robot and interface; link-local IPv6 addresses need a zone the page cannot use).
//
// The view lists them; it never sends them a token: an announcement on the network is no
// reason to trust an address (only dashboard.robots is). Avahi is loaded on start (avahi_dl.h);
// without D-Bus or Avahi the browser logs `mdns_browse_unavailable` once and lists nothing,
// and while the daemon is away (restarting) the client waits for it and browses again.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "base/thread_annotations.h"

namespace rcan::node {

struct MdnsRobot {
  std::string instance;  // the mDNS service instance name
  std::string interface;
  std::string address;  // IPv4
  uint16_t port = 0;
  bool tls = false;                        // TXT tls=1
  std::map<std::string, std::string> txt;  // keys lower-cased, first of duplicates kept
  std::string url() const {
    return std::string(tls ? "https" : "http") + "://" + address + ":" + std::to_string(port);
  }
};

class MdnsBrowser {
 public:
  MdnsBrowser();
  ~MdnsBrowser();
  MdnsBrowser(const MdnsBrowser&) = delete;
  MdnsBrowser& operator=(const MdnsBrowser&) = delete;

  void start();
  void stop();
  // What is announced now; "" or why browsing is not possible.
  std::vector<MdnsRobot> robots() const;
  std::string unavailable() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace rcan::node

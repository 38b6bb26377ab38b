#include "node/admission/registry_revocations.h"

#include <algorithm>
#include <string>

#include "node/admission/registry_feed.h"
#include "runtime/log.h"
#include "runtime/state_file.h"

namespace rcan::node {
namespace {

constexpr int kMaxPagesPerPoll = 20;

}  // namespace

void RegistryRevocationFeed::load_cursor() {
  auto c = read_state_file(link_.dir() + "/revocations_cursor.json", link_.env());
  if (!c.ok()) return;
  const json::Value* u = c->get("registry_url");
  const json::Value* s = c->get("since");
  if (u && u->is_string() && u->as_string() == link_.options().registry_url && s && s->is_int()) {
    MutexLock l(mu_);
    since_ = saved_since_ = s->as_int();
  }
}

void RegistryRevocationFeed::save_cursor() {
  int64_t since;
  {
    MutexLock l(mu_);
    if (since_ == saved_since_) return;
    since = since_;
  }
  Status s = link_.make_dir();
  if (s.ok())
    s = write_state_file(
        link_.dir() + "/revocations_cursor.json",
        json::Value(json::Object{{"registry_url", link_.options().registry_url}, {"since", since}}),
        link_.env());
  if (!s.ok()) return link_.failed("registry revocations cursor", s.error().message);
  MutexLock l(mu_);
  saved_since_ = since;
}

void RegistryRevocationFeed::advance(int64_t seq) {
  MutexLock l(mu_);
  since_ = seq;
}

int64_t RegistryRevocationFeed::since() const {
  MutexLock l(mu_);
  return since_;
}

bool RegistryRevocationFeed::poll(int timeout_ms) {
  ++polls_;
  for (int page = 0; page < kMaxPagesPerPoll; ++page) {
    const int64_t n = poll_page(timeout_ms);
    if (n < 0) return false;
    if (static_cast<size_t>(n) < kRevocationPageSize) break;
  }
  link_.feed_ok();
  return true;
}

int64_t RegistryRevocationFeed::poll_page(int timeout_ms) {
  const std::string& issuer = link_.issuer();
  const int64_t since = this->since();
  auto body = link_.get("/api/v1/revocations?since=" + std::to_string(since), timeout_ms);
  if (!body.ok())
    return link_.failed("registry revocations", body.error().message), ++failures_, -1;
  auto p = parse_revocation_page(*body, since);
  if (!p.ok()) return link_.failed("registry revocations", p.error().message), ++failures_, -1;
  const int64_t now_ms = link_.clock().wall_ms();
  for (const auto& e : p->entries) {
    Revocation r;
    r.kind = e.jti.empty() ? Revocation::Kind::kSubject : Revocation::Kind::kJti;
    r.iss = issuer;
    r.value = e.jti.empty() ? e.sub : e.jti;
    if (!e.jti.empty()) r.exp = e.exp;
    r.at_ms = e.revoked_at_ms.value_or(now_ms);
    r.by = PrincipalId{issuer, "registry"};
    r.reason = "registry revocation " + std::to_string(e.seq);
    r.feed = true;  // its own table: a flood of the feed never crowds out the OWNER's entries
    auto added = revocations_.add(r, now_ms / 1000);  // persisted; closes its streams
    // A full feed table is not a fault to wait out: the entry is skipped, counted and
    // recorded, and the feed read on (a stalled cursor would stop every later revocation).
    const bool skipped = !added.ok() && added.error().reason == "revocation_feed_full";
    TrustRecord rec{"TOKEN_REVOKED",
                    added.ok() ? (*added ? "ok" : "unchanged")
                    : skipped  ? "skipped"
                               : "failed",
                    skipped ? "revocation_feed_full" : "",
                    {{"source", "registry"},
                     {"registry_seq", e.seq},
                     {"kind", std::string(revocation_kind_name(r.kind))},
                     {"iss", issuer}}};
    if (added.ok() || skipped) rec.detail.set(std::string(revocation_kind_name(r.kind)), r.value);
    link_.record(std::move(rec));
    if (skipped) {
      ++skipped_;
      log(LogLevel::kWarn, "registry_revocation_skipped",
          json::Object{{"seq", e.seq}, {"error", added.error().message}});
      advance(e.seq);
      continue;
    }
    if (!added.ok()) {
      ++failures_;
      save_cursor();  // what was applied before it stays applied
      return link_.failed("registry revocations", added.error().message), -1;
    }
    ++applied_;
    advance(e.seq);
  }
  {
    MutexLock l(mu_);
    since_ = std::max(since_, p->next_since);
    last_poll_ms_ = now_ms;
  }
  save_cursor();
  return static_cast<int64_t>(p->entries.size());
}

json::Value RegistryRevocationFeed::status_json() const {
  MutexLock l(mu_);
  return json::Object{{"since", since_},
                      {"last_poll_ms", last_poll_ms_ ? json::Value(last_poll_ms_) : json::Value()},
                      {"applied", static_cast<int64_t>(applied_.load())}};
}

}  // namespace rcan::node

// The stop backlog (stop_backlog.h).
#include "node/vocabulary/stop_backlog.h"

#include "runtime/log.h"

namespace rcan::node {

StopBacklog::StopBacklog(std::string spill_path, base::Env* env, Limits limits)
    : path_(std::move(spill_path)), env_(env ? env : base::Env::posix()), limits_(limits) {
  if (path_.empty() || !env_->exists(path_)) return;
  auto text = env_->read_file(path_);
  if (!text.ok()) return;
  size_t lines = 0;
  for (char c : *text) lines += c == '\n';
  MutexLock lock(mu_);
  spilled_ = lines;
  pending_.store(lines, std::memory_order_release);
  if (lines > 0)
    log(LogLevel::kWarn, "audit.stop_backlog_found",
        {{"file", path_}, {"records", static_cast<int64_t>(lines)}});
}

void StopBacklog::count_lost(uint64_t n, const char* why) {
  if (n == 0) return;
  uint64_t total = lost_.fetch_add(n, std::memory_order_acq_rel) + n;
  log(LogLevel::kError, "audit.stop_record_lost",
      {{"why", why},
       {"records", static_cast<int64_t>(n)},
       {"lost_total", static_cast<int64_t>(total)}});
}

bool StopBacklog::spill_locked(const audit::AuditEntry& e) {
  if (path_.empty() || spilled_ >= limits_.spill_records) return false;
  if (!file_) {
    auto f = env_->open_appendable(path_);
    if (!f.ok()) return false;
    file_ = std::move(*f);
  }
  std::string line = json::canonical(json::Value(audit::to_object(e)));
  line += '\n';
  if (!file_->append(line).ok() || !file_->sync().ok()) {
    // The line may be half there: drop the handle; take() skips a torn line (and counts it).
    (void)file_->close();
    file_.reset();
    return false;
  }
  ++spilled_;
  return true;
}

void StopBacklog::keep(const audit::AuditEntry& e) {
  MutexLock lock(mu_);
  if (spill_locked(e)) {
    pending_.fetch_add(1, std::memory_order_acq_rel);
    return;
  }
  if (memory_.size() < limits_.memory_records) {
    memory_.push_back(e);
    pending_.fetch_add(1, std::memory_order_acq_rel);
    return;
  }
  count_lost(1, "the spill file and the memory backlog are full");
}

std::vector<audit::AuditEntry> StopBacklog::take() {
  std::vector<audit::AuditEntry> out;
  uint64_t unreadable = 0;
  {
    MutexLock lock(mu_);
    if (spilled_ > 0) {
      if (file_) {
        (void)file_->close();
        file_.reset();
      }
      auto text = env_->read_file(path_);
      if (text.ok()) {
        size_t start = 0;
        while (start < text->size()) {
          size_t end = text->find('\n', start);
          if (end == std::string::npos) {  // torn by a crash or a failed write
            ++unreadable;
            break;
          }
          auto v = json::parse(std::string_view(*text).substr(start, end - start));
          auto e =
              v.ok() && v->is_object()
                  ? audit::entry_from_object(v->as_object())
                  : Result<audit::AuditEntry>(Error(ErrorCode::kMalformedJson, "not an object"));
          if (e.ok()) {
            out.push_back(std::move(*e));
          } else {
            ++unreadable;
          }
          start = end + 1;
        }
        (void)env_->remove_file(path_);
      } else {
        unreadable += spilled_;
      }
      spilled_ = 0;
    }
    for (auto& e : memory_) out.push_back(std::move(e));
    memory_.clear();
    pending_.store(0, std::memory_order_release);
  }
  count_lost(unreadable, "unreadable lines in the spill file");
  return out;
}

json::Value StopBacklog::to_json() const {
  MutexLock lock(mu_);
  return json::Object{{"pending", static_cast<int64_t>(pending())},
                      {"spilled", static_cast<int64_t>(spilled_)},
                      {"lost", static_cast<int64_t>(lost())}};
}

}  // namespace rcan::node

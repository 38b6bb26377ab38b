#include "testing/fault_env.h"

#include <algorithm>

namespace rcan::base {
namespace {

std::string parent_dir(const std::string& path) {
  auto pos = path.rfind('/');
  return pos == std::string::npos ? std::string(".") : path.substr(0, pos);
}

IoError injected(const std::string& what) {
  return IoError{IoCode::kInjected, 0, "injected fault: " + what};
}

class FaultWritableFile final : public WritableFile {
 public:
  FaultWritableFile(FaultInjectionEnv* env, std::string path, std::unique_ptr<WritableFile> base)
      : env_(env), path_(std::move(path)), base_(std::move(base)) {}

  IoStatus append(std::string_view data) override {
    IoStatus s = env_->before_mutation("append " + path_);
    if (!s.ok()) {
      // The operation that "kills" the process may leave half of its bytes behind.
      if (env_->torn_appends() && env_->is_failing_now() && data.size() > 1) {
        std::string_view half = data.substr(0, data.size() / 2);
        if (base_->append(half).ok()) env_->note_appended(path_, half.size());
      }
      return s;
    }
    s = base_->append(data);
    if (s.ok()) env_->note_appended(path_, data.size());
    return s;
  }
  IoStatus sync() override {
    IoStatus s = env_->before_mutation("sync " + path_);
    if (!s.ok()) return s;
    s = base_->sync();
    if (s.ok()) env_->note_synced(path_);
    return s;
  }
  IoStatus close() override { return base_->close(); }

 private:
  FaultInjectionEnv* env_;
  std::string path_;
  std::unique_ptr<WritableFile> base_;
};

}  // namespace

FaultInjectionEnv::FaultInjectionEnv(Env* base) : base_(base) {}

void FaultInjectionEnv::fail_after(uint64_t n) {
  std::lock_guard<std::mutex> l(mu_);
  fail_at_ = n == 0 ? 0 : ops_ + n;
  failed_ = false;
}

bool FaultInjectionEnv::failed() const {
  std::lock_guard<std::mutex> l(mu_);
  return failed_;
}

uint64_t FaultInjectionEnv::mutations() const {
  std::lock_guard<std::mutex> l(mu_);
  return ops_;
}

// True only while handling the operation that first tripped the fault.
bool FaultInjectionEnv::is_failing_now() {
  std::lock_guard<std::mutex> l(mu_);
  return just_tripped_;
}

void FaultInjectionEnv::hold(bool on) {
  {
    std::lock_guard<std::mutex> l(mu_);
    hold_ = on;
  }
  if (!on) release_.notify_all();
}

size_t FaultInjectionEnv::held() const {
  std::lock_guard<std::mutex> l(mu_);
  return held_;
}

IoStatus FaultInjectionEnv::before_mutation(const std::string& what) {
  std::unique_lock<std::mutex> l(mu_);
  if (hold_) {
    ++held_;
    release_.wait(l, [this] { return !hold_; });
    --held_;
  }
  ++ops_;
  just_tripped_ = false;
  if (failed_) {
    --ops_;  // a dead process performs no more operations
    return injected(what + " (after crash point)");
  }
  if (fail_at_ != 0 && ops_ >= fail_at_) {
    failed_ = true;
    just_tripped_ = true;
    ops_ = fail_at_;
    return injected(what);
  }
  return IoStatus::Ok();
}

void FaultInjectionEnv::note_appended(const std::string& path, uint64_t n) {
  std::lock_guard<std::mutex> l(mu_);
  files_[path].size += n;
}

void FaultInjectionEnv::note_synced(const std::string& path) {
  std::lock_guard<std::mutex> l(mu_);
  auto& f = files_[path];
  f.durable = f.size;
  rewrites_.erase(path);
}

IoStatus FaultInjectionEnv::drop_unsynced(double keep_fraction) {
  std::map<std::string, FileState> files;
  std::set<std::string> fresh;
  std::map<std::string, std::string> rewrites;
  {
    std::lock_guard<std::mutex> l(mu_);
    files = files_;
    fresh = new_files_;
    rewrites = rewrites_;
    files_.clear();
    new_files_.clear();
    rewrites_.clear();
    failed_ = false;
    fail_at_ = 0;
  }
  // An unsynced rewrite in place: the first `keep_fraction` of what is there now, the rest as it
  // was before (the bytes past the old end are dropped).
  for (const auto& [path, before] : rewrites) {
    files.erase(path);
    if (!base_->exists(path)) continue;
    auto now = base_->read_file(path);
    if (!now.ok()) return now.error();
    const size_t keep = std::min(
        now->size(), static_cast<size_t>(static_cast<double>(now->size()) * keep_fraction));
    std::string out = now->substr(0, keep);
    if (before.size() > keep) out += before.substr(keep);
    IoStatus s = base_->write_file_synced(path, out);
    if (!s.ok()) return s;
  }
  for (const auto& path : fresh) {
    if (base_->exists(path)) {
      IoStatus s = base_->remove_file(path);
      if (!s.ok()) return s;
    }
    files.erase(path);
  }
  for (const auto& [path, st] : files) {
    if (!base_->exists(path)) continue;
    uint64_t keep = st.durable;
    if (st.size > st.durable)
      keep += static_cast<uint64_t>(static_cast<double>(st.size - st.durable) * keep_fraction);
    auto size = base_->file_size(path);
    if (!size.ok()) return size.error();
    if (*size > keep) {
      IoStatus s = base_->truncate_file(path, keep);
      if (!s.ok()) return s;
    }
  }
  return IoStatus::Ok();
}

IoResult<std::unique_ptr<WritableFile>> FaultInjectionEnv::open_appendable(
    const std::string& path) {
  bool existed = base_->exists(path);
  if (!existed) {
    IoStatus s = before_mutation("create " + path);
    if (!s.ok()) return s.error();
  }
  auto base = base_->open_appendable(path);
  if (!base.ok()) return base.error();
  {
    std::lock_guard<std::mutex> l(mu_);
    if (!existed) new_files_.insert(path);
    if (!files_.count(path)) {
      auto size = base_->file_size(path);
      uint64_t n = size.ok() ? *size : 0;
      files_[path] = FileState{n, n};
    }
  }
  return std::unique_ptr<WritableFile>(new FaultWritableFile(this, path, std::move(*base)));
}

IoResult<std::unique_ptr<WritableFile>> FaultInjectionEnv::open_existing_at(const std::string& path,
                                                                            uint64_t offset) {
  auto base = base_->open_existing_at(path, offset);  // first: a FIFO is refused, not read
  if (!base.ok()) return base.error();
  auto before = base_->read_file(path);
  {
    std::lock_guard<std::mutex> l(mu_);
    if (before.ok() && rewrites_.count(path) == 0) {
      // What a crash goes back to: the durable part of what is there.
      if (auto it = files_.find(path); it != files_.end() && it->second.durable < before->size())
        before->resize(it->second.durable);
      rewrites_[path] = std::move(*before);
    }
    files_.erase(path);  // tracked as a rewrite, not by its length
  }
  return std::unique_ptr<WritableFile>(new FaultWritableFile(this, path, std::move(*base)));
}

IoResult<std::unique_ptr<WritableFile>> FaultInjectionEnv::open_writable_at(const std::string& path,
                                                                            uint64_t offset) {
  bool existed = base_->exists(path);
  if (!existed) {
    IoStatus s = before_mutation("create " + path);
    if (!s.ok()) return s.error();
  }
  auto base = base_->open_writable_at(path, offset);
  if (!base.ok()) return base.error();
  {
    std::lock_guard<std::mutex> l(mu_);
    if (!existed) new_files_.insert(path);
    // Data beyond `offset` (preallocated zeros) is not part of the log.
    files_[path] = FileState{offset, offset};
  }
  return std::unique_ptr<WritableFile>(new FaultWritableFile(this, path, std::move(*base)));
}

IoStatus FaultInjectionEnv::write_zeros_synced(const std::string& path, uint64_t bytes) {
  bool existed = base_->exists(path);
  IoStatus s = before_mutation("preallocate " + path);
  if (!s.ok()) return s;
  s = base_->write_zeros_synced(path, bytes);
  if (s.ok()) {
    std::lock_guard<std::mutex> l(mu_);
    files_[path] = FileState{bytes, bytes};
    rewrites_.erase(path);
    if (!existed) new_files_.insert(path);
  }
  return s;
}

IoResult<std::string> FaultInjectionEnv::read_file(const std::string& path) {
  if (fail_reads_.load()) return injected("read " + path);
  return base_->read_file(path);
}
IoResult<std::string> FaultInjectionEnv::read_range(const std::string& path, uint64_t offset,
                                                    size_t n) {
  if (fail_reads_.load()) return injected("pread " + path);
  return base_->read_range(path, offset, n);
}
IoResult<uint64_t> FaultInjectionEnv::file_size(const std::string& path) {
  return base_->file_size(path);
}
bool FaultInjectionEnv::exists(const std::string& path) { return base_->exists(path); }
IoResult<std::vector<std::string>> FaultInjectionEnv::children(const std::string& dir) {
  return base_->children(dir);
}
IoStatus FaultInjectionEnv::create_dir(const std::string& dir) { return base_->create_dir(dir); }

IoStatus FaultInjectionEnv::sync_dir(const std::string& dir) {
  IoStatus s = before_mutation("sync_dir " + dir);
  if (!s.ok()) return s;
  s = base_->sync_dir(dir);
  if (s.ok()) {
    std::lock_guard<std::mutex> l(mu_);
    for (auto it = new_files_.begin(); it != new_files_.end();) {
      if (parent_dir(*it) == dir) {
        it = new_files_.erase(it);
      } else {
        ++it;
      }
    }
  }
  return s;
}

IoStatus FaultInjectionEnv::remove_file(const std::string& path) {
  IoStatus s = before_mutation("remove " + path);
  if (!s.ok()) return s;
  s = base_->remove_file(path);
  std::lock_guard<std::mutex> l(mu_);
  files_.erase(path);
  new_files_.erase(path);
  rewrites_.erase(path);
  return s;
}

IoStatus FaultInjectionEnv::rename_file(const std::string& from, const std::string& to) {
  IoStatus s = before_mutation("rename " + from);
  if (!s.ok()) return s;
  s = base_->rename_file(from, to);
  if (s.ok()) {
    std::lock_guard<std::mutex> l(mu_);
    if (auto it = files_.find(from); it != files_.end()) {
      files_[to] = it->second;
      files_.erase(it);
    }
    if (new_files_.erase(from)) new_files_.insert(to);
    rewrites_.erase(to);  // replaced: what it held before is gone
    if (auto it = rewrites_.find(from); it != rewrites_.end()) {
      rewrites_[to] = std::move(it->second);
      rewrites_.erase(it);
    }
  }
  return s;
}

IoStatus FaultInjectionEnv::truncate_file(const std::string& path, uint64_t size) {
  IoStatus s = before_mutation("truncate " + path);
  if (!s.ok()) return s;
  s = base_->truncate_file(path, size);
  if (s.ok()) {
    std::lock_guard<std::mutex> l(mu_);
    if (auto it = files_.find(path); it != files_.end()) {
      it->second.size = size;
      it->second.durable = size;
    }
    rewrites_.erase(path);
  }
  return s;
}

IoStatus FaultInjectionEnv::write_file_synced(const std::string& path, std::string_view data) {
  return synced_write(path, data, false);
}

IoStatus FaultInjectionEnv::write_private_file_synced(const std::string& path,
                                                      std::string_view data) {
  return synced_write(path, data, true);
}

IoStatus FaultInjectionEnv::synced_write(const std::string& path, std::string_view data,
                                         bool private_file) {
  bool existed = base_->exists(path);
  IoStatus s = before_mutation("write " + path);
  if (!s.ok()) return s;
  s = private_file ? base_->write_private_file_synced(path, data)
                   : base_->write_file_synced(path, data);
  if (s.ok()) {
    std::lock_guard<std::mutex> l(mu_);
    files_[path] = FileState{data.size(), data.size()};
    rewrites_.erase(path);
    if (!existed) new_files_.insert(path);
  }
  return s;
}

IoResult<int> FaultInjectionEnv::lock_file(const std::string& path) {
  return base_->lock_file(path);
}
void FaultInjectionEnv::unlock_file(int handle) { base_->unlock_file(handle); }
int64_t FaultInjectionEnv::now_ms() { return base_->now_ms() + clock_offset_ms_.load(); }

}  // namespace rcan::base

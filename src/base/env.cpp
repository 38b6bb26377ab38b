// base::Env::posix() — the real file system.
#include "rcan/base/env.h"

#include <dirent.h>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>

namespace rcan::base {
namespace {

IoError io_error(const std::string& what, const std::string& path, int err) {
  return IoError{err == ENOENT ? IoCode::kNotFound : IoCode::kIo, err,
                 what + " " + path + ": " + std::strerror(err)};
}

IoStatus write_all(int fd, std::string_view data, const std::string& path) {
  const char* p = data.data();
  size_t left = data.size();
  while (left > 0) {
    ssize_t n = ::write(fd, p, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      return io_error("write", path, errno);
    }
    p += n;
    left -= static_cast<size_t>(n);
  }
  return IoStatus::Ok();
}

// An open file descriptor: sync (fdatasync) and close, shared by the two file kinds below.
class PosixFile : public WritableFile {
 public:
  PosixFile(int fd, std::string path) : fd_(fd), path_(std::move(path)) {}
  ~PosixFile() override {
    if (fd_ >= 0) ::close(fd_);
  }
  IoStatus sync() override {
    if (::fdatasync(fd_) != 0) return io_error("fdatasync", path_, errno);
    return IoStatus::Ok();
  }
  IoStatus close() override {
    if (fd_ < 0) return IoStatus::Ok();
    int rc = ::close(fd_);
    fd_ = -1;
    if (rc != 0) return io_error("close", path_, errno);
    return IoStatus::Ok();
  }

 protected:
  int fd_;
  std::string path_;
};

class PosixWritableFile final : public PosixFile {
 public:
  using PosixFile::PosixFile;
  IoStatus append(std::string_view data) override { return write_all(fd_, data, path_); }
};

class PosixPositionalFile : public PosixFile {
 public:
  PosixPositionalFile(int fd, std::string path, uint64_t offset)
      : PosixFile(fd, std::move(path)), offset_(offset) {}
  IoStatus append(std::string_view data) override {
    const char* p = data.data();
    size_t left = data.size();
    while (left > 0) {
      ssize_t n = ::pwrite(fd_, p, left, static_cast<off_t>(offset_));
      if (n < 0) {
        if (errno == EINTR) continue;
        return io_error("pwrite", path_, errno);
      }
      p += n;
      left -= static_cast<size_t>(n);
      offset_ += static_cast<uint64_t>(n);
    }
    return IoStatus::Ok();
  }

 private:
  uint64_t offset_;
};

// A file rewritten in place (open_existing_at): a sync also says whether the file is still
// there. Removed (or renamed over) between the open and the sync, what was written is durable
// in an inode that no name reaches: an error, so that the caller writes the file anew.
class PosixLinkedFile final : public PosixPositionalFile {
 public:
  using PosixPositionalFile::PosixPositionalFile;
  IoStatus sync() override {
    if (IoStatus s = PosixPositionalFile::sync(); !s.ok()) return s;
    struct stat st {};
    if (::fstat(fd_, &st) != 0) return io_error("fstat", path_, errno);
    if (st.st_nlink == 0) return io_error("fdatasync (removed while written)", path_, ENOENT);
    return IoStatus::Ok();
  }
};

class PosixEnv final : public Env {
 public:
  IoResult<std::unique_ptr<WritableFile>> open_writable_at(const std::string& path,
                                                           uint64_t offset) override {
    int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0600);
    if (fd < 0) return io_error("open", path, errno);
    return std::unique_ptr<WritableFile>(new PosixPositionalFile(fd, path, offset));
  }

  IoResult<std::unique_ptr<WritableFile>> open_existing_at(const std::string& path,
                                                           uint64_t offset) override {
    // O_NONBLOCK: a FIFO put in the file's place would block the open until a reader came
    // (without it; with it the open fails at once), and anything but a regular file is refused
    // (O_NOCTTY: a terminal put there never becomes the process's).
    int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK | O_NOCTTY);
    if (fd < 0) return io_error("open", path, errno);
    struct stat st {};
    if (::fstat(fd, &st) != 0) {
      const int e = errno;
      ::close(fd);
      return io_error("fstat", path, e);
    }
    if (!S_ISREG(st.st_mode)) {
      ::close(fd);
      return io_error("open (not a regular file)", path, EINVAL);
    }
    if (int fl = ::fcntl(fd, F_GETFL); fl < 0 || ::fcntl(fd, F_SETFL, fl & ~O_NONBLOCK) != 0) {
      const int e = errno;
      ::close(fd);
      return io_error("fcntl", path, e);
    }
    return std::unique_ptr<WritableFile>(new PosixLinkedFile(fd, path, offset));
  }

  IoStatus write_zeros_synced(const std::string& path, uint64_t bytes) override {
    int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0) return io_error("open", path, errno);
    static const std::string kZeros(1 << 20, '\0');
    IoStatus s;
    uint64_t left = bytes;
    while (s.ok() && left > 0) {
      size_t n = static_cast<size_t>(std::min<uint64_t>(left, kZeros.size()));
      s = write_all(fd, std::string_view(kZeros.data(), n), path);
      left -= n;
    }
    if (s.ok() && ::fsync(fd) != 0) s = io_error("fsync", path, errno);
    ::close(fd);
    return s;
  }

  IoResult<std::unique_ptr<WritableFile>> open_appendable(const std::string& path) override {
    int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0600);
    if (fd < 0) return io_error("open", path, errno);
    return std::unique_ptr<WritableFile>(new PosixWritableFile(fd, path));
  }

  IoResult<std::string> read_file(const std::string& path) override {
    int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return io_error("open", path, errno);
    std::string out;
    char buf[1 << 16];
    for (;;) {
      ssize_t n = ::read(fd, buf, sizeof buf);
      if (n < 0) {
        if (errno == EINTR) continue;
        int e = errno;
        ::close(fd);
        return io_error("read", path, e);
      }
      if (n == 0) break;
      out.append(buf, static_cast<size_t>(n));
    }
    ::close(fd);
    return out;
  }

  IoResult<std::string> read_range(const std::string& path, uint64_t offset, size_t n) override {
    int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return io_error("open", path, errno);
    // A length from a corrupt index must not become a huge allocation: never more than the
    // file holds past `offset` (a short result, which the callers report).
    struct stat st {};
    if (::fstat(fd, &st) != 0) {
      int e = errno;
      ::close(fd);
      return io_error("fstat", path, e);
    }
    const uint64_t size = st.st_size > 0 ? static_cast<uint64_t>(st.st_size) : 0;
    n = offset >= size ? 0 : static_cast<size_t>(std::min<uint64_t>(n, size - offset));
    std::string out(n, '\0');
    size_t got = 0;
    while (got < n) {
      ssize_t r = ::pread(fd, out.data() + got, n - got, static_cast<off_t>(offset + got));
      if (r < 0) {
        if (errno == EINTR) continue;
        int e = errno;
        ::close(fd);
        return io_error("pread", path, e);
      }
      if (r == 0) break;
      got += static_cast<size_t>(r);
    }
    ::close(fd);
    out.resize(got);
    return out;
  }

  IoResult<uint64_t> file_size(const std::string& path) override {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return io_error("stat", path, errno);
    return static_cast<uint64_t>(st.st_size);
  }

  bool exists(const std::string& path) override { return ::access(path.c_str(), F_OK) == 0; }

  IoResult<std::vector<std::string>> children(const std::string& dir) override {
    DIR* d = ::opendir(dir.c_str());
    if (!d) return io_error("opendir", dir, errno);
    std::vector<std::string> out;
    while (struct dirent* e = ::readdir(d)) {
      std::string n = e->d_name;
      if (n != "." && n != "..") out.push_back(std::move(n));
    }
    ::closedir(d);
    return out;
  }

  IoStatus create_dir(const std::string& dir) override {
    if (::mkdir(dir.c_str(), 0700) != 0 && errno != EEXIST) return io_error("mkdir", dir, errno);
    return IoStatus::Ok();
  }

  IoStatus sync_dir(const std::string& dir) override {
    int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return io_error("open", dir, errno);
    int rc = ::fsync(fd);
    int e = errno;
    ::close(fd);
    if (rc != 0) return io_error("fsync", dir, e);
    return IoStatus::Ok();
  }

  IoStatus remove_file(const std::string& path) override {
    if (::unlink(path.c_str()) != 0) return io_error("unlink", path, errno);
    return IoStatus::Ok();
  }

  IoStatus rename_file(const std::string& from, const std::string& to) override {
    if (::rename(from.c_str(), to.c_str()) != 0) return io_error("rename", from, errno);
    return IoStatus::Ok();
  }

  IoStatus truncate_file(const std::string& path, uint64_t size) override {
    int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
    if (fd < 0) return io_error("open", path, errno);
    if (::ftruncate(fd, static_cast<off_t>(size)) != 0) {
      int e = errno;
      ::close(fd);
      return io_error("ftruncate", path, e);
    }
    int rc = ::fsync(fd);
    int e = errno;
    ::close(fd);
    if (rc != 0) return io_error("fsync", path, e);
    return IoStatus::Ok();
  }

  IoStatus write_file_synced(const std::string& path, std::string_view data) override {
    int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0) return io_error("open", path, errno);
    IoStatus s = write_all(fd, data, path);
    if (s.ok() && ::fsync(fd) != 0) s = io_error("fsync", path, errno);
    ::close(fd);
    return s;
  }

  IoStatus write_private_file_synced(const std::string& path, std::string_view data) override {
    int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC | O_NOFOLLOW, 0600);
    if (fd < 0) return io_error("open", path, errno);
    // The umask may have removed bits and an existing file may have had others: make it exact.
    IoStatus s;
    if (::fchmod(fd, 0600) != 0) s = io_error("chmod", path, errno);
    if (s.ok()) s = write_all(fd, data, path);
    if (s.ok() && ::fsync(fd) != 0) s = io_error("fsync", path, errno);
    if (::close(fd) != 0 && s.ok()) s = io_error("close", path, errno);
    return s;
  }

  IoResult<int> lock_file(const std::string& path) override {
    int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    if (fd < 0) return io_error("open", path, errno);
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      int e = errno;
      ::close(fd);
      return IoError{IoCode::kLocked, e,
                     path + " is locked by another process: " + std::strerror(e)};
    }
    return fd;
  }

  void unlock_file(int handle) override {
    if (handle >= 0) {
      ::flock(handle, LOCK_UN);
      ::close(handle);
    }
  }

  int64_t now_ms() override {
    return std::chrono::duration_cast<std::chrono::milliseconds>(
               std::chrono::system_clock::now().time_since_epoch())
        .count();
  }
};

// The directory holding `path` ("." for a bare name, "/" for a file at the root).
std::string parent_dir(const std::string& path) {
  auto pos = path.rfind('/');
  if (pos == std::string::npos) return ".";
  return pos == 0 ? std::string("/") : path.substr(0, pos);
}

}  // namespace

IoStatus Env::write_file_atomic(const std::string& path, std::string_view data) {
  const std::string tmp = path + ".tmp";
  IoStatus s = write_private_file_synced(tmp, data);
  if (s.ok()) s = rename_file(tmp, path);
  if (!s.ok()) {
    if (exists(tmp)) (void)remove_file(tmp);
    return s;
  }
  return sync_dir(parent_dir(path));
}

Env* Env::posix() {
  static PosixEnv* env = new PosixEnv();  // never deleted: used by static destructors
  return env;
}

}  // namespace rcan::base

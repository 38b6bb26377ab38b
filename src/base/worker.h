// Worker — a small pool of threads for blocking work (disk reads for audit export, …) so the
// transport's I/O threads never wait on a disk.
#pragma once

#include <pthread.h>

#include <deque>
#include <functional>
#include <thread>
#include <vector>

#include "base/thread_annotations.h"

namespace rcan {

class Worker {
 public:
  explicit Worker(int threads = 1) {
    for (int i = 0; i < threads; ++i)
      threads_.emplace_back([this] {
        pthread_setname_np(pthread_self(), "node-worker");
        loop();
      });
  }
  ~Worker() { shutdown(); }
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  // Queues `fn`; false when shut down or the queue is full (the caller answers 503).
  bool post(std::function<void()> fn, size_t max_queue = 1024) EXCLUDES(mu_) {
    MutexLock lock(mu_);
    if (quit_ || q_.size() >= max_queue) return false;
    q_.push_back(std::move(fn));
    cv_.notify_one();
    return true;
  }

  // Runs what is queued, then joins.
  void shutdown() EXCLUDES(mu_) {
    {
      MutexLock lock(mu_);
      if (quit_) return;
      quit_ = true;
      cv_.notify_all();
    }
    for (auto& t : threads_)
      if (t.joinable()) t.join();
  }

 private:
  void loop() EXCLUDES(mu_) {
    while (true) {
      std::function<void()> fn;
      {
        MutexLock lock(mu_);
        while (!quit_ && q_.empty()) cv_.wait(mu_);
        if (q_.empty()) return;
        fn = std::move(q_.front());
        q_.pop_front();
      }
      fn();
    }
  }

  Mutex mu_;
  CondVar cv_;
  std::deque<std::function<void()>> q_ GUARDED_BY(mu_);
  bool quit_ GUARDED_BY(mu_) = false;
  std::vector<std::thread> threads_;
};

}  // namespace rcan

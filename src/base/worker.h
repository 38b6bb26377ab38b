// Worker — a small pool of threads for blocking work (disk reads for audit export, …) so the
// transport's I/O threads never wait on a disk.
#pragma once

#include <pthread.h>

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

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
  bool post(std::function<void()> fn, size_t max_queue = 1024) {
    std::lock_guard<std::mutex> lock(mu_);
    if (quit_ || q_.size() >= max_queue) return false;
    q_.push_back(std::move(fn));
    cv_.notify_one();
    return true;
  }

  // Runs what is queued, then joins.
  void shutdown() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (quit_) return;
      quit_ = true;
      cv_.notify_all();
    }
    for (auto& t : threads_)
      if (t.joinable()) t.join();
  }

 private:
  void loop() {
    while (true) {
      std::function<void()> fn;
      {
        std::unique_lock<std::mutex> lock(mu_);
        cv_.wait(lock, [this] { return quit_ || !q_.empty(); });
        if (q_.empty()) return;
        fn = std::move(q_.front());
        q_.pop_front();
      }
      fn();
    }
  }

  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> q_;
  bool quit_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace rcan

// Lock rules the compiler checks: Clang's thread-safety annotations, an annotated `Mutex`, its
// RAII guards and a condition variable that waits on it (after LevelDB's
// port/thread_annotations.h and Abseil's Mutex).
//
// The contract. A member that a mutex protects says so with GUARDED_BY(mu_) (PT_GUARDED_BY for
// what a pointer points to); a function that must be called with the lock held says
// REQUIRES(mu_) (the `*_locked` helpers); a public function that takes the lock itself may say
// EXCLUDES(mu_), so that calling it with the lock held (a self-deadlock) is caught. The lock is
// taken with `MutexLock` (a scope) or `ReleasableMutexLock` (a scope that may unlock and lock
// again); a condition variable waits on the `Mutex` itself. Built with clang and
// -Wthread-safety (the CTest test `source.thread_safety`, scripts/check_thread_safety.py), a
// guarded member read or written without its lock, a REQUIRES function called without it, or a
// lock not released on every path is a compile error. With any other compiler the macros are
// empty and the classes are thin wrappers of std::mutex and std::condition_variable.
//
//   class Queue {
//    public:
//     void push(int v) EXCLUDES(mu_) {
//       MutexLock lock(mu_);
//       items_.push_back(v);
//       cv_.notify_one();
//     }
//     int pop() EXCLUDES(mu_) {
//       MutexLock lock(mu_);
//       while (items_.empty()) cv_.wait(mu_);  // a loop, not a predicate lambda (below)
//       return take_locked();
//     }
//
//    private:
//     int take_locked() REQUIRES(mu_) {
//       const int v = items_.front();
//       items_.pop_front();
//       return v;
//     }
//     Mutex mu_;
//     CondVar cv_;
//     std::deque<int> items_ GUARDED_BY(mu_);
//   };
//
// What the analysis cannot see: a lambda is analysed as a function of its own, so a lambda that
// touches guarded members while its caller holds the lock is flagged. Wait in a loop instead of
// passing a predicate, move the body into a REQUIRES helper, or annotate the lambda itself
// (`[this]() REQUIRES(mu_) { … }`). Where a lock is known to be held but the analysis cannot
// follow it, `mu_.assert_held()` tells it so. NO_THREAD_SAFETY_ANALYSIS turns the check off for
// one function and is used only with a comment saying why.
#pragma once

#include <chrono>
#include <condition_variable>
#include <mutex>

#if defined(__clang__)
#define RCAN_THREAD_ANNOTATION_(x) __attribute__((x))
#else
#define RCAN_THREAD_ANNOTATION_(x)
#endif

// Each macro is defined unless a header included earlier defined it (Abseil's internal
// thread_annotations.h, which gRPC includes, defines several of them the same way).

// On a class: its objects are a capability (a lock) named `x` in the diagnostics.
#ifndef CAPABILITY
#define CAPABILITY(x) RCAN_THREAD_ANNOTATION_(capability(x))
#endif
// On a class: an RAII object that holds a capability for its lifetime.
#ifndef SCOPED_CAPABILITY
#define SCOPED_CAPABILITY RCAN_THREAD_ANNOTATION_(scoped_lockable)
#endif
// On a member: read and written only with `x` held (reads: held at least shared).
#ifndef GUARDED_BY
#define GUARDED_BY(x) RCAN_THREAD_ANNOTATION_(guarded_by(x))
#endif
// On a pointer member: what it points to is read and written only with `x` held.
#ifndef PT_GUARDED_BY
#define PT_GUARDED_BY(x) RCAN_THREAD_ANNOTATION_(pt_guarded_by(x))
#endif
// On a mutex member: the order in which locks are taken (checked with -Wthread-safety-beta).
#ifndef ACQUIRED_BEFORE
#define ACQUIRED_BEFORE(...) RCAN_THREAD_ANNOTATION_(acquired_before(__VA_ARGS__))
#endif
#ifndef ACQUIRED_AFTER
#define ACQUIRED_AFTER(...) RCAN_THREAD_ANNOTATION_(acquired_after(__VA_ARGS__))
#endif
// On a function: the caller holds the capabilities (exclusively, or at least shared).
#ifndef REQUIRES
#define REQUIRES(...) RCAN_THREAD_ANNOTATION_(requires_capability(__VA_ARGS__))
#endif
#ifndef REQUIRES_SHARED
#define REQUIRES_SHARED(...) RCAN_THREAD_ANNOTATION_(requires_shared_capability(__VA_ARGS__))
#endif
// On a function: it takes the capabilities and returns holding them.
#ifndef ACQUIRE
#define ACQUIRE(...) RCAN_THREAD_ANNOTATION_(acquire_capability(__VA_ARGS__))
#endif
#ifndef ACQUIRE_SHARED
#define ACQUIRE_SHARED(...) RCAN_THREAD_ANNOTATION_(acquire_shared_capability(__VA_ARGS__))
#endif
// On a function: the caller holds the capabilities and the function releases them.
#ifndef RELEASE
#define RELEASE(...) RCAN_THREAD_ANNOTATION_(release_capability(__VA_ARGS__))
#endif
#ifndef RELEASE_SHARED
#define RELEASE_SHARED(...) RCAN_THREAD_ANNOTATION_(release_shared_capability(__VA_ARGS__))
#endif
// On a function: TRY_ACQUIRE(b, …) takes the capabilities when it returns `b` (try_lock).
#ifndef TRY_ACQUIRE
#define TRY_ACQUIRE(...) RCAN_THREAD_ANNOTATION_(try_acquire_capability(__VA_ARGS__))
#endif
#ifndef TRY_ACQUIRE_SHARED
#define TRY_ACQUIRE_SHARED(...) RCAN_THREAD_ANNOTATION_(try_acquire_shared_capability(__VA_ARGS__))
#endif
// On a function: the caller must not hold the capabilities (the function takes them).
#ifndef EXCLUDES
#define EXCLUDES(...) RCAN_THREAD_ANNOTATION_(locks_excluded(__VA_ARGS__))
#endif
// On a function: it checks (or knows) that the capability is held; the caller may assume it.
#ifndef ASSERT_CAPABILITY
#define ASSERT_CAPABILITY(x) RCAN_THREAD_ANNOTATION_(assert_capability(x))
#endif
// On a function: it returns a reference to the capability `x`.
#ifndef RETURN_CAPABILITY
#define RETURN_CAPABILITY(x) RCAN_THREAD_ANNOTATION_(lock_returned(x))
#endif
// On a function: not analysed. Only with a comment saying why the analysis cannot follow it.
#ifndef NO_THREAD_SAFETY_ANALYSIS
#define NO_THREAD_SAFETY_ANALYSIS RCAN_THREAD_ANNOTATION_(no_thread_safety_analysis)
#endif

namespace rcan {

class CondVar;

// std::mutex, annotated: a capability the analysis tracks.
class CAPABILITY("mutex") Mutex {
 public:
  Mutex() = default;
  Mutex(const Mutex&) = delete;
  Mutex& operator=(const Mutex&) = delete;

  void lock() ACQUIRE() { mu_.lock(); }
  void unlock() RELEASE() { mu_.unlock(); }
  bool try_lock() TRY_ACQUIRE(true) { return mu_.try_lock(); }
  // Tells the analysis the lock is held here (it is, by a path it cannot follow). No run-time
  // check: std::mutex does not know its owner.
  void assert_held() const ASSERT_CAPABILITY(this) {}

 private:
  friend class CondVar;
  std::mutex mu_;
};

// Holds `mu` for the scope: std::lock_guard, annotated.
class SCOPED_CAPABILITY MutexLock {
 public:
  explicit MutexLock(Mutex& mu) ACQUIRE(mu) : mu_(mu) { mu_.lock(); }
  ~MutexLock() RELEASE() { mu_.unlock(); }
  MutexLock(const MutexLock&) = delete;
  MutexLock& operator=(const MutexLock&) = delete;

 private:
  Mutex& mu_;
};

// Holds `mu` from construction; may unlock() and lock() again inside the scope and releases it
// at the end of the scope if held: std::unique_lock, annotated.
class SCOPED_CAPABILITY ReleasableMutexLock {
 public:
  explicit ReleasableMutexLock(Mutex& mu) ACQUIRE(mu) : mu_(mu) { mu_.lock(); }
  ~ReleasableMutexLock() RELEASE() {
    if (held_) mu_.unlock();
  }
  ReleasableMutexLock(const ReleasableMutexLock&) = delete;
  ReleasableMutexLock& operator=(const ReleasableMutexLock&) = delete;

  void lock() ACQUIRE() {
    mu_.lock();
    held_ = true;
  }
  void unlock() RELEASE() {
    held_ = false;
    mu_.unlock();
  }

 private:
  Mutex& mu_;
  bool held_ = true;
};

// std::condition_variable over a `Mutex`: each wait is called with the mutex held, releases it
// while blocked and holds it again when it returns (spurious wake-ups included: wait in a loop
// on the condition).
class CondVar {
 public:
  CondVar() = default;
  CondVar(const CondVar&) = delete;
  CondVar& operator=(const CondVar&) = delete;

  void wait(Mutex& mu) REQUIRES(mu) {
    Adopted lock(mu);
    cv_.wait(lock.lock);
  }
  template <class Clock, class Duration>
  std::cv_status wait_until(Mutex& mu, const std::chrono::time_point<Clock, Duration>& deadline)
      REQUIRES(mu) {
    Adopted lock(mu);
    return cv_.wait_until(lock.lock, deadline);
  }
  template <class Rep, class Period>
  std::cv_status wait_for(Mutex& mu, const std::chrono::duration<Rep, Period>& timeout)
      REQUIRES(mu) {
    Adopted lock(mu);
    return cv_.wait_for(lock.lock, timeout);
  }
  void notify_one() noexcept { cv_.notify_one(); }
  void notify_all() noexcept { cv_.notify_all(); }

 private:
  // The caller's lock, lent to std::condition_variable for one wait and left held (also when
  // the wait throws): the caller's own guard releases it.
  struct Adopted {
    explicit Adopted(Mutex& mu) : lock(mu.mu_, std::adopt_lock) {}
    ~Adopted() { lock.release(); }
    std::unique_lock<std::mutex> lock;
  };
  std::condition_variable cv_;
};

}  // namespace rcan

#include "node/thread_prep.h"

#include <pthread.h>

#include <algorithm>

#include "rcan/errors.h"

namespace rcan::node {

namespace {

constexpr size_t kChunk = 16 * 1024;
constexpr size_t kPage = 4096;

// Touches `chunks` consecutive 16 KiB frames below the caller's. The read after the recursive
// call keeps each frame alive (no tail call reuses it).
[[gnu::noinline]] int touch_stack(size_t chunks) {
  volatile char frame[kChunk];
  for (size_t i = 0; i < kChunk; i += kPage) frame[i] = 0;
  int below = chunks > 1 ? touch_stack(chunks - 1) : 0;
  return below + frame[0];
}

size_t stack_size_of_this_thread() {
  pthread_attr_t attr;
  if (pthread_getattr_np(pthread_self(), &attr) != 0) return 0;
  size_t size = 0;
  void* addr = nullptr;
  if (pthread_attr_getstack(&attr, &addr, &size) != 0) size = 0;
  pthread_attr_destroy(&attr);
  return size;
}

}  // namespace

void prepare_command_thread(size_t stack_bytes) {
  thread_local bool prepared = false;
  if (prepared) return;
  prepared = true;
  const size_t limit = stack_size_of_this_thread() / 2;
  const size_t bytes = std::min(stack_bytes, limit);
  if (bytes >= kChunk) (void)touch_stack(bytes / kChunk);
  (void)new_uuid_v4();  // seeds this thread's generator and fills its id pool
}

}  // namespace rcan::node

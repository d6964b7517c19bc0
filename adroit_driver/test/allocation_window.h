// Counts the calls of the global operator new made while a window is open: code the driver
// runs in its real-time loop must allocate nothing inside one. It replaces the global
// operator new / delete of the test binary, so include it in exactly one file of a binary.
#pragma once

#include <cstddef>
#include <cstdlib>
#include <new>

namespace allocation_window {
inline bool open = false;
inline std::size_t count = 0;
inline void start() {
  count = 0;
  open = true;
}
// Closes the window; the allocations made while it was open.
inline std::size_t stop() {
  open = false;
  return count;
}
}  // namespace allocation_window

void* operator new(std::size_t size) {
  if (allocation_window::open) ++allocation_window::count;
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size) { return operator new(size); }
// Not inlined: GCC would then see malloc's memory freed through a "delete" and warn.
[[gnu::noinline]] void operator delete(void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete[](void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

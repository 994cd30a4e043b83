#pragma once
// A counting allocator: this program's global operator new and delete, replaced to keep the
// bytes held by live allocations (as malloc_usable_size counts them) and their peak. Include in
// exactly one translation unit of a program (it defines the replaceable global operators).

#include <malloc.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <new>

namespace crumple::testing::counting {

// Bytes held by live allocations, and their peak since it was last set.
inline std::atomic<long long> g_live{0};
inline std::atomic<long long> g_peak{0};

inline void* counted(void* p) {
  if (p == nullptr) throw std::bad_alloc();
  const auto n = static_cast<long long>(malloc_usable_size(p));
  const long long now = g_live.fetch_add(n) + n;
  long long peak = g_peak.load();
  while (now > peak && !g_peak.compare_exchange_weak(peak, now)) {
  }
  return p;
}
inline void uncounted(void* p) noexcept {
  if (p == nullptr) return;
  g_live.fetch_sub(static_cast<long long>(malloc_usable_size(p)));
  std::free(p);
}
inline void* aligned(std::size_t n, std::align_val_t a) {
  void* p = nullptr;
  const std::size_t al = std::max(static_cast<std::size_t>(a), sizeof(void*));
  return counted(posix_memalign(&p, al, n == 0 ? 1 : n) == 0 ? p : nullptr);
}

}  // namespace crumple::testing::counting

// The replaced operators (every form: plain, array, aligned, nothrow, sized).
namespace counting_ = crumple::testing::counting;
void* operator new(std::size_t n) { return counting_::counted(std::malloc(n == 0 ? 1 : n)); }
void* operator new[](std::size_t n) { return counting_::counted(std::malloc(n == 0 ? 1 : n)); }
void* operator new(std::size_t n, std::align_val_t a) { return counting_::aligned(n, a); }
void* operator new[](std::size_t n, std::align_val_t a) { return counting_::aligned(n, a); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counting_::counted(std::malloc(n == 0 ? 1 : n));
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t& t) noexcept { return operator new(n, t); }
void operator delete(void* p) noexcept { counting_::uncounted(p); }
void operator delete[](void* p) noexcept { counting_::uncounted(p); }
void operator delete(void* p, std::size_t) noexcept { counting_::uncounted(p); }
void operator delete[](void* p, std::size_t) noexcept { counting_::uncounted(p); }
void operator delete(void* p, std::align_val_t) noexcept { counting_::uncounted(p); }
void operator delete[](void* p, std::align_val_t) noexcept { counting_::uncounted(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { counting_::uncounted(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { counting_::uncounted(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { counting_::uncounted(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { counting_::uncounted(p); }

#include <crumple/core/parallel.hpp>

#include <algorithm>
#include <thread>

#ifdef CRUMPLE_HAVE_TBB
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#endif

namespace crumple {

int resolve_threads(int threads) {
  if (threads > 0) return threads;
#ifdef CRUMPLE_HAVE_TBB
  return tbb::this_task_arena::max_concurrency();
#else
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
#endif
}

void parallel_for_chunks(std::size_t n, int threads, std::size_t grain,
                         const std::function<void(std::size_t, std::size_t)>& body) {
  if (n == 0) return;
  grain = std::max<std::size_t>(grain, 1);
#ifdef CRUMPLE_HAVE_TBB
  if (threads != 1 && n > grain) {
    tbb::task_arena arena(resolve_threads(threads));
    arena.execute([&] {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain),
                        [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
    });
    return;
  }
#else
  (void)threads;
#endif
  body(0, n);
}

}  // namespace crumple

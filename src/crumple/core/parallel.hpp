#pragma once
/// \file
/// Minimal parallel loop used by detectors. Uses oneTBB when crumple is built with it, a plain
/// serial loop otherwise; callers must not depend on the order in which chunks run.

#include <crumple/core/types.hpp>

#include <cstddef>
#include <functional>

namespace crumple {

/// Number of worker threads `threads` resolves to: 0 means every hardware thread.
int resolve_threads(int threads);

/// Calls `body(begin, end)` on disjoint chunks covering [0, n), at most `threads` at a time
/// (0 = all hardware threads, 1 = serial in the calling thread). `grain` is the smallest chunk.
void parallel_for_chunks(std::size_t n, int threads, std::size_t grain,
                         const std::function<void(std::size_t begin, std::size_t end)>& body);

}  // namespace crumple

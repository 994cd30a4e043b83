#pragma once
/// \file
/// Minimal parallel loop used by detectors, on crumple's own team of threads that spin between
/// loops (the default), or on oneTBB when crumple is built with it; a plain serial loop
/// otherwise. Callers must not depend on the order in which chunks run.
///
/// Why a team of its own: an exact detector's frame is some twenty short parallel loops
/// separated by short serial steps, and oneTBB's workers go to sleep in those steps; waking them
/// costs more than a small loop's work on a virtual machine. The team's workers spin for
/// `kTeamSpin` after each loop before they sleep, so the next loop of the frame finds them awake
/// (bench/parallel_bench.cpp times both).

#include <crumple/core/types.hpp>

#include <chrono>
#include <cstddef>
#include <functional>

namespace crumple {

/// Number of worker threads `threads` resolves to: 0 means every hardware thread.
int resolve_threads(int threads);

/// Calls `body(begin, end)` on disjoint chunks covering [0, n), at most `threads` at a time
/// (0 = all hardware threads, 1 = serial in the calling thread). `grain` is the smallest chunk
/// (the last one may be smaller). An exception thrown by `body` is rethrown here once every
/// chunk has run or been abandoned. A call made from inside a body, or while the team serves
/// another thread's loop, runs serially in the calling thread.
void parallel_for_chunks(std::size_t n, int threads, std::size_t grain,
                         const std::function<void(std::size_t begin, std::size_t end)>& body);

/// A grain for a loop of n items on `threads` threads that gives each thread at least 16 chunks,
/// within [smallest, largest]: a loop's last chunk is one thread's alone, so a chunk that is a
/// large part of a short loop leaves the other threads waiting at its end.
std::size_t balanced_grain(std::size_t n, int threads, std::size_t smallest, std::size_t largest);

/// Which threads `parallel_for_chunks` runs on.
enum class ParallelBackend {
  team,  ///< crumple's team: workers spin for `kTeamSpin` after each loop, then sleep
  tbb,   ///< oneTBB's task arenas (only when crumple is built with TBB)
  host,  ///< the host application's task system (`set_task_dispatcher`)
};

/// A host application's task system (an engine's job system): `dispatch(count, task)` must call
/// `task(i)` exactly once for every i in [0, count), on any of its threads (the calling one
/// included), and return only once every call has returned. `task` never throws: an exception
/// of a loop's body is kept and rethrown by `parallel_for_chunks` after `dispatch` returns.
using TaskDispatcher =
    std::function<void(std::size_t count, const std::function<void(std::size_t index)>& task)>;

/// Runs every later parallel loop as tasks of `dispatcher`, one task per chunk of `grain` items
/// (backend `host`); the detectors' `threads` option then only sizes the work (1 still means
/// serial, in the calling thread). An empty dispatcher goes back to the `team` backend. A loop
/// started from inside a task runs serially in it. Not to be called while a loop runs.
void set_task_dispatcher(TaskDispatcher dispatcher);

/// How long a team worker keeps spinning for the next loop before it sleeps. Only while the
/// loop's thread count fits the hardware threads; oversubscribed workers sleep at once.
inline constexpr std::chrono::microseconds kTeamSpin{500};

/// Chooses the backend for the whole process (default: `team`, or what the environment
/// variable CRUMPLE_PARALLEL says, `team` or `tbb`, read at the first loop; any other value
/// makes every loop throw `InputError` naming it). Throws `InputError` for `tbb` in a build
/// without TBB, and for `host` before `set_task_dispatcher`. Not to be called while a loop runs.
void set_parallel_backend(ParallelBackend backend);
ParallelBackend parallel_backend();
/// Whether this build can run `backend`.
bool has_parallel_backend(ParallelBackend backend);

}  // namespace crumple

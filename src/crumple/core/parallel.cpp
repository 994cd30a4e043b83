#include <crumple/core/parallel.hpp>

#include <crumple/core/error.hpp>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

#ifdef CRUMPLE_HAVE_TBB
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#endif

namespace crumple {

namespace {

using Body = std::function<void(std::size_t, std::size_t)>;

void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  _mm_pause();
#endif
}

/// Read once: `std::thread::hardware_concurrency` reads /sys/devices/system/cpu on every call
/// (glibc), a file read that would dominate a small loop if the team asked it at the start of
/// every loop (bench/parallel_bench.cpp).
int hardware_threads() {
  static const int count = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  return count;
}

/// Set while this thread runs a chunk of a team loop (and for the team's workers always): a
/// loop started from inside one runs serially.
thread_local bool t_in_team = false;

/// The team: workers that claim chunks of the current loop from one atomic word, generation <<
/// 32 | next unit (a unit is `grain` items), each claim about 1 / (2 x threads) of what is left
/// and at least one unit (large first, small at the end, for balance with few claims). The
/// calling thread works too. After a loop a worker spins for `kTeamSpin`, then sleeps on the
/// word until the next loop changes it.
class Team {
 public:
  /// Runs the loop on the caller and `threads - 1` workers; false (nothing run) when another
  /// thread's loop holds the team.
  bool run(int threads, std::size_t n, std::size_t grain, const Body& body) {
    const std::unique_lock lock(busy_, std::try_to_lock);
    if (!lock.owns_lock()) return false;
    const auto workers = static_cast<std::size_t>(threads - 1);
    grow(workers);
    // Closes the previous loop first: a worker that comes late to it may still try to claim a
    // unit of it, and must not succeed with this loop's fields.
    next_.store(std::uint64_t{generation_} << 32 | kClosed);
    body_ = &body;
    error_ = nullptr;
    n_.store(n, std::memory_order_relaxed);
    grain_.store(grain, std::memory_order_relaxed);
    units_.store(static_cast<std::uint32_t>((n + grain - 1) / grain), std::memory_order_relaxed);
    workers_.store(workers, std::memory_order_relaxed);
    spin_.store(threads <= hardware_threads(), std::memory_order_relaxed);
    ++generation_;
    next_.store(std::uint64_t{generation_} << 32);  // publishes the fields above
    if (sleepers_.load() > 0) next_.notify_all();
    t_in_team = true;
    work(generation_);
    t_in_team = false;
    // Every unit is claimed; wait for the workers still inside a chunk.
    while (inside_.load() != 0) cpu_relax();
    if (error_) std::rethrow_exception(error_);
    return true;
  }

 private:
  void grow(std::size_t workers) {
    while (threads_ < workers) {
      const std::size_t id = threads_++;
      std::thread([this, id] { serve(id); }).detach();
    }
  }

  /// Claims and runs chunks of loop `generation` until none is left.
  void work(std::uint32_t generation) {
    for (;;) {
      std::uint64_t word = next_.load();
      std::uint32_t unit = 0, take = 0;
      do {
        if (static_cast<std::uint32_t>(word >> 32) != generation) return;
        unit = static_cast<std::uint32_t>(word);
        const std::uint32_t units = units_.load(std::memory_order_relaxed);  // kClosed > units
        if (unit >= units) return;
        const auto share = static_cast<std::uint32_t>(2 * (workers_.load(std::memory_order_relaxed) + 1));
        take = std::max<std::uint32_t>(1, (units - unit) / share);
      } while (!next_.compare_exchange_weak(word, word + take));
      // The loop cannot end (nor its fields change) while this claim is being run: `inside_`.
      const std::size_t grain = grain_.load(std::memory_order_relaxed), n = n_.load(std::memory_order_relaxed);
      const std::size_t begin = std::size_t{unit} * grain;
      const std::size_t end = std::min(n, (std::size_t{unit} + take) * grain);
      try {
        (*body_)(begin, end);
      } catch (...) {
        const std::lock_guard lock(error_mutex_);
        if (!error_) error_ = std::current_exception();
      }
    }
  }

  /// A worker: waits for a loop (spinning, then asleep), helps with it, again.
  void serve(std::size_t id) {
    t_in_team = true;
    std::uint32_t seen = 0;
    for (;;) {
      std::uint64_t word = next_.load();
      const auto start = std::chrono::steady_clock::now();
      for (unsigned spins = 0; static_cast<std::uint32_t>(word >> 32) == seen; ++spins) {
        const bool spin = spin_.load(std::memory_order_relaxed);
        if (spin && (spins % 256 != 255 || std::chrono::steady_clock::now() - start < kTeamSpin)) {
          cpu_relax();
        } else {
          ++sleepers_;
          word = next_.load();
          if (static_cast<std::uint32_t>(word >> 32) == seen) next_.wait(word);
          --sleepers_;
        }
        word = next_.load();
      }
      seen = static_cast<std::uint32_t>(word >> 32);
      ++inside_;
      // Workers beyond this loop's count sit it out; one that is late finds it over (work
      // checks the generation before it reads anything else).
      if (id < workers_.load(std::memory_order_relaxed)) work(seen);
      --inside_;
    }
  }

  static constexpr std::uint32_t kClosed = std::numeric_limits<std::uint32_t>::max();

  std::mutex busy_;
  std::size_t threads_ = 0;
  std::uint32_t generation_ = 0;
  std::atomic<std::uint64_t> next_{0};
  std::atomic<int> inside_{0}, sleepers_{0};
  std::atomic<std::size_t> n_{0}, grain_{1}, workers_{0};
  std::atomic<std::uint32_t> units_{0};
  std::atomic<bool> spin_{true};
  const Body* body_ = nullptr;
  std::mutex error_mutex_;
  std::exception_ptr error_;
};

/// Never destroyed: its detached workers may still be asleep on it at exit.
Team& team() {
  static auto* t = new Team;
  return *t;
}

#ifdef CRUMPLE_HAVE_TBB
/// One arena per thread count, made on first use and kept: making one costs far more than a
/// small loop's work, and an exact detector's frame makes about ten such calls. Never
/// destroyed, so that no loop can outlive its arena at exit.
tbb::task_arena& arena(int threads) {
  static std::mutex mutex;
  static auto* arenas = new std::map<int, std::unique_ptr<tbb::task_arena>>;
  const std::lock_guard lock(mutex);
  auto& a = (*arenas)[threads];
  if (!a) a = std::make_unique<tbb::task_arena>(threads);
  return *a;
}
#endif

/// The host's dispatcher (`set_task_dispatcher`); set and read only while no loop runs.
TaskDispatcher& host_dispatcher() {
  static auto* d = new TaskDispatcher;
  return *d;
}

/// Set while this thread runs a task of a host loop: a loop started from inside one runs serially.
thread_local bool t_in_host = false;

/// One loop as tasks of the host's dispatcher, chunk i = [i * grain, min(n, (i + 1) * grain)).
void run_on_host(std::size_t n, std::size_t grain, const Body& body) {
  std::mutex error_mutex;
  std::exception_ptr error;
  std::atomic<bool> failed{false};
  host_dispatcher()((n - 1) / grain + 1, [&](std::size_t i) {
    if (failed.load(std::memory_order_relaxed)) return;  // abandoned after an error
    const bool outer = t_in_host;
    t_in_host = true;
    try {
      body(i * grain, std::min(n, (i + 1) * grain));
    } catch (...) {
      const std::lock_guard lock(error_mutex);
      if (!error) error = std::current_exception();
      failed = true;
    }
    t_in_host = outer;
  });
  if (error) std::rethrow_exception(error);
}

/// `backend`, after checking that this build has it (`who` names the request in the error).
ParallelBackend available(ParallelBackend backend, const std::string& who) {
  if (backend == ParallelBackend::host && !host_dispatcher()) {
    throw InputError(who + ": no task dispatcher set (set_task_dispatcher)");
  }
  if (!has_parallel_backend(backend)) throw InputError(who + ": this build of crumple has no TBB (CRUMPLE_WITH_TBB=OFF)");
  return backend;
}

ParallelBackend backend_from_environment() {
  const char* name = std::getenv("CRUMPLE_PARALLEL");
  if (name == nullptr || std::string(name).empty() || std::string(name) == "team") return ParallelBackend::team;
  if (std::string(name) == "tbb") return available(ParallelBackend::tbb, "CRUMPLE_PARALLEL=tbb");
  throw InputError("CRUMPLE_PARALLEL='" + std::string(name) + "': expected 'team' or 'tbb'");
}

std::atomic<ParallelBackend>& chosen_backend() {
  static std::atomic<ParallelBackend> backend{backend_from_environment()};
  return backend;
}

}  // namespace

bool has_parallel_backend(ParallelBackend backend) {
#ifdef CRUMPLE_HAVE_TBB
  (void)backend;
  return true;
#else
  return backend != ParallelBackend::tbb;
#endif
}

void set_parallel_backend(ParallelBackend backend) {
  const char* who = backend == ParallelBackend::tbb    ? "set_parallel_backend(tbb)"
                    : backend == ParallelBackend::host ? "set_parallel_backend(host)"
                                                       : "set_parallel_backend(team)";
  chosen_backend().store(available(backend, who));
}

void set_task_dispatcher(TaskDispatcher dispatcher) {
  const bool set = static_cast<bool>(dispatcher);
  host_dispatcher() = std::move(dispatcher);
  chosen_backend().store(set ? ParallelBackend::host : ParallelBackend::team);
}

ParallelBackend parallel_backend() { return chosen_backend().load(); }

int resolve_threads(int threads) {
  if (threads > 0) return threads;
#ifdef CRUMPLE_HAVE_TBB
  return tbb::this_task_arena::max_concurrency();
#else
  return hardware_threads();
#endif
}

std::size_t balanced_grain(std::size_t n, int threads, std::size_t smallest, std::size_t largest) {
  CRUMPLE_ASSERT(0 < smallest && smallest <= largest);
  return std::clamp<std::size_t>(n / (16 * static_cast<std::size_t>(resolve_threads(threads))), smallest, largest);
}

void parallel_for_chunks(std::size_t n, int threads, std::size_t grain, const Body& body) {
  // Read on every call, so that a bad CRUMPLE_PARALLEL is reported by the first loop of any
  // size, serial ones included.
  const ParallelBackend backend = parallel_backend();
  if (n == 0) return;
  grain = std::max<std::size_t>(grain, 1);
  threads = resolve_threads(threads);
  if (threads != 1 && n > grain) {
    if (backend == ParallelBackend::host && !t_in_host && !t_in_team) {
      run_on_host(n, grain, body);
      return;
    }
    if (backend == ParallelBackend::tbb) {
#ifdef CRUMPLE_HAVE_TBB
      arena(threads).execute([&] {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain),
                          [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
      });
      return;
#endif
    }
    // Units are counted in 32 bits, below the closed mark.
    const bool fits = (n - 1) / grain + 1 < std::numeric_limits<std::uint32_t>::max();
    if (!t_in_team && !t_in_host && backend != ParallelBackend::host && fits &&
        team().run(threads, n, grain, body)) {
      return;
    }
  }
  body(0, n);
}

}  // namespace crumple

// parallel_for_chunks on both backends: every index once, chunks of at least `grain`, loops that
// really use several threads, exceptions, nested and concurrent calls.
#include <crumple/core/parallel.hpp>

#include <crumple/core/error.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

namespace crumple {
namespace {

/// Switches the backend for one test and back.
class BackendScope {
 public:
  explicit BackendScope(ParallelBackend backend) : before_(parallel_backend()) { set_parallel_backend(backend); }
  ~BackendScope() { set_parallel_backend(before_); }
  BackendScope(const BackendScope&) = delete;
  BackendScope& operator=(const BackendScope&) = delete;

 private:
  ParallelBackend before_;
};

std::vector<ParallelBackend> backends() {
  std::vector<ParallelBackend> all{ParallelBackend::team};
  if (has_parallel_backend(ParallelBackend::tbb)) all.push_back(ParallelBackend::tbb);
  return all;
}

const char* name(ParallelBackend backend) { return backend == ParallelBackend::team ? "team" : "tbb"; }

TEST(ParallelForChunks, CoversEveryIndexOnceInChunksOfAtLeastTheGrain) {
  for (const ParallelBackend backend : backends()) {
    const BackendScope scope(backend);
    for (const int threads : {1, 2, 3, 5}) {
      for (const std::size_t grain : {std::size_t{1}, std::size_t{7}, std::size_t{1000}}) {
        for (const std::size_t n : {std::size_t{1}, grain, grain + 1, std::size_t{10007}}) {
          SCOPED_TRACE(testing::Message() << name(backend) << " threads " << threads << " grain " << grain << " n " << n);
          std::vector<std::atomic<int>> hits(n);
          std::mutex mutex;
          std::vector<std::pair<std::size_t, std::size_t>> chunks;
          parallel_for_chunks(n, threads, grain, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) ++hits[i];
            const std::lock_guard lock(mutex);
            chunks.emplace_back(begin, end);
          });
          for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(hits[i].load(), 1) << "index " << i;
          std::sort(chunks.begin(), chunks.end());
          for (std::size_t k = 0; k < chunks.size(); ++k) {
            ASSERT_LT(chunks[k].first, chunks[k].second);
            // The team's chunks are whole grains but the last (TBB splits ranges its own way).
            if (backend == ParallelBackend::team && k + 1 < chunks.size()) {
              EXPECT_EQ((chunks[k].second - chunks[k].first) % grain, 0u);
            }
          }
        }
      }
    }
  }
}

TEST(BalancedGrain, SixteenChunksPerThreadWithinTheBounds) {
  EXPECT_EQ(balanced_grain(23203, 2, 256, 2048), 23203u / 32);  // the funnel's candidates
  EXPECT_EQ(balanced_grain(573319, 2, 256, 2048), 2048u);        // cloth-ball's: the largest grain
  EXPECT_EQ(balanced_grain(1000, 2, 256, 2048), 256u);           // few items: the smallest
  EXPECT_EQ(balanced_grain(0, 4, 1, 8), 1u);
  EXPECT_EQ(balanced_grain(23203, 1, 256, 4096), 23203u / 16);
  EXPECT_EQ(balanced_grain(64000, 4, 1, 100000), 1000u);
  // 0 threads: every hardware thread.
  const auto all = static_cast<std::size_t>(resolve_threads(0));
  EXPECT_EQ(balanced_grain(std::size_t{1} << 20, 0, 1, std::size_t{1} << 20), (std::size_t{1} << 20) / (16 * all));
}

TEST(ParallelForChunks, TwoThreadsRunChunksAtOnce) {
  // The first chunk to start waits until a chunk runs on another thread: the loop ends only if
  // two threads work on it at once (a 10 s limit instead of a hang otherwise).
  for (const ParallelBackend backend : backends()) {
    SCOPED_TRACE(name(backend));
    // TBB gives an arena no worker on a single hardware thread; the team always has its own.
    if (backend == ParallelBackend::tbb && std::thread::hardware_concurrency() < 2) continue;
    const BackendScope scope(backend);
    for (int round = 0; round < 20; ++round) {
      std::atomic<int> entered{0};
      std::atomic<bool> met{false};
      std::mutex mutex;
      std::set<std::thread::id> ids;
      parallel_for_chunks(64, 2, 1, [&](std::size_t, std::size_t) {
        {
          const std::lock_guard lock(mutex);
          ids.insert(std::this_thread::get_id());
          if (ids.size() > 1) met = true;
        }
        if (entered++ == 0) {
          const auto limit = std::chrono::steady_clock::now() + std::chrono::seconds(10);
          while (!met && std::chrono::steady_clock::now() < limit) std::this_thread::yield();
        }
      });
      ASSERT_TRUE(met.load()) << "round " << round << ": only one thread ran the loop";
    }
  }
}

TEST(ParallelForChunks, RethrowsAnExceptionOfTheBodyAndStaysUsable) {
  for (const ParallelBackend backend : backends()) {
    SCOPED_TRACE(name(backend));
    const BackendScope scope(backend);
    for (const int threads : {1, 2, 3}) {
      EXPECT_THROW(parallel_for_chunks(1000, threads, 10,
                                       [](std::size_t begin, std::size_t end) {
                                         if (begin <= 500 && 500 < end) throw std::runtime_error("chunk 500");
                                       }),
                   std::runtime_error);
      std::atomic<std::size_t> sum{0};
      parallel_for_chunks(1000, threads, 10, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) sum += i;
      });
      EXPECT_EQ(sum.load(), 999u * 1000u / 2);
    }
  }
}

TEST(ParallelForChunks, NestedLoopsCoverTheirRanges) {
  for (const ParallelBackend backend : backends()) {
    SCOPED_TRACE(name(backend));
    const BackendScope scope(backend);
    std::vector<std::atomic<int>> hits(40 * 50);
    parallel_for_chunks(40, 2, 1, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        parallel_for_chunks(50, 2, 4, [&](std::size_t b, std::size_t e) {
          for (std::size_t j = b; j < e; ++j) ++hits[i * 50 + j];
        });
      }
    });
    for (std::size_t k = 0; k < hits.size(); ++k) ASSERT_EQ(hits[k].load(), 1) << k;
  }
}

TEST(ParallelForChunks, LoopsFromSeveralThreadsAtOnce) {
  // Four threads each run loops at the same time: each loop covers its range once (the team
  // serves one of them at a time; the others run in their own threads).
  for (const ParallelBackend backend : backends()) {
    SCOPED_TRACE(name(backend));
    const BackendScope scope(backend);
    std::atomic<int> failures{0};
    std::vector<std::thread> callers;
    for (int c = 0; c < 4; ++c) {
      callers.emplace_back([&failures] {
        for (int loop = 0; loop < 50; ++loop) {
          std::vector<std::atomic<int>> hits(3000);
          parallel_for_chunks(hits.size(), 2, 16, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) ++hits[i];
          });
          for (const auto& h : hits) failures += h.load() == 1 ? 0 : 1;
        }
      });
    }
    for (auto& t : callers) t.join();
    EXPECT_EQ(failures.load(), 0);
  }
}

TEST(ParallelForChunks, BackendChoice) {
  EXPECT_TRUE(has_parallel_backend(ParallelBackend::team));
  if (!has_parallel_backend(ParallelBackend::tbb)) {
    EXPECT_THROW(set_parallel_backend(ParallelBackend::tbb), InputError);
  }
  for (const ParallelBackend backend : backends()) {
    const BackendScope scope(backend);
    EXPECT_EQ(parallel_backend(), backend);
  }
  EXPECT_GE(resolve_threads(0), 1);
  EXPECT_EQ(resolve_threads(3), 3);
}

}  // namespace
}  // namespace crumple

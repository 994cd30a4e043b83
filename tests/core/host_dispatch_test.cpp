// parallel_for_chunks on the host application's task system (`set_task_dispatcher`): every
// index once in chunks of the grain, on the host's threads, exceptions rethrown, nested loops
// serial, `threads = 1` serial, and back to the team when the dispatcher is removed.
#include <crumple/core/error.hpp>
#include <crumple/core/parallel.hpp>
#include <support/host_pool.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <thread>
#include <vector>

namespace crumple {
namespace {

TEST(HostDispatch, EveryIndexOnceInTasksOfTheGrainOnTheHostsThreads) {
  testing::HostPool pool(3);
  const testing::DispatcherScope scope(pool.dispatcher());
  EXPECT_EQ(parallel_backend(), ParallelBackend::host);
  std::vector<std::atomic<int>> seen(1000);
  parallel_for_chunks(seen.size(), 0, 64, [&](std::size_t begin, std::size_t end) {
    EXPECT_TRUE(end - begin == 64 || end == seen.size());
    for (std::size_t i = begin; i < end; ++i) seen[i].fetch_add(1);
  });
  for (const auto& s : seen) EXPECT_EQ(s.load(), 1);
  EXPECT_EQ(pool.dispatches(), 1u);
  EXPECT_EQ(pool.tasks(), 16u);  // ceil(1000 / 64)
  EXPECT_GE(pool.threads().size(), 1u);
  // threads = 1 and loops of one chunk stay in the calling thread, without a dispatch.
  parallel_for_chunks(1000, 1, 64, [](std::size_t, std::size_t) {});
  parallel_for_chunks(10, 0, 64, [](std::size_t, std::size_t) {});
  EXPECT_EQ(pool.dispatches(), 1u);
}

TEST(HostDispatch, RethrowsTheBodysExceptionAndNestedLoopsRunSerially) {
  testing::HostPool pool(2);
  const testing::DispatcherScope scope(pool.dispatcher());
  EXPECT_THROW(parallel_for_chunks(100, 0, 1,
                                   [](std::size_t begin, std::size_t) {
                                     if (begin == 37) throw std::runtime_error("body");
                                   }),
               std::runtime_error);
  const std::size_t before = pool.dispatches();
  std::atomic<std::size_t> inner{0};
  parallel_for_chunks(8, 0, 1, [&](std::size_t, std::size_t) {
    const std::thread::id me = std::this_thread::get_id();
    parallel_for_chunks(50, 0, 1, [&](std::size_t b, std::size_t e) {
      EXPECT_EQ(std::this_thread::get_id(), me);
      inner += e - b;
    });
  });
  EXPECT_EQ(inner.load(), 8u * 50u);
  EXPECT_EQ(pool.dispatches(), before + 1);  // the nested loops made no dispatch
}

TEST(HostDispatch, ChoosingTheBackend) {
  ASSERT_EQ(parallel_backend(), ParallelBackend::team);
  EXPECT_THROW(set_parallel_backend(ParallelBackend::host), InputError);  // no dispatcher yet
  {
    testing::HostPool pool(1);
    const testing::DispatcherScope scope(pool.dispatcher());
    set_parallel_backend(ParallelBackend::team);  // kept, but not used
    parallel_for_chunks(100, 2, 1, [](std::size_t, std::size_t) {});
    EXPECT_EQ(pool.dispatches(), 0u);
    set_parallel_backend(ParallelBackend::host);
    parallel_for_chunks(100, 2, 1, [](std::size_t, std::size_t) {});
    EXPECT_EQ(pool.dispatches(), 1u);
  }
  EXPECT_EQ(parallel_backend(), ParallelBackend::team);
  EXPECT_TRUE(has_parallel_backend(ParallelBackend::host));
}

}  // namespace
}  // namespace crumple

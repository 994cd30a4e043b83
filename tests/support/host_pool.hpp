#pragma once
// A stand-in for an engine's job system, for the `set_task_dispatcher` tests: each dispatch
// runs its tasks on `workers` threads of its own plus the calling thread, each task claimed
// once from an atomic counter. Counts the tasks and the threads that ran them.
#include <crumple/core/parallel.hpp>

#include <atomic>
#include <cstddef>
#include <mutex>
#include <set>
#include <thread>
#include <utility>
#include <vector>

namespace crumple::testing {

class HostPool {
 public:
  explicit HostPool(int workers) : workers_(workers) {}

  TaskDispatcher dispatcher() {
    return [this](std::size_t count, const std::function<void(std::size_t)>& task) {
      std::atomic<std::size_t> next{0};
      const auto work = [&] {
        for (std::size_t i = next.fetch_add(1); i < count; i = next.fetch_add(1)) {
          task(i);
          tasks_.fetch_add(1);
          const std::lock_guard lock(mutex_);
          threads_.insert(std::this_thread::get_id());
        }
      };
      std::vector<std::thread> pool;
      for (int w = 0; w < workers_; ++w) pool.emplace_back(work);
      work();
      for (std::thread& t : pool) t.join();
      dispatches_.fetch_add(1);
    };
  }

  std::size_t tasks() const { return tasks_.load(); }
  std::size_t dispatches() const { return dispatches_.load(); }
  std::set<std::thread::id> threads() const {
    const std::lock_guard lock(mutex_);
    return threads_;
  }

 private:
  int workers_;
  std::atomic<std::size_t> tasks_{0}, dispatches_{0};
  mutable std::mutex mutex_;
  std::set<std::thread::id> threads_;
};

/// Installs a dispatcher for one test and goes back to the `team` backend after it.
class DispatcherScope {
 public:
  explicit DispatcherScope(TaskDispatcher d) { set_task_dispatcher(std::move(d)); }
  ~DispatcherScope() { set_task_dispatcher({}); }
  DispatcherScope(const DispatcherScope&) = delete;
  DispatcherScope& operator=(const DispatcherScope&) = delete;
};

}  // namespace crumple::testing

/// Micro-benchmarks of `parallel_for_chunks`: what starting and joining one loop costs, for
/// loops whose bodies do almost nothing (Google Benchmark's "Time" column, one loop per
/// iteration). An exact detector's frame runs about twenty loops, so on the small scenes a few
/// microseconds each are a few percent of a two-thread frame.
///
///   build/release/bench/parallel_bench --benchmark_min_time=0.5
///
/// Arguments: items in the loop, threads. The team's workers spin between loops back to back,
/// as they do between a frame's loops.

#include <crumple/core/parallel.hpp>

#include <benchmark/benchmark.h>

#include <cstddef>
#include <vector>

namespace {

void run_loops(benchmark::State& state, crumple::ParallelBackend backend) {
  if (!crumple::has_parallel_backend(backend)) {
    state.SkipWithError("this build has no such backend");
    return;
  }
  const crumple::ParallelBackend before = crumple::parallel_backend();  // CRUMPLE_PARALLEL may have chosen it
  crumple::set_parallel_backend(backend);
  const auto n = static_cast<std::size_t>(state.range(0));
  const auto threads = static_cast<int>(state.range(1));
  std::vector<double> items(n, 1.0);
  for (auto _ : state) {
    crumple::parallel_for_chunks(n, threads, 1, [&](std::size_t begin, std::size_t end) {
      double sum = 0;
      for (std::size_t i = begin; i < end; ++i) sum += items[i];
      benchmark::DoNotOptimize(sum);
    });
  }
  crumple::set_parallel_backend(before);
}

void BM_team_loop(benchmark::State& state) { run_loops(state, crumple::ParallelBackend::team); }
void BM_tbb_loop(benchmark::State& state) { run_loops(state, crumple::ParallelBackend::tbb); }

void loop_sizes(benchmark::internal::Benchmark* b) {
  for (const int threads : {1, 2}) {
    for (const int n : {2, 64, 4096}) b->Args({n, threads});
  }
}

}  // namespace

BENCHMARK(BM_team_loop)->Apply(loop_sizes);
BENCHMARK(BM_tbb_loop)->Apply(loop_sizes);

BENCHMARK_MAIN();

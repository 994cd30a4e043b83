// Cost per frame of the stochastic detector vs mesh size at fixed parameters (the point of the
// method: the cost is set by the parameters, not by the number of elements).
//
// Scene: the built-in folding sequence (detect/compare.hpp) on n × n lattices, n = 10, 30, 100,
// 300 (200 to 180 000 triangles), thickness ℓ/4, frames 16..31 of 32 played back and forth
// (the part with contact). Each benchmark iteration is one `update()`. Counters are per frame:
// distance evaluations, convergence steps, pairs drawn, kept, colliding, contacts reported.
//
//   build-sto/bench/stochastic_bench --benchmark_counters_tabular=true
#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>

#include <benchmark/benchmark.h>

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace crumple {
namespace {

struct Scene {
  std::unique_ptr<FoldingSequence> sequence;
  std::vector<Positions> frames;  ///< the played frames, in order (back and forth)
};

const Scene& scene(Index n) {
  static std::map<Index, Scene> cache;
  auto it = cache.find(n);
  if (it != cache.end()) return it->second;
  Scene s;
  s.sequence = std::make_unique<FoldingSequence>(FoldingParams{.n = n, .frames = 32, .seed = 1});
  for (std::size_t i = 16; i < 32; ++i) s.frames.push_back(s.sequence->positions(i));
  for (std::size_t i = 30; i > 16; --i) s.frames.push_back(s.sequence->positions(i));
  return cache.emplace(n, std::move(s)).first->second;
}

void run(benchmark::State& state, const std::string& spec) {
  const Index n = static_cast<Index>(state.range(0));
  const Scene& s = scene(n);
  auto detector = make_detector(MethodSpec::parse(spec), {.thickness = s.sequence->thickness()});
  detector->set_topology(s.sequence->mesh().topology_ptr());
  ContactSet contacts;
  std::size_t frame = 0;
  for (std::size_t i = 0; i < s.frames.size(); ++i) detector->update(s.frames[i], contacts);  // warm up
  double evals = 0, steps = 0, drawn = 0, kept = 0, colliding = 0, found = 0;
  for (auto _ : state) {
    detector->update(s.frames[frame], contacts);
    frame = (frame + 1) % s.frames.size();
    const DetectorStats& st = detector->stats();
    evals += st.get("distance_evals");
    steps += st.get("converge_steps");
    drawn += st.get("drawn");
    kept += st.get("kept");
    colliding += st.get("colliding");
    found += static_cast<double>(contacts.size());
  }
  using benchmark::Counter;
  state.counters["triangles"] = s.sequence->mesh().num_faces();
  state.counters["evals"] = Counter(evals, Counter::kAvgIterations);
  state.counters["steps"] = Counter(steps, Counter::kAvgIterations);
  state.counters["drawn"] = Counter(drawn, Counter::kAvgIterations);
  state.counters["kept"] = Counter(kept, Counter::kAvgIterations);
  state.counters["colliding"] = Counter(colliding, Counter::kAvgIterations);
  state.counters["contacts"] = Counter(found, Counter::kAvgIterations);
}

void register_all() {
  for (const char* variant : {"simple", "propagate-by-convergence", "direct", "vertex"}) {
    for (int setting : {2, 1}) {
      const std::string spec = std::string("stochastic:variant=") + variant + ",setting=" + std::to_string(setting);
      benchmark::RegisterBenchmark(spec.c_str(), [spec](benchmark::State& st) { run(st, spec); })
          ->ArgName("n")
          ->Arg(10)
          ->Arg(30)
          ->Arg(100)
          ->Arg(300)
          ->Unit(benchmark::kMillisecond);
    }
  }
}

}  // namespace
}  // namespace crumple

int main(int argc, char** argv) {
  crumple::register_all();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

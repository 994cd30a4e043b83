// Simulation cost per step, by part: integration (each integrator), detection (naive and the
// exact accelerated methods), self-collision response, on the hanging-cloth scene at 10x10 and
// 100x100 after it has fallen for a while (so there are contacts to respond to).
//   ./build/release/bench/sim_bench --benchmark_format=json
#include <crumple/sim/scene.hpp>

#include <benchmark/benchmark.h>

#include <map>
#include <memory>

namespace {

using namespace crumple;
using namespace crumple::sim;

/// Scene state after `frames` frames of the default simulation (cached per size).
const Scene& fallen_cloth(int n) {
  static std::map<int, std::unique_ptr<Scene>> cache;
  auto& slot = cache[n];
  if (!slot) {
    Scene s = make_scene(SceneSpec::parse("hanging-cloth:nx=" + std::to_string(n) + ",ny=" + std::to_string(n)), 1);
    Settings settings = s.settings;
    settings.method = MethodSpec::parse("hash");
    Simulation sim(s.model, s.state, s.field, {}, {}, settings);
    for (int f = 0; f < (n <= 10 ? 120 : 20); ++f) sim.advance_frame();
    s.state = sim.state();
    slot = std::make_unique<Scene>(std::move(s));
  }
  return *slot;
}

void BM_Integrate(benchmark::State& bench, IntegratorKind kind, int n) {
  const Scene& s = fallen_cloth(n);
  auto integrator = make_integrator(kind);
  State state = s.state;
  for (auto _ : bench) {
    integrator->step(s.model, s.field, state, s.settings.dt);
    benchmark::DoNotOptimize(state.x.data());
  }
  bench.counters["cg_iterations"] = integrator->last_iterations();
}

void BM_Detect(benchmark::State& bench, const char* method, int n) {
  const Scene& s = fallen_cloth(n);
  DetectorOptions options = s.settings.detector;
  auto detector = make_detector(MethodSpec::parse(method), options);
  detector->set_topology(s.model.topology_ptr());
  ContactSet contacts;
  for (auto _ : bench) {
    detector->update(s.state.x, contacts);
    benchmark::DoNotOptimize(contacts.ee.data());
  }
  bench.counters["contacts"] = static_cast<double>(contacts.size());
  bench.counters["collision_share"] = collision_share(s.model.topology(), contacts);
}

void BM_Response(benchmark::State& bench, int n) {
  const Scene& s = fallen_cloth(n);
  auto detector = make_detector(MethodSpec::parse("hash"), s.settings.detector);
  detector->set_topology(s.model.topology_ptr());
  ContactSet contacts;
  detector->update(s.state.x, contacts);
  const auto faces = s.model.topology().faces();
  response::ResponseOptions options;
  options.thickness = s.settings.detector.thickness;
  for (auto _ : bench) {
    bench.PauseTiming();
    State state = s.state;
    bench.ResumeTiming();
    const auto stencils = response::make_stencils(contacts, faces);
    benchmark::DoNotOptimize(response::resolve(stencils, s.model.inv_mass(), state.x, state.v, options));
  }
  bench.counters["contacts"] = static_cast<double>(contacts.size());
}

void register_all() {
  for (int n : {10, 100}) {
    for (IntegratorKind k : all_integrators()) {
      benchmark::RegisterBenchmark(("integrate/" + std::string(to_string(k)) + "/" + std::to_string(n)).c_str(),
                                   BM_Integrate, k, n)
          ->Unit(benchmark::kMillisecond);
    }
    for (const char* method : {"naive", "hash", "kdop", "sap"}) {
      auto* b = benchmark::RegisterBenchmark(("detect/" + std::string(method) + "/" + std::to_string(n)).c_str(),
                                             BM_Detect, method, n);
      b->Unit(benchmark::kMillisecond);
      if (n >= 100 && std::string(method) == "naive") b->Iterations(1);
    }
    benchmark::RegisterBenchmark(("response/" + std::to_string(n)).c_str(), BM_Response, n)
        ->Unit(benchmark::kMillisecond);
  }
}

}  // namespace

int main(int argc, char** argv) {
  register_all();
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

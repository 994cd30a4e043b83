// Simulation cost per step, by part: integration (each integrator), detection (naive and the
// exact accelerated methods), self-collision response, on the hanging-cloth scene at 10x10 and
// 100x100 after it has fallen for a while (so there are contacts to respond to).
// `frame/SCENE/N`: whole frames of the built-in scenes with their defaults (projective dynamics,
// one detection per frame with kdop, proximity response), after a warm-up of 30 frames (0.5 s,
// the cloth in contact), reporting ms per frame by part, contacts (VF + EE closer than the
// thickness), intersecting triangle pairs at the last frame (exact: kdop with kinds tt) and
// frames per second (docs/benchmarks/simulation.md):
//   ./build/release/bench/sim_bench --benchmark_filter=frame/ --benchmark_out=sim.json
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

/// Whole frames of a built-in scene with its default settings.
void BM_Frame(benchmark::State& bench, const std::string& spec) {
  Scene s = make_scene(SceneSpec::parse(spec), 1);
  Settings settings = s.settings;
  settings.method = MethodSpec::parse("kdop");
  Simulation sim(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles), std::move(s.kinematics),
                 settings);
  sim.current_stats();
  for (int f = 0; f < 30; ++f) sim.advance_frame();
  double integrate = 0, detect = 0, response = 0, contacts = 0, frames = 0;
  for (auto _ : bench) {
    const FrameStats st = sim.advance_frame();
    integrate += st.integrate_ms;
    detect += st.detect_ms;
    response += st.response_ms;
    contacts += static_cast<double>(st.vf + st.ee);
    frames += 1;
  }
  DetectorOptions tt_options;
  tt_options.kinds = ContactKinds::parse("tt");
  auto tt = make_detector(MethodSpec::parse("kdop"), tt_options);
  tt->set_topology(sim.model().topology_ptr());
  ContactSet intersections;
  tt->update(sim.state().x, intersections);
  bench.counters["integrate_ms"] = integrate / frames;
  bench.counters["detect_ms"] = detect / frames;
  bench.counters["response_ms"] = response / frames;
  bench.counters["contacts"] = contacts / frames;
  bench.counters["tt_pairs_last_frame"] = static_cast<double>(intersections.tt.size());
  bench.counters["vertices"] = sim.model().num_particles();
  bench.counters["fps"] = benchmark::Counter(frames, benchmark::Counter::kIsRate);
}

void register_all() {
  for (const char* scene : {"cloth-on-sphere", "crumple"}) {
    for (int n : {32, 64, 100}) {
      const std::string spec = std::string(scene) + ":n=" + std::to_string(n);
      benchmark::RegisterBenchmark(("frame/" + spec).c_str(), BM_Frame, spec)
          ->Unit(benchmark::kMillisecond)
          ->Iterations(20)
          ->UseRealTime();
    }
  }
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

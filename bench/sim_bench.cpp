// Simulation cost per step, by part: integration (each integrator), detection (naive and the
// exact accelerated methods), self-collision response, on the hanging-cloth scene at 10x10 and
// 100x100 after it has fallen for a while (so there are contacts to respond to).
// `frame/SCENE/N`: whole frames of the built-in scenes with their defaults (projective dynamics,
// one detection per frame with kdop, proximity response), after a warm-up of 30 frames (0.5 s,
// the cloth in contact), reporting ms per frame by part, contacts (VF + EE closer than the
// thickness), the CCD fail-safe's ms, impacts and frozen vertices, intersecting triangle pairs
// counted at every frame (exact: kdop with kinds tt; frames with any, the most, the mean) and
// frames per second; `frame-no-fail-safe/...` the same without the fail-safe, at n <= 64;
// `frame-late/...` the same after 300 frames (the cloth at rest; the crumple pile formed)
// (docs/benchmarks/simulation.md):
//   ./build/release/bench/sim_bench --benchmark_filter=frame/ --benchmark_out=sim.json
//   ./build/release/bench/sim_bench --benchmark_format=json
// `integrate-frame/SCENE/threads:T`: one frame's integration steps alone (the scene's model and
// integrator options, T threads).
// `--check-frames=SPEC --frames=N`: N frames of one scene, intersections counted at every frame
// (see `check_frames`).
#include <crumple/sim/scene.hpp>

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>

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

/// The exact detector of intersecting triangle pairs (`kdop`, kinds `tt`) over `sim`'s mesh, on
/// `threads` threads (< 0: the detector's default).
std::unique_ptr<Detector> intersection_counter(const Simulation& sim, int threads = -1) {
  DetectorOptions options;
  options.kinds = ContactKinds::parse("tt");
  if (threads >= 0) options.threads = threads;
  auto tt = make_detector(MethodSpec::parse("kdop"), options);
  tt->set_topology(sim.model().topology_ptr());
  return tt;
}

/// Whole frames of a built-in scene with its default settings (`fail_safe` off: the baseline).
/// Intersecting triangle pairs are counted at every frame, warm-up included, outside the timing.
void BM_Frame(benchmark::State& bench, const std::string& spec, bool fail_safe, int late_warm_up) {
  Scene s = make_scene(SceneSpec::parse(spec), 1);
  Settings settings = s.settings;
  settings.method = MethodSpec::parse("kdop");
  settings.fail_safe = fail_safe;
  // The baseline without the fail-safe also runs without untangling (which would query and
  // repair intersections every frame); with it, untangling costs one query at the first frame.
  settings.untangle = fail_safe;
  Simulation sim(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles), std::move(s.kinematics),
                 settings);
  auto tt = intersection_counter(sim);
  ContactSet intersections;
  double tt_frames = 0, tt_max = 0, tt_sum = 0, counted = 0;
  const auto count_intersections = [&] {
    tt->update(sim.state().x, intersections);
    const auto pairs = static_cast<double>(intersections.tt.size());
    tt_frames += pairs > 0 ? 1 : 0;
    tt_max = std::max(tt_max, pairs);
    tt_sum += pairs;
    counted += 1;
  };
  sim.current_stats();
  // The sweeping sphere reaches the cloth at frame ~57: its rows time frames 46..65.
  const int warm_up = late_warm_up > 0 ? late_warm_up : spec.find("sweep-speed") == std::string::npos ? 30 : 45;
  try {
    for (int f = 0; f < warm_up; ++f) {
      sim.advance_frame();
      count_intersections();
    }
  } catch (const DivergenceError& e) {
    bench.SkipWithError(e.what());
    return;
  }
  double integrate = 0, detect = 0, response = 0, ccd = 0, contacts = 0, impacts = 0, frozen = 0, queries = 0,
         frames = 0;
  for (auto _ : bench) {
    FrameStats st;
    try {
      st = sim.advance_frame();
    } catch (const DivergenceError& e) {
      bench.SkipWithError(e.what());
      break;
    }
    integrate += st.integrate_ms;
    detect += st.detect_ms;
    response += st.response_ms;
    ccd += st.ccd_ms;
    contacts += static_cast<double>(st.vf + st.ee);
    impacts += static_cast<double>(st.ccd_impacts);
    frozen += static_cast<double>(st.ccd_frozen);
    queries += st.ccd_queries;
    frames += 1;
    bench.PauseTiming();
    count_intersections();
    bench.ResumeTiming();
  }
  bench.counters["integrate_ms"] = integrate / frames;
  bench.counters["detect_ms"] = detect / frames;
  bench.counters["response_ms"] = response / frames;
  bench.counters["ccd_ms"] = ccd / frames;
  bench.counters["contacts"] = contacts / frames;
  bench.counters["ccd_impacts"] = impacts / frames;
  bench.counters["ccd_frozen"] = frozen / frames;
  bench.counters["ccd_queries"] = queries / frames;
  bench.counters["tt_frames"] = tt_frames;
  bench.counters["tt_max"] = tt_max;
  bench.counters["tt_mean"] = tt_sum / counted;
  bench.counters["frames_counted"] = counted;
  bench.counters["vertices"] = sim.model().num_particles();
  bench.counters["fps"] = benchmark::Counter(frames, benchmark::Counter::kIsRate);
}

/// One frame's integration (the scene's steps per frame, nothing else) of a built-in scene's
/// model from its initial state, with its default integrator options on `threads` threads: the
/// integrator alone, outside the frame's other parts (the factorization is paid before timing).
void BM_IntegrateFrame(benchmark::State& bench, const std::string& spec, int threads) {
  const Scene s = make_scene(SceneSpec::parse(spec), 1);
  IntegratorOptions options = s.settings.integrator_options;
  options.threads = threads;
  auto integrator = make_integrator(s.settings.integrator, options);
  State state = s.state;
  integrator->step(s.model, s.field, state, s.settings.dt);
  for (auto _ : bench) {
    bench.PauseTiming();
    state = s.state;
    bench.ResumeTiming();
    for (int k = 0; k < s.settings.substeps; ++k) integrator->step(s.model, s.field, state, s.settings.dt);
    benchmark::DoNotOptimize(state.x.data());
  }
  bench.counters["factorizations"] = static_cast<double>(integrator->factorizations());
}

void register_all() {
  for (const char* scene : {"cloth-on-sphere", "crumple", "cloth-on-sphere:sweep-speed=5"}) {
    for (int n : {32, 64, 100}) {
      std::string spec = std::string(scene) + (std::string(scene).find(':') == std::string::npos ? ":" : ",") +
                         "n=" + std::to_string(n);
      benchmark::RegisterBenchmark(("frame/" + spec).c_str(), BM_Frame, spec, true, 0)
          ->Unit(benchmark::kMillisecond)
          ->Iterations(20)
          ->UseRealTime();
      if (n <= 64) {
        benchmark::RegisterBenchmark(("frame-no-fail-safe/" + spec).c_str(), BM_Frame, spec, false, 0)
            ->Unit(benchmark::kMillisecond)
            ->Iterations(20)
            ->UseRealTime();
      }
    }
  }
  // Frames 301..320: the cloth at rest on the sphere; the crumple walls just stopped, the pile
  // formed (its most expensive frames: thousands of contacts).
  for (const char* scene : {"cloth-on-sphere", "crumple"}) {
    for (int n : {64, 100}) {
      const std::string spec = std::string(scene) + ":n=" + std::to_string(n);
      benchmark::RegisterBenchmark(("frame-late/" + spec).c_str(), BM_Frame, spec, true, 300)
          ->Unit(benchmark::kMillisecond)
          ->Iterations(20)
          ->UseRealTime();
    }
  }
  for (const char* scene : {"cloth-on-sphere", "crumple"}) {
    for (int n : {64, 100}) {
      for (int threads : {1, 2}) {
        const std::string spec = std::string(scene) + ":n=" + std::to_string(n);
        benchmark::RegisterBenchmark(("integrate-frame/" + spec + "/threads:" + std::to_string(threads)).c_str(),
                                     BM_IntegrateFrame, spec, threads)
            ->Unit(benchmark::kMillisecond)
            ->UseRealTime();
      }
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

namespace {

/// The signal (SIGINT or SIGTERM, e.g. from `timeout`) that asked `--check-frames` to stop after
/// the current frame, or 0.
volatile std::sig_atomic_t g_stop_signal = 0;
extern "C" void on_stop_signal(int signal) { g_stop_signal = signal; }

/// Seconds between progress lines of `--check-frames`: CRUMPLE_PROGRESS_SECONDS (as for the
/// `crumple` program) or 10.
double progress_period() {
  if (const char* env = std::getenv("CRUMPLE_PROGRESS_SECONDS")) {
    char* end = nullptr;
    const double v = std::strtod(env, &end);
    if (end != env && v >= 0) return v;
  }
  return 10;
}

/// A number option's value, or an error naming the option.
double number_option(const std::string& arg, std::size_t prefix) {
  const std::string value = arg.substr(prefix);
  char* end = nullptr;
  const double v = std::strtod(value.c_str(), &end);
  if (value.empty() || end != value.c_str() + value.size() || !std::isfinite(v)) {
    throw InputError("sim_bench --check-frames: '" + arg + "' expects a number");
  }
  return v;
}

/// FNV-1a over the bits of every position and velocity: equal digests mean the same state bit
/// for bit (up to a 64-bit collision), so `--verbose` logs of two builds compare exactly.
std::uint64_t state_digest(const State& s) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  const auto mix = [&h](const std::vector<Vec3>& v) {
    for (const Vec3& p : v) {
      for (int c = 0; c < 3; ++c) {
        std::uint64_t bits;
        const Scalar x = p[c];
        std::memcpy(&bits, &x, sizeof bits);
        for (int b = 0; b < 8; ++b) h = (h ^ ((bits >> (8 * b)) & 0xff)) * 0x100000001b3ULL;
      }
    }
  };
  mix(s.x);
  mix(s.v);
  return h;
}

}  // namespace

/// `--check-frames=SPEC [--frames=N] [--fail-safe=off] [--response=on] [--search-factor=F]
/// [--motion-search=on] [--motion-retries=N] [--contact-forces=on|off] [--relaxation=W] [--rho=R] [--iterations=N] [--settle=F]
/// [--substeps=S] [--threads=T]
/// [--verbose]`:
/// runs N frames (1000) of the built-in scene SPEC with the `frame/` rows' settings
/// (`--response=on` turns the response, and with it the fail-safe, on for scenes that have it
/// off, e.g. hanging-cloth), counting the intersecting triangle pairs after every frame with the
/// exact detector (kdop, kinds tt, as the rows do). `--search-factor` sets
/// `Settings::search_factor` (the proximity radius in thicknesses), `--motion-search=on`
/// turns `Settings::motion_search` on (contacts from the frame's predicted motion), `--motion-retries`
/// sets `Settings::motion_retries` (the scene's otherwise: 1 for crumple and for cloth-on-sphere above n = 100, 3 for twisted-ribbon above nx = 100, 0 for
/// the others), `--contact-forces` sets `Settings::contact_forces` (the scene's otherwise), `--relaxation`
/// `Settings::proximity_relaxation` (the scene's otherwise: 0.5 for crumple, 1 for the others); `--rho`, `--iterations` and
/// `--settle` the projective step's Chebyshev ρ, iterations and settling tolerance (a fraction of
/// h_c, as the ribbon's `settle` key); `--substeps` the steps per frame (the frame's length kept);
/// `--threads` the detector's and the integrator's threads (0: all); `--flat-rings` sets
/// `Settings::flat_neighbour_rings` (0 keeps the flat neighbours' pairs).
/// Prints every frame with intersections (`--verbose`: every frame, with a digest of the state's
/// bits), a progress line every 10 s (CRUMPLE_PROGRESS_SECONDS sets the period) and a summary line, also when the run stops early:
/// on a divergence, or on SIGINT / SIGTERM (after the current frame). Output is line-buffered,
/// so a log of a killed run keeps every line printed. Exit status: 0 when every frame of the N
/// ran clean, 1 when a frame intersects or the run diverged, 3 when stopped by a signal first.
int check_frames(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  std::string spec;
  int frames = 1000, threads = -1;
  bool fail_safe = true, response = false, verbose = false, motion_search = false;
  double search_factor = 0;  // 0: the scene's
  double rho = -1;           // < 0: the scene's
  double settle = -1;        // < 0: the scene's
  double relaxation = -1;    // < 0: the scene's
  int iterations_option = 0, substeps = 0;  // 0: the scene's
  int flat_rings = -1;                      // < 0: the default
  int motion_retries = -1;                  // < 0: the scene's
  int contact_forces = -1;                  // < 0: the scene's, else 0 (off) or 1 (on)
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (a.rfind("--check-frames=", 0) == 0) {
        spec = a.substr(15);
      } else if (a.rfind("--frames=", 0) == 0) {
        const double v = number_option(a, 9);
        if (!(v >= 1) || v != std::floor(v) || v > 1e9) throw InputError("--frames expects an integer >= 1");
        frames = static_cast<int>(v);
      } else if (a == "--fail-safe=off") {
        fail_safe = false;
      } else if (a == "--response=on") {
        response = true;
      } else if (a == "--motion-search=on") {
        motion_search = true;
      } else if (a == "--verbose") {
        verbose = true;
      } else if (a.rfind("--search-factor=", 0) == 0) {
        search_factor = number_option(a, 16);
        if (!(search_factor > 1)) throw InputError("--search-factor expects a number > 1");
      } else if (a.rfind("--rho=", 0) == 0) {
        rho = number_option(a, 6);
        if (!(rho >= 0 && rho < 1)) throw InputError("--rho expects a number in [0, 1)");
      } else if (a.rfind("--iterations=", 0) == 0) {
        const double v = number_option(a, 13);
        if (!(v >= 1) || v != std::floor(v) || v > 1000) throw InputError("--iterations expects an integer >= 1");
        iterations_option = static_cast<int>(v);
      } else if (a.rfind("--settle=", 0) == 0) {
        settle = number_option(a, 9);
        if (!(settle >= 0)) throw InputError("--settle expects a number >= 0");
      } else if (a.rfind("--relaxation=", 0) == 0) {
        relaxation = number_option(a, 13);
        if (!(relaxation > 0 && relaxation <= 1)) throw InputError("--relaxation expects a number in (0, 1]");
      } else if (a.rfind("--motion-retries=", 0) == 0) {
        const double v = number_option(a, 17);
        if (!(v >= 0) || v != std::floor(v) || v > 100) throw InputError("--motion-retries expects an integer in [0, 100]");
        motion_retries = static_cast<int>(v);
      } else if (a == "--contact-forces=on" || a == "--contact-forces=off") {
        contact_forces = a == "--contact-forces=on" ? 1 : 0;
      } else if (a.rfind("--substeps=", 0) == 0) {
        const double v = number_option(a, 11);
        if (!(v >= 1) || v != std::floor(v) || v > 1000) throw InputError("--substeps expects an integer >= 1");
        substeps = static_cast<int>(v);
      } else if (a.rfind("--flat-rings=", 0) == 0) {
        const double v = number_option(a, 13);
        if (!(v >= 0 && v <= 2) || v != std::floor(v)) throw InputError("--flat-rings expects 0, 1 or 2");
        flat_rings = static_cast<int>(v);
      } else if (a.rfind("--threads=", 0) == 0) {
        const double v = number_option(a, 10);
        if (!(v >= 0) || v != std::floor(v) || v > 1024) throw InputError("--threads expects an integer >= 0");
        threads = static_cast<int>(v);
      } else {
        throw InputError("unknown argument '" + a + "'");
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sim_bench --check-frames: %s\n", e.what());
    return 2;
  }
  std::optional<Scene> made;
  try {
    made = make_scene(SceneSpec::parse(spec), 1);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sim_bench --check-frames: %s\n", e.what());
    return 2;
  }
  Scene& s = *made;
  Settings settings = s.settings;
  settings.method = MethodSpec::parse("kdop");
  settings.response = settings.response || response;
  settings.fail_safe = fail_safe;
  if (search_factor > 0) settings.search_factor = search_factor;
  settings.motion_search = settings.motion_search || motion_search;
  if (flat_rings >= 0) settings.flat_neighbour_rings = flat_rings;
  if (motion_retries >= 0) settings.motion_retries = motion_retries;
  if (contact_forces >= 0) settings.contact_forces = contact_forces == 1;
  if (relaxation > 0) settings.proximity_relaxation = relaxation;
  if (rho >= 0) settings.integrator_options.projective_rho = rho;
  if (iterations_option > 0) settings.integrator_options.projective_iterations = iterations_option;
  if (settle >= 0) settings.integrator_options.projective_tolerance = settle * settings.detector.thickness;
  if (substeps > 0) {
    settings.dt *= static_cast<double>(settings.substeps) / substeps;
    settings.substeps = substeps;
  }
  if (threads >= 0) settings.detector.threads = settings.integrator_options.threads = threads;
  Simulation sim(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles), std::move(s.kinematics),
                 settings);
  auto tt = intersection_counter(sim, threads);
  ContactSet intersections;
  tt->update(sim.state().x, intersections);
  std::string step(to_string(settings.integrator));
  if (settings.integrator == IntegratorKind::Projective) {
    char buffer[96];
    std::snprintf(buffer, sizeof buffer, " (rho %.2g, %d iterations, settle %.3g m)",
                  settings.integrator_options.projective_rho, settings.integrator_options.projective_iterations,
                  settings.integrator_options.projective_tolerance);
    step += buffer;
  }
  {
    char buffer[224];
    std::snprintf(buffer, sizeof buffer,
                  ", %d steps of %.4g s, search %.3g h_c, motion search %s, motion retries %d, push relaxation %.3g, "
                  "contact forces %s",
                  settings.substeps, settings.dt, settings.search_factor, settings.motion_search ? "on" : "off",
                  settings.motion_retries, settings.proximity_relaxation, settings.contact_forces ? "on" : "off");
    step += buffer;
  }
  std::printf("%s: %d vertices, response %s, fail-safe %s, %s, start: %zu intersecting pairs\n", spec.c_str(),
              sim.model().num_particles(), settings.response ? "on" : "off", fail_safe ? "on" : "off", step.c_str(),
              intersections.tt.size());

  g_stop_signal = 0;
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  ::sigaction(SIGINT, &action, nullptr);
  ::sigaction(SIGTERM, &action, nullptr);

  using Clock = std::chrono::steady_clock;
  const Clock::time_point started = Clock::now();
  Clock::time_point last_report = started;
  const double period = progress_period();
  int bad = 0, run = 0;
  std::size_t most = 0, impacts = 0, frozen = 0, most_impacts = 0, zone_vertices = 0;
  int most_impacts_frame = 0, zone_frames = 0, retried_frames = 0;
  double iterations = 0;
  double flat_pairs = 0;
  double ms = 0, ccd_ms = 0, queries = 0, motion_pairs = 0, integrate_ms = 0, detect_ms = 0, response_ms = 0, contacts = 0;
  double stretch = 0, most_stretch = 0, fastest = 0, most_energy = -std::numeric_limits<double>::infinity();
  double speed = 0, energy = 0;
  int most_stretch_frame = 0;
  std::string stopped;
  const auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - started).count(); };
  const auto progress = [&](const char* what) {
    const double seconds = elapsed();
    std::printf("%s %s: frame %d of %d, %.0f s, %.2f frames/s, %d with intersections (most %zu), live impacts "
                "max %zu (frame %d), %zu zone vertices and %zu frozen in all; now: fastest %.3g m/s, longest "
                "spring %.3gx rest (max %.3gx at frame %d), energy %.4g J\n",
                what, spec.c_str(), run, frames, seconds, run / std::max(seconds, 1e-9), bad, most, most_impacts,
                most_impacts_frame, zone_vertices, frozen, speed, stretch, most_stretch, most_stretch_frame, energy);
  };
  for (int f = 1; f <= frames; ++f) {
    if (g_stop_signal != 0) {
      stopped = g_stop_signal == SIGINT ? "SIGINT" : "SIGTERM";
      break;
    }
    FrameStats st;
    try {
      st = sim.advance_frame();
    } catch (const DivergenceError& e) {
      stopped = std::string("DIVERGED: ") + e.what();
      break;
    }
    ++run;
    ms += st.integrate_ms + st.detect_ms + st.response_ms + st.ccd_ms;
    ccd_ms += st.ccd_ms;
    iterations += st.cg_iterations;
    integrate_ms += st.integrate_ms;
    detect_ms += st.detect_ms;
    response_ms += st.response_ms;
    contacts += static_cast<double>(st.vf + st.ee);
    impacts += st.ccd_impacts;
    frozen += st.ccd_frozen;
    zone_vertices += st.ccd_zone_vertices;
    zone_frames += st.ccd_zone_vertices > 0 ? 1 : 0;
    queries += st.ccd_queries;
    motion_pairs += static_cast<double>(st.motion_pairs);
    flat_pairs += static_cast<double>(st.flat_pairs);
    retried_frames += st.retries > 0 ? 1 : 0;
    if (st.ccd_impacts > most_impacts) {
      most_impacts = st.ccd_impacts;
      most_impacts_frame = f;
    }
    speed = st.max_speed;
    energy = st.energy;
    fastest = std::max(fastest, speed);
    most_energy = std::max(most_energy, energy);
    stretch = st.longest_spring;
    if (stretch > most_stretch) {
      most_stretch = stretch;
      most_stretch_frame = f;
    }
    tt->update(sim.state().x, intersections);
    const std::size_t pairs = intersections.tt.size();
    if (verbose) {
      std::printf("frame %d: %.1f ms, CCD %.1f ms, %zu live impacts, %d queries, %zu zone vertices, %zu frozen, "
                  "%zu contacts, %zu flat-neighbour pairs left out, fastest %.3g m/s, longest spring %.3gx rest, "
                  "energy %.4g J, %zu intersecting pairs, state %016llx\n",
                  f, st.integrate_ms + st.detect_ms + st.response_ms + st.ccd_ms, st.ccd_ms, st.ccd_impacts,
                  st.ccd_queries, st.ccd_zone_vertices, st.ccd_frozen, st.vf + st.ee, st.flat_pairs, speed, stretch,
                  energy, pairs, static_cast<unsigned long long>(state_digest(sim.state())));
    }
    if (pairs > 0) {
      ++bad;
      most = std::max(most, pairs);
      std::printf("frame %d: %zu intersecting pairs\n", f, pairs);
    }
    if (std::chrono::duration<double>(Clock::now() - last_report).count() >= period) {
      progress("progress");
      last_report = Clock::now();
    }
  }
  const double per = std::max(run, 1);
  std::printf(
      "summary %s: %d frames run of %d, %d with intersections (most %zu); %.1f ms/frame (integrate %.1f, "
      "detect %.1f, response %.1f, CCD %.1f), %.2f frames/s of wall time; %.0f contacts/frame, %.1f live "
      "impacts/frame (max %zu at frame %d), %.2f queries/frame, %.1f motion-search contacts/frame, %.0f flat-neighbour pairs left out/frame, %d frames run again, %d frames with impact zones (%zu zone vertices "
      "in all), %zu frozen in all; fastest %.3g m/s, longest spring %.3gx rest (frame %d), energy at most %.4g "
      "J; %.1f solver iterations/frame%s%s\n",
      spec.c_str(), run, frames, bad, most, ms / per, integrate_ms / per, detect_ms / per, response_ms / per,
      ccd_ms / per, run / std::max(elapsed(), 1e-9), contacts / per, static_cast<double>(impacts) / per,
      most_impacts, most_impacts_frame, queries / per, motion_pairs / per, flat_pairs / per, retried_frames, zone_frames, zone_vertices, frozen, fastest, most_stretch,
      most_stretch_frame, run > 0 ? most_energy : 0.0, iterations / per, stopped.empty() ? "" : "; STOPPED: ",
      stopped.c_str());
  if (bad > 0 || stopped.rfind("DIVERGED", 0) == 0) return 1;
  return stopped.empty() ? 0 : 3;
}

int main(int argc, char** argv) {
  if (argc > 1 && std::string(argv[1]).rfind("--check-frames=", 0) == 0) return check_frames(argc, argv);
  register_all();
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

// `crumple simulate`: runs a built-in scene or a model from a file, writes frames, per-frame
// statistics and the final state (X3D MassSpring + a JSON side file) so a run can be resumed.
#include "commands.hpp"
#include "sim_glue.hpp"

#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/sim/scene.hpp>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace crumple::cli {

namespace {

volatile std::sig_atomic_t g_interrupted = 0;
extern "C" void on_sigint(int) { g_interrupted = 1; }

struct SimulateArgs {
  std::string input = "hanging-cloth";
  std::vector<std::string> params;
  long long frames = 600;
  std::optional<double> dt;
  std::optional<int> substeps;
  std::optional<std::string> integrator;
  std::optional<std::string> method;
  std::optional<double> thickness;
  std::optional<std::string> kinds;
  std::optional<std::string> response;
  std::optional<int> passes;
  std::optional<std::uint64_t> seed;
  int threads = 0;
  std::string out = "crumple-out";
  std::string format = "obj";
  long long every = 1;
  bool quiet = false;
};

std::string scenes_help() {
  std::string out = "Built-in scene SPEC, NAME[:key=value,...], or a file (.x3d .obj .ply .off). Scenes:";
  for (const sim::SceneInfo& s : sim::all_scenes()) {
    out += "\n  " + std::string(s.name) + " — " + std::string(s.summary);
    for (const sim::SceneParamInfo& p : s.params) {
      out += "\n      " + std::string(p.key) + "=" + std::string(p.default_value) + "  " + std::string(p.description);
    }
  }
  return out;
}

bool has_extension(const std::string& input) {
  const std::string ext = std::filesystem::path(input).extension().string();
  return !ext.empty() && input.find(':') == std::string::npos;
}

/// What a run starts from.
struct Start {
  sim::Scene scene;
  std::uint64_t seed = 1;
  std::int64_t frame = 0;
  std::string source;  // for messages
};

Start load(const SimulateArgs& args, std::optional<SideFile>& side) {
  Start start;
  start.seed = args.seed.value_or(1);
  if (!has_extension(args.input)) {
    const sim::SceneSpec spec = apply_params(sim::SceneSpec::parse(args.input), args.params);
    start.scene = sim::make_scene(spec, start.seed);
    start.source = "scene " + start.scene.spec;
    return start;
  }
  const std::filesystem::path path(args.input);
  if (!std::filesystem::exists(path)) throw InputError("no such file or scene: '" + args.input + "'");
  const bool x3d = io::format_from_path(path) == io::MeshFormat::X3d;
  if (x3d && file_mentions(path, "MassSpring")) {
    const io::MassSpringData data = io::read_mass_spring(path);
    std::filesystem::path side_path = path;
    side_path.replace_extension(".json");
    Scalar time = 0;
    if (std::filesystem::exists(side_path)) {
      side = read_side_file(side_path);
      if (side->values["format"] != "crumple-sim-state") side.reset();
    }
    sim::Model model = model_from_mass_spring(data);
    if (side) {
      time = side->number("time", side_path);
      start.frame = static_cast<std::int64_t>(side->number("frame", side_path));
      if (!args.seed) start.seed = static_cast<std::uint64_t>(side->number("seed", side_path));
      sim::SceneSpec spec = apply_params(sim::SceneSpec::parse(side->text("scene", side_path)), args.params);
      if (spec.name() == "file") {
        start.scene = sim::make_scene_from_model(std::move(model), state_from_mass_spring(data, time), spec);
      } else {
        start.scene = sim::make_scene(spec, start.seed);
        start.scene.model = std::move(model);
        start.scene.state = state_from_mass_spring(data, time);
      }
      start.source = "state " + path.string() + " (" + start.scene.spec + ", frame " + std::to_string(start.frame) + ")";
    } else {
      const sim::SceneSpec spec = apply_params(sim::SceneSpec::parse("file"), args.params);
      start.scene = sim::make_scene_from_model(std::move(model), state_from_mass_spring(data, 0), spec);
      start.source = "mass-spring " + path.string();
    }
    if (data.faces.empty()) {
      std::cerr << "crumple: warning: " << path.string() << " has no Face node: no triangles, no self-collisions\n";
    }
    return start;
  }
  const TriMesh mesh = io::read_mesh(path);
  const sim::SceneSpec spec = apply_params(sim::SceneSpec::parse("file"), args.params);
  start.scene = sim::make_scene_from_mesh(mesh, spec);
  start.source = "mesh " + path.string();
  return start;
}

bool parse_on_off(const std::string& value) {
  if (value == "on") return true;
  if (value == "off") return false;
  throw InputError("--response expects on or off, got '" + value + "'");
}

std::string frame_name(std::int64_t frame, const std::string& ext) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%06lld.", static_cast<long long>(frame));
  return buf + ext;
}

std::string csv_number(double v) {
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

struct Summary {
  long long frames = 0;
  double integrate_ms = 0, detect_ms = 0, response_ms = 0;
  double share_min = 1, share_max = 0;
  bool hit0 = false, hit30 = false, hit50 = false, hit80 = false;
  long long close_frames = 0;  // frames with a VF/EE pair closer than half the thickness
  double max_penetration = 0;
  void add(const sim::FrameStats& s, Scalar thickness) {
    ++frames;
    integrate_ms += s.integrate_ms;
    detect_ms += s.detect_ms;
    response_ms += s.response_ms;
    share_min = std::min<double>(share_min, s.collision_share);
    share_max = std::max<double>(share_max, s.collision_share);
    hit0 |= s.collision_share == 0;
    hit30 |= s.collision_share >= 0.25 && s.collision_share <= 0.35;
    hit50 |= s.collision_share >= 0.45 && s.collision_share <= 0.55;
    hit80 |= s.collision_share >= 0.8;
    if (s.min_distance < 0.5 * thickness) ++close_frames;
    max_penetration = std::max<double>(max_penetration, s.obstacle_penetration);
  }
};

int run_simulate(const SimulateArgs& args) {
  if (args.frames < 0) throw InputError("--frames must be >= 0");
  if (args.every < 1) throw InputError("--every must be >= 1");
  if (args.format != "obj" && args.format != "ply" && args.format != "x3d" && args.format != "off") {
    throw InputError("--format expects obj, ply, off or x3d, got '" + args.format + "'");
  }
  std::optional<SideFile> side;
  Start start = load(args, side);
  sim::Scene& scene = start.scene;
  sim::Settings settings = scene.settings;
  const std::filesystem::path side_path = [&] {
    std::filesystem::path p(args.input);
    return p.replace_extension(".json");
  }();
  // Saved settings first, then explicit options.
  if (side) {
    settings.dt = side->number("dt", side_path);
    settings.substeps = static_cast<int>(side->number("substeps", side_path));
    settings.integrator = sim::parse_integrator(side->text("integrator", side_path));
    settings.method = MethodSpec::parse(side->text("method", side_path));
    settings.detector.thickness = side->number("thickness", side_path);
    settings.detector.kinds = ContactKinds::parse(side->text("kinds", side_path));
    settings.response = side->text("response", side_path) == "true";
    settings.passes = static_cast<int>(side->number("passes", side_path));
  }
  if (args.dt) settings.dt = *args.dt;
  if (args.substeps) settings.substeps = *args.substeps;
  if (args.integrator) settings.integrator = sim::parse_integrator(*args.integrator);
  if (args.method) settings.method = MethodSpec::parse(*args.method);
  if (args.thickness) settings.detector.thickness = *args.thickness;
  if (args.kinds) settings.detector.kinds = ContactKinds::parse(*args.kinds);
  if (args.response) settings.response = parse_on_off(*args.response);
  if (args.passes) settings.passes = *args.passes;
  settings.detector.threads = args.threads;
  if (!(settings.dt > 0)) throw InputError("--dt must be > 0");
  if (settings.substeps < 1) throw InputError("--substeps must be >= 1");
  if (settings.passes < 1) throw InputError("--passes must be >= 1");
  if (!(settings.detector.thickness >= 0)) throw InputError("--thickness must be >= 0");

  const std::filesystem::path out(args.out);
  const std::filesystem::path frames_dir = out / "frames";
  std::filesystem::create_directories(frames_dir);

  const std::string spec_text = scene.spec;
  const auto faces = std::vector<Face>(scene.model.topology().faces().begin(), scene.model.topology().faces().end());
  sim::Simulation simulation(std::move(scene.model), std::move(scene.state), scene.field,
                             std::move(scene.obstacles), std::move(scene.kinematics), settings, start.frame);
  // The stochastic detector's kept pairs and generator, when the method is unchanged.
  if (side && side->values.count("detector_state")) {
    if (settings.method.to_string() == side->text("method", side_path)) {
      simulation.restore_detector_state(side->text("detector_state", side_path));
    } else if (!side->text("detector_state", side_path).empty()) {
      std::cerr << "crumple: warning: the method changed from " << side->text("method", side_path)
                << ": its saved state across frames is not restored\n";
    }
  }

  if (!args.quiet) {
    std::printf("crumple simulate: %s\n  %d particles, %zu springs, %zu faces, %d edges; dt %.6g s x %d substeps "
                "per frame, %s, detector %s, thickness %.6g m, response %s\n",
                start.source.c_str(), simulation.model().num_particles(), simulation.model().springs().size(),
                faces.size(), simulation.model().topology().num_edges(), settings.dt, settings.substeps,
                std::string(sim::to_string(settings.integrator)).c_str(), settings.method.to_string().c_str(),
                settings.detector.thickness, settings.response ? "on" : "off");
    std::fflush(stdout);
  }

  // Statistics: one complete line at a time, flushed, so an interrupted run leaves whole lines.
  const std::filesystem::path csv_path = out / "stats.csv";
  std::FILE* csv = std::fopen(csv_path.string().c_str(), "w");
  if (!csv) throw ParseError(csv_path.string(), {}, "cannot open for writing");
  std::fputs("frame,time,integrate_ms,detect_ms,response_ms,vf,ee,tt,collision_share,min_distance,"
             "obstacle_penetration,cg_iterations,corrections\n",
             csv);
  std::fflush(csv);

  Summary summary;
  const auto record = [&](const sim::FrameStats& s) {
    const std::string line =
        std::to_string(s.frame) + "," + csv_number(s.time) + "," + csv_number(s.integrate_ms) + "," +
        csv_number(s.detect_ms) + "," + csv_number(s.response_ms) + "," + std::to_string(s.vf) + "," +
        std::to_string(s.ee) + "," + std::to_string(s.tt) + "," + csv_number(s.collision_share) + "," +
        csv_number(s.min_distance) + "," + csv_number(s.obstacle_penetration) + "," +
        std::to_string(s.cg_iterations) + "," + std::to_string(s.corrections) + "\n";
    std::fputs(line.c_str(), csv);
    std::fflush(csv);
    if ((s.frame - start.frame) % args.every == 0) {
      io::write_mesh(frames_dir / frame_name(s.frame, args.format), simulation.state().x, faces);
    }
    summary.add(s, settings.detector.thickness);
  };

  g_interrupted = 0;
  struct sigaction action {};
  action.sa_handler = on_sigint;
  sigemptyset(&action.sa_mask);
  struct sigaction previous {};
  ::sigaction(SIGINT, &action, &previous);

  const bool progress = !args.quiet && ::isatty(STDERR_FILENO);
  int status = 0;
  try {
    record(simulation.current_stats());
    for (long long k = 0; k < args.frames; ++k) {
      if (g_interrupted) break;
      record(simulation.advance_frame());
      if (progress) {
        const int width = 30;
        const int done = static_cast<int>((k + 1) * width / std::max<long long>(args.frames, 1));
        std::fprintf(stderr, "\r[%s%s] frame %lld/%lld", std::string(static_cast<std::size_t>(done), '#').c_str(),
                     std::string(static_cast<std::size_t>(width - done), '.').c_str(), k + 1, args.frames);
      }
    }
  } catch (...) {
    ::sigaction(SIGINT, &previous, nullptr);
    std::fclose(csv);
    throw;
  }
  if (progress) std::fprintf(stderr, "\r\033[K");
  std::fclose(csv);

  // Final state: X3D MassSpring + JSON side file (settings needed to resume bit for bit).
  io::write_mass_spring(out / "state.x3d", to_mass_spring(simulation.model(), simulation.state()));
  const std::string side_json = JsonObject()
                                    .add("format", "crumple-sim-state")
                                    .add("version", 1)
                                    .add("scene", spec_text)
                                    .add("seed", static_cast<long long>(start.seed))
                                    .add("frame", static_cast<long long>(simulation.frame()))
                                    .add("time", simulation.state().time)
                                    .add("dt", settings.dt)
                                    .add("substeps", settings.substeps)
                                    .add("integrator", sim::to_string(settings.integrator))
                                    .add("method", settings.method.to_string())
                                    .add("thickness", settings.detector.thickness)
                                    .add("kinds", settings.detector.kinds.to_string())
                                    .add("response", settings.response)
                                    .add("passes", settings.passes)
                                    .add("detector_state", simulation.detector_state())
                                    .str();
  write_file_atomically(out / "state.json", [&](std::ostream& os) { os << side_json << "\n"; });
  ::sigaction(SIGINT, &previous, nullptr);

  if (g_interrupted) {
    std::fprintf(stderr, "crumple: interrupted after frame %lld; files are complete\n",
                 static_cast<long long>(simulation.frame()));
    status = 130;
  }
  if (!args.quiet) {
    const double n = static_cast<double>(std::max<long long>(summary.frames - 1, 1));
    const auto yes = [](bool b) { return b ? "yes" : "no"; };
    std::printf("\n  %-28s %lld (%lld written to %s)\n", "frames simulated", summary.frames - 1, summary.frames,
                frames_dir.string().c_str());
    std::printf("  %-28s %.4g s\n", "simulated time", simulation.state().time);
    std::printf("  %-28s %.3f / %.3f / %.3f\n", "ms per frame: integrate/detect/response", summary.integrate_ms / n,
                summary.detect_ms / n, summary.response_ms / n);
    std::printf("  %-28s %.1f%% .. %.1f%%\n", "collision share min..max", 100 * summary.share_min,
                100 * summary.share_max);
    std::printf("  %-28s 0%%: %s  ~30%%: %s  ~50%%: %s  >=80%%: %s\n", "share reached", yes(summary.hit0),
                yes(summary.hit30), yes(summary.hit50), yes(summary.hit80));
    std::printf("  %-28s %lld of %lld\n", "frames with a pair < h/2", summary.close_frames, summary.frames);
    std::printf("  %-28s %.3g m\n", "max obstacle penetration", summary.max_penetration);
    std::printf("  %-28s %s, %s\n", "wrote", csv_path.string().c_str(), (out / "state.x3d").string().c_str());
  }
  return status;
}

}  // namespace

Run add_simulate_command(CLI::App& app) {
  auto args = std::make_shared<SimulateArgs>();
  app.description(
      "Simulate a mass-spring cloth with self-collision detection (and response), writing one mesh\n"
      "per frame to DIR/frames/NNNNNN.EXT (the initial state first), per-frame statistics to\n"
      "DIR/stats.csv and the final state to DIR/state.x3d (MassSpring node) + DIR/state.json;\n"
      "`crumple simulate DIR/state.x3d` resumes the run bit for bit. Ctrl-C finishes the current\n"
      "frame and leaves every file complete.");
  app.add_option("SCENE", args->input, scenes_help())->capture_default_str();
  app.add_option("-p,--param", args->params,
                 "Scene key=value (repeatable), e.g. -p nx=20; for files: pins, stiffness, ...");
  app.add_option("-n,--frames", args->frames, "Frames to simulate")->capture_default_str();
  app.add_option("--dt", args->dt, "Time step (s); default: the scene's");
  app.add_option("--substeps", args->substeps, "Steps per frame; default: the scene's");
  app.add_option("-i,--integrator", args->integrator,
                 "explicit-euler, symplectic-euler, rk4 or implicit-euler; default: the scene's");
  app.add_option("-m,--method", args->method, "Detection method SPEC (see `crumple detect --help`); default naive");
  app.add_option("-t,--thickness", args->thickness, "Contact thickness (m); default: the scene's");
  app.add_option("-k,--kinds", args->kinds, "Contact kinds: comma-separated vf, ee, tt; default vf,ee");
  app.add_option("--response", args->response, "Self-collision response on|off; default: the scene's");
  app.add_option("--passes", args->passes, "Response sweeps per step; default 4");
  app.add_option("-s,--seed", args->seed, "Seed of the scene's random perturbation; default 1");
  app.add_option("-j,--threads", args->threads, "Detector threads (0 = all cores)")->capture_default_str();
  app.add_option("-o,--out", args->out, "Output folder")->capture_default_str();
  app.add_option("-f,--format", args->format, "Frame format: obj, ply, off or x3d")->capture_default_str();
  app.add_option("--every", args->every, "Write every K-th frame only (stats keep every frame)")
      ->capture_default_str();
  app.add_flag("-q,--quiet", args->quiet, "No header, progress bar or summary");
  return [args]() { return run_simulate(*args); };
}

}  // namespace crumple::cli

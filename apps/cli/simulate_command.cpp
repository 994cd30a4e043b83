// `crumple simulate`: runs a built-in scene or a model from a file, writes frames, per-frame
// statistics and the final state (X3D MassSpring + a JSON side file) so a run can be resumed.
#include "commands.hpp"
#include "options.hpp"
#include "outputs.hpp"
#include "progress.hpp"
#include "sim_glue.hpp"

#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/sim/scene.hpp>
#include <crumple/sim/time_step.hpp>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cerrno>
#include <csignal>
#include <cstring>
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

/// The signal (SIGINT or SIGTERM) that asked the run to stop after the current frame, or 0.
volatile std::sig_atomic_t g_interrupted = 0;
extern "C" void on_stop_signal(int signal) { g_interrupted = signal; }

struct SimulateArgs {
  std::string input = "hanging-cloth";
  std::vector<std::string> params;
  long long frames = 600;
  std::optional<double> dt;
  std::optional<int> substeps;
  std::optional<std::string> integrator;
  DetectionArgs detection;
  std::optional<std::string> response;
  std::optional<int> passes;
  std::optional<std::string> fail_safe;
  std::optional<std::string> untangle;
  std::optional<std::string> untangle_pull;
  std::optional<std::string> motion_search;
  std::optional<int> motion_retries;
  std::optional<double> push_relaxation;
  std::optional<long long> response_from;
  std::optional<std::uint64_t> seed;
  std::optional<std::string> out;  ///< default: the resumed state's folder, else kDefaultOut
  std::string format = "obj";
  long long every = 1;
  bool force = false;
  bool quiet = false;
};

constexpr const char* kDefaultOut = "crumple-out";

/// Columns of stats.csv.
constexpr const char* kStatsHeader =
    "frame,time,integrate_ms,detect_ms,response_ms,vf,ee,tt,collision_share,min_distance,"
    "obstacle_penetration,cg_iterations,corrections,energy,max_speed,min_x,min_y,min_z,max_x,"
    "max_y,max_z,ccd_ms,ccd_impacts,ccd_frozen,intersecting_pairs,contours,untangle_pulls,pinches,"
    "ccd_zone_vertices,longest_spring";

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
        // MassSpring has no bending hinges: the scene's own are rebuilt from its spec.
        const auto hinges = start.scene.model.hinges();
        start.scene.model = model.with_hinges({hinges.begin(), hinges.end()});
        start.scene.state = state_from_mass_spring(data, time);
      }
      start.source = "state " + path.string() + " (" + start.scene.spec + ", frame " + std::to_string(start.frame) + ")";
    } else {
      // A run's state without its side file would silently start over as a plain mesh file
      // (another integrator, time 0): say so.
      if (path.stem() == "state") {
        std::cerr << "crumple: warning: no crumple state file " << side_path.string() << " beside "
                  << path.string() << ": simulating it as a MassSpring file from time 0 with the file "
                  << "defaults, not resuming its run\n";
      }
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

bool parse_on_off(const std::string& value, const char* flag) {
  if (value == "on") return true;
  if (value == "off") return false;
  throw InputError(std::string(flag) + " expects on or off, got '" + value + "'");
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
  long long written = 0;  // frame files written by this run (`--every`)
  double integrate_ms = 0, detect_ms = 0, response_ms = 0, ccd_ms = 0;
  double share_min = 1, share_max = 0;
  bool hit0 = false, hit30 = false, hit50 = false, hit80 = false;
  long long close_frames = 0;  // frames with a VF/EE pair closer than half the thickness
  double wall_ms = 0;          // the frame loop's wall time, writing frames included
  double max_penetration = 0;
  long long first_pairs = -1, last_pairs = -1;  // intersecting pairs, -1: not measured
  long long clean_frame = -1;                   // first frame whose pairs fell to 0 after > 0
  void add(const sim::FrameStats& s, Scalar thickness) {
    ++frames;
    integrate_ms += s.integrate_ms;
    detect_ms += s.detect_ms;
    response_ms += s.response_ms;
    ccd_ms += s.ccd_ms;
    share_min = std::min<double>(share_min, s.collision_share);
    share_max = std::max<double>(share_max, s.collision_share);
    hit0 |= s.collision_share == 0;
    hit30 |= s.collision_share >= 0.25 && s.collision_share <= 0.35;
    hit50 |= s.collision_share >= 0.45 && s.collision_share <= 0.55;
    hit80 |= s.collision_share >= 0.8;
    if (s.min_distance < 0.5 * thickness) ++close_frames;
    max_penetration = std::max<double>(max_penetration, s.obstacle_penetration);
    if (s.intersecting_pairs >= 0) {  // pinch pairs count too: 0 is intersection-free
      const std::int64_t pairs = s.intersecting_pairs + std::max<std::int64_t>(s.pinches, 0);
      if (first_pairs < 0) first_pairs = pairs;
      if (pairs == 0 && last_pairs > 0 && clean_frame < 0) clean_frame = s.frame;
      last_pairs = pairs;
    }
  }
};

/// The files of a run in `out`: stats.csv, state.x3d, state.json and frames/.
bool holds_a_run(const std::filesystem::path& out) {
  std::error_code ec;
  for (const char* name : {"stats.csv", "state.x3d", "state.json", "frames"}) {
    if (std::filesystem::exists(out / name, ec)) return true;
  }
  return false;
}

/// Removes the files of another run from `out` (--force): frames/NNNNNN.*, stats.csv, state.*.
void remove_run(const std::filesystem::path& out) {
  for (const char* name : {"stats.csv", "state.x3d", "state.json"}) std::filesystem::remove(out / name);
  const std::filesystem::path frames = out / "frames";
  if (!std::filesystem::is_directory(frames)) return;
  for (const auto& entry : std::filesystem::directory_iterator(frames)) {
    const std::string stem = entry.path().stem().string();
    if (entry.is_regular_file() && stem.size() == 6 &&
        std::all_of(stem.begin(), stem.end(), [](char c) { return c >= '0' && c <= '9'; })) {
      std::filesystem::remove(entry.path());
    }
  }
}

/// The last line of a text file ("" when none).
std::string last_line(const std::filesystem::path& path, std::string* first = nullptr) {
  std::ifstream in(path);
  std::string line, last;
  bool at_first = true;
  while (std::getline(in, line)) {
    if (at_first && first) *first = line;
    at_first = false;
    if (!line.empty()) last = line;
  }
  return last;
}

/// The final state: X3D MassSpring + JSON side file (the settings needed to resume bit for bit).
void save_state(const std::filesystem::path& out, const sim::Simulation& simulation,
                const sim::Settings& settings, const std::string& spec_text, std::uint64_t seed) {
  io::write_mass_spring(out / "state.x3d", to_mass_spring(simulation.model(), simulation.state()));
  const std::string side_json = JsonObject()
                                    .add("format", "crumple-sim-state")
                                    .add("version", 1)
                                    .add("scene", spec_text)
                                    .add("seed", static_cast<long long>(seed))
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
                                    .add("fail_safe", settings.fail_safe)
                                    .add("untangle", settings.untangle)
                                    .add("untangle_pull", settings.untangle_in_solve ? "solve" : "after")
                                    .add("motion_search", settings.motion_search)
                                    .add("motion_retries", settings.motion_retries)
                                    .add("push_relaxation", settings.proximity_relaxation)
                                    .add("detector_state", simulation.detector_state())
                                    .str();
  write_file_atomically(out / "state.json", [&](std::ostream& os) { os << side_json << "\n"; });
}

/// The summary table on stdout.
void print_summary(const Summary& summary, const sim::Simulation& simulation,
                   const std::filesystem::path& frames_dir, const std::filesystem::path& csv_path,
                   bool append, const std::filesystem::path& out) {
  const double n = static_cast<double>(std::max<long long>(summary.frames - 1, 1));
  const auto yes = [](bool b) { return b ? "yes" : "no"; };
  std::printf("\n  %-28s %lld (%lld written to %s)\n", "frames simulated", summary.frames - 1, summary.written,
              frames_dir.string().c_str());
  std::printf("  %-28s %.4g s\n", "simulated time", simulation.state().time);
  std::printf("  %-28s %.3f / %.3f / %.3f / %.3f\n", "ms per frame: integrate/detect/response/ccd",
              summary.integrate_ms / n, summary.detect_ms / n, summary.response_ms / n, summary.ccd_ms / n);
  const double compute_ms = summary.integrate_ms + summary.detect_ms + summary.response_ms + summary.ccd_ms;
  if (summary.frames > 1 && compute_ms > 0 && summary.wall_ms > 0) {
    std::printf("  %-28s %.1f (simulation only: %.1f)\n", "frames per second", 1000 * n / summary.wall_ms,
                1000 * n / compute_ms);
  }
  std::printf("  %-28s %.1f%% .. %.1f%%\n", "collision share min..max", 100 * summary.share_min,
              100 * summary.share_max);
  std::printf("  %-28s 0%%: %s  ~30%%: %s  ~50%%: %s  >=80%%: %s\n", "share reached", yes(summary.hit0),
              yes(summary.hit30), yes(summary.hit50), yes(summary.hit80));
  std::printf("  %-28s %lld of %lld\n", "frames with a pair < h/2", summary.close_frames, summary.frames);
  std::printf("  %-28s %.3g m\n", "max obstacle penetration", summary.max_penetration);
  if (summary.first_pairs >= 0) {
    std::printf("  %-28s %lld first measured, %lld at the end", "intersecting pairs", summary.first_pairs,
                summary.last_pairs);
    if (summary.clean_frame >= 0) std::printf(" (0 from frame %lld)", summary.clean_frame);
    std::printf("\n");
  }
  std::printf("  %-28s %s%s, %s\n", "wrote", csv_path.string().c_str(), append ? " (appended)" : "",
              (out / "state.x3d").string().c_str());
}

/// Where a run writes: the folder, and whether stats.csv is continued.
struct RunOutput {
  std::filesystem::path out;
  bool append = false;
};

/// The output folder, checked and created before any work. Resuming DIR/state.x3d continues the
/// run in DIR (stats.csv appended, when it ends at the state's frame); any other folder holding
/// a run is refused, or cleared of that run's files with --force.
RunOutput prepare_run_output(const SimulateArgs& args, bool resumed, std::int64_t start_frame) {
  const std::filesystem::path input(args.input);
  const std::filesystem::path state_dir = input.parent_path().empty() ? "." : input.parent_path();
  RunOutput result;
  result.out = args.out ? std::filesystem::path(*args.out)
               : resumed ? state_dir
                         : std::filesystem::path(kDefaultOut);
  const std::filesystem::path& out = result.out;
  std::error_code ec;
  const bool continuing = resumed && input.stem() == "state" && std::filesystem::exists(out) &&
                          std::filesystem::equivalent(out, state_dir, ec);
  const std::filesystem::path csv_path = out / "stats.csv";
  if (continuing) {
    if (std::filesystem::exists(csv_path)) {
      std::string header;
      const std::string last = last_line(csv_path, &header);
      if (header != kStatsHeader) {
        throw InputError(csv_path.string() + " has other columns than this version writes: resume "
                         "into another folder with --out");
      }
      if (last.rfind(std::to_string(start_frame) + ",", 0) != 0) {
        throw InputError(csv_path.string() + " does not end at the saved state's frame " +
                         std::to_string(start_frame) +
                         ": resume into another folder with --out, so that no line is lost");
      }
      result.append = true;
    }
  } else if (std::filesystem::is_directory(out) && holds_a_run(out)) {
    if (!args.force) {
      throw InputError("--out '" + out.string() +
                       "' holds another run (stats.csv, state or frames): give a new or empty "
                       "folder, or --force to replace that run's files");
    }
    remove_run(out);
  }
  prepare_output_folder(out, "--out");
  prepare_output_folder(out / "frames", "--out");
  return result;
}

/// A time step beyond the integrator's stable range, fitted by `sim::fit_time_step` (the scene's
/// own step split into stable substeps, a step the user chose kept), and the choice said.
/// Returns the stable step estimate.
Scalar choose_time_step(sim::Settings& settings, const sim::Scene& scene, bool user_step) {
  const sim::TimeStepFit fit = sim::fit_time_step(settings, scene.model, scene.field, scene.state.x, user_step);
  const std::string name(sim::to_string(settings.integrator));
  if (fit.action == sim::StepFit::Split) {
    std::fprintf(stderr,
                 "crumple simulate: the scene's time step %.3g s is beyond %s's stable range "
                 "(about %.3g s for the model's fastest modes): using %d substeps of %.3g s per frame "
                 "instead of %d (same frame length); --dt and --substeps override\n",
                 fit.given_dt, name.c_str(), fit.stable_dt, fit.substeps, fit.dt, fit.given_substeps);
  } else if (fit.action == sim::StepFit::Kept && !(fit.stable_dt > 0)) {
    std::fprintf(stderr,
                 "crumple: warning: %s is beyond its stable range at every time step on this model "
                 "(a spring or hinge without damping gains energy at any step): the run will likely "
                 "diverge. Use -i symplectic-euler, -i rk4 or -i implicit-euler\n",
                 name.c_str());
  } else if (fit.action == sim::StepFit::Kept) {
    std::fprintf(stderr,
                 "crumple: warning: the time step %.3g s is beyond %s's stable range (about "
                 "%.3g s for the model's fastest modes): the run will likely diverge. Use --dt %.3g "
                 "--substeps %d (same frame length) or -i implicit-euler\n",
                 fit.given_dt, name.c_str(), fit.stable_dt, fit.dt, fit.substeps);
  }
  return fit.stable_dt;
}

int run_simulate(const SimulateArgs& args) {
  if (args.frames < 0) throw InputError("--frames must be >= 0");
  if (args.every < 1) throw InputError("--every must be >= 1");
  if (args.format != "obj" && args.format != "ply" && args.format != "x3d" && args.format != "off") {
    throw InputError("--format expects obj, ply, off or x3d, got '" + args.format + "'");
  }
  check_detection_args(args.detection);
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
    // Absent from states saved before the fail-safe existed: the default (on).
    if (side->values.count("fail_safe")) settings.fail_safe = side->text("fail_safe", side_path) == "true";
    if (side->values.count("untangle")) settings.untangle = side->text("untangle", side_path) == "true";
    if (side->values.count("untangle_pull")) {
      const std::string pull = side->text("untangle_pull", side_path);
      if (pull != "solve" && pull != "after") {
        throw ParseError(side_path.string(), {}, "key 'untangle_pull' expects solve or after, got '" + pull + "'");
      }
      settings.untangle_in_solve = pull == "solve";
    }
    if (side->values.count("motion_search")) {
      settings.motion_search = side->text("motion_search", side_path) == "true";
    }
    if (side->values.count("motion_retries")) {
      settings.motion_retries = static_cast<int>(side->number("motion_retries", side_path));
    }
    if (side->values.count("push_relaxation")) {
      settings.proximity_relaxation = side->number("push_relaxation", side_path);
      if (!(settings.proximity_relaxation > 0 && settings.proximity_relaxation <= 1)) {
        throw ParseError(side_path.string(), {}, "key 'push_relaxation' expects a number in (0, 1], got '" +
                                                     side->text("push_relaxation", side_path) + "'");
      }
    }
  }
  if (args.dt) settings.dt = *args.dt;
  if (args.substeps) settings.substeps = *args.substeps;
  if (args.integrator) settings.integrator = sim::parse_integrator(*args.integrator);
  settings.method = method_of(args.detection, settings.method);
  settings.detector.thickness = thickness_of(args.detection, scene.state.x, settings.detector.thickness);
  if (args.detection.kinds) settings.detector.kinds = ContactKinds::parse(*args.detection.kinds);
  if (args.response) settings.response = parse_on_off(*args.response, "--response");
  if (args.passes) settings.passes = *args.passes;
  if (args.fail_safe) settings.fail_safe = parse_on_off(*args.fail_safe, "--fail-safe");
  if (args.untangle) settings.untangle = parse_on_off(*args.untangle, "--untangle");
  if (args.untangle_pull) {
    if (*args.untangle_pull != "solve" && *args.untangle_pull != "after") {
      throw InputError("--untangle-pull expects solve or after, got '" + *args.untangle_pull + "'");
    }
    settings.untangle_in_solve = *args.untangle_pull == "solve";
  }
  if (args.motion_search) settings.motion_search = parse_on_off(*args.motion_search, "--motion-search");
  if (args.motion_retries) settings.motion_retries = *args.motion_retries;
  if (args.push_relaxation) {
    if (!(*args.push_relaxation > 0 && *args.push_relaxation <= 1)) {
      char text[32];
      const auto end = std::to_chars(text, text + sizeof text, *args.push_relaxation).ptr;
      throw InputError("--push-relaxation expects a number in (0, 1], got " + std::string(text, end));
    }
    settings.proximity_relaxation = *args.push_relaxation;
  }
  if (args.response_from) {
    if (*args.response_from < start.frame) {
      throw InputError("--response-from " + std::to_string(*args.response_from) + " is before the first frame (" +
                       std::to_string(start.frame) + ")");
    }
    if (args.response && !settings.response) throw InputError("--response-from needs the response on, not --response off");
    settings.response = true;
  }
  settings.detector.threads = args.detection.threads;
  settings.integrator_options.threads = args.detection.threads;  // projective solves: same bits on any count
  if (!(settings.dt > 0 && std::isfinite(settings.dt))) throw InputError("--dt must be > 0");
  if (settings.substeps < 1) throw InputError("--substeps must be >= 1");
  if (settings.passes < 1) throw InputError("--passes must be >= 1");

  const auto [out, append] = prepare_run_output(args, side.has_value(), start.frame);
  const std::filesystem::path csv_path = out / "stats.csv";
  const std::filesystem::path frames_dir = out / "frames";
  const Scalar stable_dt = choose_time_step(settings, scene, args.dt || args.substeps || side);
  const std::string integrator_name(sim::to_string(settings.integrator));

  const std::string spec_text = scene.spec;
  const auto faces = std::vector<Face>(scene.model.topology().faces().begin(), scene.model.topology().faces().end());
  check_contact_budget(scene.model.topology(), scene.state.x, settings.detector,
                       args.detection.max_contacts);
  // --response-from: the run starts with the response off and switches to `settings` there.
  const bool delayed = args.response_from && *args.response_from > start.frame;
  sim::Settings early = settings;
  early.response = false;
  const sim::Kinematics kinematics = scene.kinematics;
  std::optional<sim::Simulation> holder;
  holder.emplace(std::move(scene.model), std::move(scene.state), scene.field, std::move(scene.obstacles),
                 std::move(scene.kinematics), delayed ? early : settings, start.frame);
  sim::Simulation* simulation = &*holder;
  // The stochastic detector's kept pairs and generator, when the method is unchanged.
  if (side && side->values.count("detector_state")) {
    if (settings.method.to_string() == side->text("method", side_path)) {
      simulation->restore_detector_state(side->text("detector_state", side_path));
    } else if (!side->text("detector_state", side_path).empty()) {
      std::cerr << "crumple: warning: the method changed from " << side->text("method", side_path)
                << ": its saved state across frames is not restored\n";
    }
  }

  if (!args.quiet) {
    std::printf("crumple simulate: %s\n  %d particles, %zu springs, %zu faces, %d edges; dt %.6g s x %d substeps "
                "per frame, %s, detector %s, thickness %.6g m, response %s\n",
                start.source.c_str(), simulation->model().num_particles(), simulation->model().springs().size(),
                faces.size(), simulation->model().topology().num_edges(), settings.dt, settings.substeps,
                integrator_name.c_str(), settings.method.to_string().c_str(),
                settings.detector.thickness,
                delayed ? ("off until frame " + std::to_string(*args.response_from) + ", then on").c_str()
                : settings.response ? "on"
                                    : "off");
    std::fflush(stdout);
  }

  // Statistics: one complete line at a time, flushed, so an interrupted run leaves whole lines.
  std::FILE* csv = std::fopen(csv_path.string().c_str(), append ? "a" : "w");
  if (!csv) throw InputError("cannot write " + csv_path.string() + ": " + std::strerror(errno));
  const auto write_csv = [&](const std::string& text) {
    if (std::fputs(text.c_str(), csv) < 0 || std::fflush(csv) != 0) {
      throw InputError("cannot write " + csv_path.string() + ": " + std::strerror(errno));
    }
  };
  struct CloseCsv {
    std::FILE*& file;
    ~CloseCsv() {
      if (file) std::fclose(file);
    }
  } close_csv{csv};
  if (!append) write_csv(std::string(kStatsHeader) + "\n");

  Summary summary;
  const auto record = [&](const sim::FrameStats& s) {
    const std::string line =
        std::to_string(s.frame) + "," + csv_number(s.time) + "," + csv_number(s.integrate_ms) + "," +
        csv_number(s.detect_ms) + "," + csv_number(s.response_ms) + "," + std::to_string(s.vf) + "," +
        std::to_string(s.ee) + "," + std::to_string(s.tt) + "," + csv_number(s.collision_share) + "," +
        csv_number(s.min_distance) + "," + csv_number(s.obstacle_penetration) + "," +
        std::to_string(s.cg_iterations) + "," + std::to_string(s.corrections) + "," +
        csv_number(s.energy) + "," + csv_number(s.max_speed) + "," + csv_number(s.bounds.min.x()) + "," +
        csv_number(s.bounds.min.y()) + "," + csv_number(s.bounds.min.z()) + "," +
        csv_number(s.bounds.max.x()) + "," + csv_number(s.bounds.max.y()) + "," +
        csv_number(s.bounds.max.z()) + "," + csv_number(s.ccd_ms) + "," + std::to_string(s.ccd_impacts) + "," +
        std::to_string(s.ccd_frozen) + "," + std::to_string(s.intersecting_pairs) + "," +
        std::to_string(s.contours) + "," + std::to_string(s.untangle_pulls) + "," + std::to_string(s.pinches) + "," +
        std::to_string(s.ccd_zone_vertices) + "," + csv_number(s.longest_spring) + "\n";
    write_csv(line);
    if (!args.quiet && s.intersecting_pairs == 0 && s.pinches == 0 && summary.last_pairs > 0 &&
        summary.clean_frame < 0) {
      std::printf("\rcrumple simulate: 0 intersecting triangle pairs at frame %lld, pinches included (%lld before)\n",
                  static_cast<long long>(s.frame), summary.last_pairs);
      std::fflush(stdout);
    }
    if ((s.frame - start.frame) % args.every == 0) {
      io::write_mesh(frames_dir / frame_name(s.frame, args.format), simulation->state().x, faces);
      ++summary.written;
    }
    summary.add(s, settings.detector.thickness);
  };
  const auto save = [&] { save_state(out, *simulation, simulation->settings(), spec_text, start.seed); };

  // SIGINT and SIGTERM finish the current frame, then leave complete files and a state to resume.
  g_interrupted = 0;
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  struct sigaction previous_int {}, previous_term {};
  ::sigaction(SIGINT, &action, &previous_int);
  ::sigaction(SIGTERM, &action, &previous_term);
  struct RestoreSignals {
    struct sigaction &int_action, &term_action;
    ~RestoreSignals() {
      ::sigaction(SIGINT, &int_action, nullptr);
      ::sigaction(SIGTERM, &term_action, nullptr);
    }
  } restore_signals{previous_int, previous_term};

  Progress progress("simulate", "frame", static_cast<std::size_t>(args.frames), !args.quiet);
  std::optional<sim::DivergenceError> diverged;
  if (append) {
    summary.add(simulation->current_stats(), settings.detector.thickness);  // already on file
  } else {
    record(simulation->current_stats());
  }
  const auto loop_start = std::chrono::steady_clock::now();
  try {
    for (long long k = 0; k < args.frames; ++k) {
      if (g_interrupted) break;
      if (delayed && simulation->frame() == *args.response_from) {
        // The response starts: a new simulation from the current state with `settings`.
        sim::Simulation& before = *simulation;
        sim::Simulation next(before.model(), before.state(), before.field(), before.obstacles(), kinematics,
                             settings, before.frame());
        holder.emplace(std::move(next));
        simulation = &*holder;
      }
      const sim::FrameStats frame = simulation->advance_frame();
      record(frame);
      // The progress line's note: frames per second so far, and the untangling's count.
      const double seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - loop_start).count();
      char note[96];
      int used = std::snprintf(note, sizeof note, "%.1f fps", seconds > 0 ? static_cast<double>(k + 1) / seconds : 0.0);
      if (frame.intersecting_pairs >= 0) {
        std::snprintf(note + used, sizeof note - static_cast<std::size_t>(used), ", %lld intersecting pairs, %lld pinches",
                      static_cast<long long>(frame.intersecting_pairs), static_cast<long long>(frame.pinches));
      }
      progress.update(static_cast<std::size_t>(k + 1), note);
    }
  } catch (const sim::DivergenceError& e) {
    diverged = e;  // the simulation is back at the last good frame
  }
  summary.wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - loop_start).count();
  progress.finish();
  // The close is checked too (every line was flushed and checked as written); the state is
  // saved first either way, so that a failed close still leaves a run that resumes.
  const bool closed = std::fclose(csv) == 0;
  const int close_errno = errno;
  csv = nullptr;
  save();
  if (!closed) throw InputError("cannot write " + csv_path.string() + ": " + std::strerror(close_errno));

  if (diverged) {
    const Scalar frame_time = settings.dt * settings.substeps;
    const auto [dt, substeps] = sim::stable_split(frame_time, std::min(settings.dt / 4, stable_dt));
    const std::string state = (out / "state.x3d").string();
    // No step is stable (explicit Euler on an undamped element): another integrator instead.
    char smaller[128];
    if (stable_dt > 0) {
      std::snprintf(smaller, sizeof smaller, "--dt %.3g --substeps %d", dt, substeps);
    } else {
      std::snprintf(smaller, sizeof smaller, "-i symplectic-euler");
    }
    std::fprintf(stderr,
                 "crumple: error: %s.\n"
                 "  Frames up to %lld are written; the last good state (frame %lld) is saved in %s.\n"
                 "  Resume it with a smaller time step or a stable integrator, e.g.\n"
                 "    crumple simulate %s %s\n"
                 "    crumple simulate %s -i implicit-euler\n",
                 diverged->what(), static_cast<long long>(simulation->frame()),
                 static_cast<long long>(simulation->frame()), state.c_str(), state.c_str(), smaller,
                 state.c_str());
    return 1;
  }
  int status = 0;
  if (g_interrupted) {
    std::fprintf(stderr, "crumple: %s after frame %lld; files are complete, resume with `crumple simulate %s`\n",
                 g_interrupted == SIGTERM ? "terminated" : "interrupted",
                 static_cast<long long>(simulation->frame()), (out / "state.x3d").string().c_str());
    status = 128 + static_cast<int>(g_interrupted);
  }
  if (!args.quiet) print_summary(summary, *simulation, frames_dir, csv_path, append, out);
  return status;
}

}  // namespace

Run add_simulate_command(CLI::App& app) {
  auto args = std::make_shared<SimulateArgs>();
  app.description(
      "Simulate a mass-spring cloth with self-collision detection (and response), writing one mesh\n"
      "per frame to DIR/frames/NNNNNN.EXT (the initial state first), per-frame statistics to\n"
      "DIR/stats.csv and the final state to DIR/state.x3d (MassSpring node) + DIR/state.json;\n"
      "`crumple simulate DIR/state.x3d` resumes the run bit for bit. Ctrl-C or SIGTERM finishes\n"
      "the current frame and leaves every file complete. The state is checked after every step:\n"
      "a diverging run stops with an error and saves its last good frame's state.");
  app.add_option("SCENE", args->input, scenes_help())->capture_default_str();
  app.add_option("-p,--param", args->params,
                 "Scene key=value (repeatable), e.g. -p nx=20; for files: pins, stiffness, ...");
  app.add_option("-n,--frames", args->frames, "Frames to simulate")->capture_default_str();
  app.add_option("--dt", args->dt, "Time step (s); default: the scene's");
  app.add_option("--substeps", args->substeps,
                 "Steps per frame; default: the scene's, split further (up to 100x, said on stderr) where an "
                 "explicit integrator needs a smaller step to stay stable");
  app.add_option("-i,--integrator", args->integrator,
                 "explicit-euler, symplectic-euler, rk4, implicit-euler or projective; default: the scene's");
  add_detection_options(app, args->detection,
                        {.method_default = std::string("the scene's (") + kDefaultMethod + ")",
                         .thickness_default = "the scene's"});
  app.add_option("--response", args->response, "Self-collision response on|off; default: the scene's");
  app.add_option("--passes", args->passes, "Response sweeps per step; default 4");
  app.add_option("--fail-safe", args->fail_safe,
                 "on|off: with response on, the continuous (CCD) fail-safe that keeps every frame "
                 "intersection-free; default on");
  app.add_option("--untangle", args->untangle,
                 "on|off: with response on, untangle a cloth that already intersects itself (Global "
                 "Intersection Analysis); the column intersecting_pairs of stats.csv counts the "
                 "intersecting triangle pairs every frame; default on");
  app.add_option("--untangle-pull", args->untangle_pull,
                 "solve|after: the untangling pulls act inside the implicit Euler step, as stiff springs "
                 "that the cloth's springs share with the pulled vertices' neighbours (solve), or move "
                 "the vertices after each step (after; other integrators always); default after");
  app.add_option("--motion-search", args->motion_search,
                 "on|off: with response on, pairs that the velocities bring within the thickness over "
                 "the frame join its contacts (a continuous query over the fast vertices); default: the "
                 "scene's (off)");
  app.add_option("--motion-retries", args->motion_retries,
                 "With response on, how many times a frame may run again when its own motion brings "
                 "pairs within the fail-safe's reach that were beyond the detection radius at its start "
                 "(they join its contacts); default: the scene's (crumple 2, 1 above n = 100; cloth-on-sphere 1 above n = 100; "
                 "twisted-ribbon 3 above nx = 100; others 0)")
      ->check(CLI::Range(0, 100));
  app.add_option("--push-relaxation", args->push_relaxation,
                 "With response on, the share (0, 1] of a pair's shortfall below the thickness that each "
                 "push-out closes (below 1, layers squeezed from both sides settle instead of trading "
                 "pushes with the springs); default: the scene's (crumple 0.5, others 1)");
  app.add_option("--response-from", args->response_from,
                 "Frame from which the response is on; before it the run has no response (e.g. a "
                 "hanging cloth falls through itself, then untangles)");
  app.add_option("-s,--seed", args->seed, "Seed of the scene's random perturbation; default 1");
  app.add_option("-o,--out", args->out,
                 std::string("Output folder; default: the resumed state's folder (the run goes "
                             "on there, stats.csv appended), else ") + kDefaultOut);
  app.add_flag("--force", args->force,
               "Replace the files of another run (frames, stats.csv, state) in --out");
  app.add_option("-f,--format", args->format, "Frame format: obj, ply, off or x3d")->capture_default_str();
  app.add_option("--every", args->every, "Write every K-th frame only (stats keep every frame)")
      ->capture_default_str();
  app.add_flag("-q,--quiet", args->quiet, "No header, progress or summary");
  return [args]() { return run_simulate(*args); };
}

}  // namespace crumple::cli

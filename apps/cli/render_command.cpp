// `crumple render`: pictures without a display. A built-in scene (simulated up to the frame),
// a mesh file or a folder of frames is drawn by the software rasteriser of crumple::render with
// the viewer's colouring (red edges in collision, VF contacts as segments) and written as PNG;
// `--video DIR` writes one PNG per frame (and an MP4 when ffmpeg is on PATH).
#include "commands.hpp"
#include "options.hpp"
#include "outputs.hpp"
#include "process.hpp"
#include "progress.hpp"
#include "sim_glue.hpp"

#include <crumple/core/error.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/io/frames.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/render/colouring.hpp>
#include <crumple/sim/scene.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace crumple::cli {

namespace {

struct RenderArgs {
  std::string input = "hanging-cloth";
  std::vector<std::string> params;
  std::optional<long long> frame;
  std::string out;
  std::string size = "800x600";
  std::optional<std::string> camera;
  bool wireframe = false;
  bool springs = false;
  int supersample = 2;
  DetectionArgs detection;
  std::optional<std::string> response;
  std::optional<std::uint64_t> seed;
  std::string video;
  long long every = 1;
  bool force = false;
  bool quiet = false;
};

struct Size {
  int width = 800, height = 600;
};

Size parse_size(const std::string& text) {
  Size s;
  char extra = 0;
  if (std::sscanf(text.c_str(), "%dx%d%c", &s.width, &s.height, &extra) != 2 || s.width < 1 ||
      s.height < 1 || s.width > 8192 || s.height > 8192) {
    throw InputError(
        std::string("--size expects WxH with 1..8192 pixels a side (e.g. 800x600), got '")
            .append(text)
            .append("'"));
  }
  return s;
}

struct CameraArg {
  double yaw = 30, pitch = 20;
  std::optional<double> distance;
};

CameraArg parse_camera(const std::string& text) {
  std::vector<double> values;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, ',');) {
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    const bool ok = !item.empty() && end == item.c_str() + item.size();
    values.push_back(ok ? v : std::numeric_limits<double>::quiet_NaN());
  }
  const auto bad = [&] {
    return InputError(
        std::string("--camera expects YAW,PITCH[,DISTANCE] (degrees, degrees, scene units "
                    "> 0), got '")
            .append(text)
            .append("'"));
  };
  if (values.size() < 2 || values.size() > 3) throw bad();
  for (double v : values) {
    if (!std::isfinite(v)) throw bad();
  }
  CameraArg c{values[0], values[1], std::nullopt};
  if (values.size() == 3) {
    if (!(values[2] > 0)) throw bad();
    c.distance = values[2];
  }
  if (c.pitch < -89 || c.pitch > 89)
    throw InputError("--camera: pitch must be in [-89, 89] degrees");
  return c;
}

bool looks_like_file(const std::string& input) {
  return input.find(':') == std::string::npos &&
         (std::filesystem::exists(input) || !std::filesystem::path(input).extension().empty());
}

/// Draws and writes frames with one camera set-up and one size.
class Painter {
 public:
  Painter(const RenderArgs& args)
      : size_(parse_size(args.size)),
        camera_(args.camera ? parse_camera(*args.camera) : CameraArg{}) {
    if (args.supersample < 1 || args.supersample > 4) throw InputError("--aa must be 1..4");
    // The rasteriser holds colour and depth for every sample: bound them (~1.5 GB).
    constexpr long long kMaxSamples = 1LL << 27;
    const long long samples = static_cast<long long>(size_.width) * size_.height *
                              args.supersample * args.supersample;
    if (samples > kMaxSamples) {
      throw InputError("--size " + args.size + " with --aa " + std::to_string(args.supersample) +
                       " needs " + std::to_string(samples) + " samples, more than " +
                       std::to_string(kMaxSamples) + ": lower --aa or --size");
    }
    options_.wireframe = args.wireframe;
    options_.masses_springs = args.springs;
    supersample_ = args.supersample;
  }

  render::Picture paint(const Topology& topology, PositionsView x, const ContactSet& contacts,
                        std::span<const Edge> springs, std::span<const bool> pinned,
                        std::span<const render::ShapeMesh> obstacles) const {
    render::Camera cam;
    cam.yaw_deg = camera_.yaw;
    cam.pitch_deg = camera_.pitch;
    cam.fit(compute_bounds(x), static_cast<double>(size_.width) / size_.height);
    if (camera_.distance) cam.distance = *camera_.distance;
    render::Frame frame{&topology, x, &contacts, springs, pinned, obstacles};
    return render::render_frame(frame, cam, size_.width, size_.height, options_, supersample_);
  }
  const Size& size() const { return size_; }

 private:
  Size size_;
  CameraArg camera_;
  render::DrawOptions options_;
  int supersample_ = 2;
};

std::string frame_png(const std::filesystem::path& dir, long long frame) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%06lld.png", frame);
  return (dir / buf).string();
}

/// Writes one frame of a video or the single picture, and says what it drew.
struct Output {
  const RenderArgs& args;
  const Painter& painter;
  long long last = 0;  ///< the frame written to --out
  long long pictures = 0;

  void frame(long long index, const Topology& topology, PositionsView x, const ContactSet& contacts,
             std::span<const Edge> springs = {}, std::span<const bool> pinned = {},
             std::span<const render::ShapeMesh> obstacles = {}) {
    const bool video_frame = !args.video.empty() && index % args.every == 0;
    const bool is_last = index == last;
    if (!video_frame && !(is_last && !args.out.empty())) return;
    const render::Picture picture = painter.paint(topology, x, contacts, springs, pinned, obstacles);
    if (video_frame) {
      render::write_png(frame_png(args.video, index), picture);
      ++pictures;
    }
    if (is_last && !args.out.empty()) {
      render::write_png(args.out, picture);
      if (!args.quiet) {
        std::printf(
            "crumple render: wrote %s (%dx%d, frame %lld, %zu vf + %zu ee contacts, %.1f%% of "
            "edges in collision)\n",
            args.out.c_str(), picture.width(), picture.height(), index, contacts.vf.size(),
            contacts.ee.size(), 100 * sim::collision_share(topology, contacts));
      }
    }
  }
};

void render_scene(const RenderArgs& args, Output& output) {
  sim::Scene scene;
  if (!looks_like_file(args.input)) {
    scene = sim::make_scene(apply_params(sim::SceneSpec::parse(args.input), args.params),
                            args.seed.value_or(1));
  } else {
    const io::MassSpringData data = io::read_mass_spring(args.input);
    scene =
        sim::make_scene_from_model(model_from_mass_spring(data), state_from_mass_spring(data, 0),
                                   apply_params(sim::SceneSpec::parse("file"), args.params));
  }
  sim::Settings settings = scene.settings;
  settings.method = method_of(args.detection, settings.method);
  settings.detector.thickness =
      thickness_of(args.detection, scene.state.x, settings.detector.thickness);
  if (args.detection.kinds) settings.detector.kinds = ContactKinds::parse(*args.detection.kinds);
  if (args.response) {
    if (*args.response != "on" && *args.response != "off") {
      throw InputError("--response expects on or off, got '" + *args.response + "'");
    }
    settings.response = *args.response == "on";
  }
  settings.detector.threads = args.detection.threads;
  check_contact_budget(scene.model.topology(), scene.state.x, settings.detector,
                       args.detection.max_contacts);
  sim::Simulation simulation(std::move(scene.model), std::move(scene.state), scene.field,
                             std::move(scene.obstacles), std::move(scene.kinematics), settings);
  std::vector<Edge> springs;
  for (const sim::Spring& s : simulation.model().springs()) springs.push_back({s.a, s.b});
  const auto pinned_flags = [&] {
    std::unique_ptr<bool[]> flags(
        new bool[static_cast<std::size_t>(simulation.model().num_particles())]);
    for (Index i = 0; i < simulation.model().num_particles(); ++i)
      flags[static_cast<std::size_t>(i)] = simulation.model().pinned(i);
    return flags;
  }();
  const std::span<const bool> pinned(pinned_flags.get(),
                                     static_cast<std::size_t>(simulation.model().num_particles()));
  const long long last = args.frame.value_or(0);
  output.last = last;
  Progress progress("render", "frame", static_cast<std::size_t>(last + 1), !args.quiet);
  for (long long f = 0;; ++f) {
    progress.update(static_cast<std::size_t>(f));
    output.frame(f, simulation.model().topology(), simulation.state().x, simulation.contacts(), springs, pinned,
                 render::obstacle_meshes(simulation.obstacles(), simulation.state().time, simulation.state().x));
    if (f >= last) break;
    simulation.advance_frame();
  }
  progress.update(static_cast<std::size_t>(last + 1));
}

void render_files(const RenderArgs& args, Output& output) {
  const std::filesystem::path input(args.input);
  const bool folder = std::filesystem::is_directory(input);
  io::FrameSequence frames(folder ? frame_files({args.input})
                                 : std::vector<std::filesystem::path>{input});
  // A video of a folder without --frame runs over every frame.
  const long long index =
      args.frame.value_or(args.video.empty() ? 0 : static_cast<long long>(frames.size()) - 1);
  output.last = index;
  if (index < 0 || static_cast<std::size_t>(index) >= frames.size()) {
    throw InputError(std::string("--frame ")
                         .append(std::to_string(index))
                         .append(" is out of range: ")
                         .append(args.input)
                         .append(" has ")
                         .append(std::to_string(frames.size()))
                         .append(frames.size() == 1 ? " frame" : " frames"));
  }
  const DetectorOptions options = detector_options(args.detection, frames.first().positions());
  check_contact_budget(frames.first().topology(), frames.first().positions(), options,
                       args.detection.max_contacts);
  auto detector = make_detector(method_of(args.detection), options);
  detector->set_topology(frames.first().topology_ptr());
  ContactSet contacts;
  const Topology& topology = frames.first().topology();
  if (args.video.empty()) {
    const Positions x = frames.positions(static_cast<std::size_t>(index));
    detector->update(x, contacts);
    output.frame(index, topology, x, contacts);
    return;
  }
  Positions previous;
  Progress progress("render", "frame", static_cast<std::size_t>(index + 1), !args.quiet);
  for (long long f = 0; f <= index; ++f) {
    progress.update(static_cast<std::size_t>(f));
    Positions x = frames.positions(static_cast<std::size_t>(f));
    if (previous.empty()) {
      detector->update(x, contacts);
    } else {
      detector->update(previous, x, contacts);
    }
    output.frame(f, topology, x, contacts);
    previous = std::move(x);
  }
  progress.update(static_cast<std::size_t>(index + 1));
}

/// Whether `name` is a picture or the video of a `--video` folder.
bool is_video_file(const std::filesystem::path& name) {
  const std::string stem = name.stem().string();
  if (name.filename() == "video.mp4") return true;
  return name.extension() == ".png" && stem.size() == 6 &&
         std::all_of(stem.begin(), stem.end(), [](char c) { return c >= '0' && c <= '9'; });
}

/// Creates the --video folder. Pictures of another video there would be mixed into this one:
/// refused, or removed with --force.
void prepare_video_folder(const std::filesystem::path& dir, bool force) {
  prepare_output_folder(dir, "--video");
  std::vector<std::filesystem::path> stale;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.is_regular_file() && is_video_file(entry.path().filename())) stale.push_back(entry.path());
  }
  if (stale.empty()) return;
  if (!force) {
    throw InputError("--video '" + dir.string() + "' holds the pictures of another video (" +
                     stale.front().filename().string() +
                     ", ...): give a new or empty folder, or --force to replace them");
  }
  for (const auto& path : stale) std::filesystem::remove(path);
}

int run_render(RenderArgs args) {
  if (args.out.empty() && args.video.empty())
    throw InputError("nothing to write: give --out FILE.png and/or --video DIR");
  if (args.frame && *args.frame < 0) throw InputError("--frame must be >= 0");
  if (args.every < 1) throw InputError("--every must be >= 1");
  if (!args.out.empty() && std::filesystem::path(args.out).extension() != ".png") {
    throw InputError("--out must name a .png file, got '" + args.out + "'");
  }
  const Painter painter(args);
  const bool file = looks_like_file(args.input);
  if (file && !std::filesystem::exists(args.input))
    throw InputError("no such file, folder or scene: '" + args.input + "'");
  check_detection_args(args.detection);
  if (!args.out.empty()) check_output_file(args.out, "--out");
  if (!args.video.empty()) prepare_video_folder(args.video, args.force);
  Output output{args, painter};
  const bool mass_spring = file && !std::filesystem::is_directory(args.input) &&
                           io::format_from_path(args.input) == io::MeshFormat::X3d &&
                           file_mentions(args.input, "MassSpring");
  if (!file || mass_spring) {
    render_scene(args, output);
  } else {
    render_files(args, output);
  }
  if (!args.video.empty()) {
    const std::string mp4 = (std::filesystem::path(args.video) / "video.mp4").string();
    if (!args.quiet)
      std::printf("crumple render: wrote %lld PNGs to %s\n", output.pictures, args.video.c_str());
    if (on_path("ffmpeg")) {
      // Run in the video folder with relative names: no shell, and no folder name reaches
      // ffmpeg's glob pattern.
      const std::vector<std::string> command{
          "ffmpeg", "-nostdin", "-y", "-loglevel", "error", "-framerate", "30",
          "-pattern_type", "glob", "-i", "[0-9][0-9][0-9][0-9][0-9][0-9].png",
          "-pix_fmt", "yuv420p", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "video.mp4"};
      if (!args.quiet) {
        std::fprintf(stderr, "crumple render: encoding %lld pictures into %s with ffmpeg\n",
                     output.pictures, mp4.c_str());
      }
      const int status = run_program(command, args.video);
      if (status != 0) {
        throw Error("ffmpeg failed (exit status " + std::to_string(status) + ") writing " + mp4);
      }
      if (!args.quiet) std::printf("crumple render: wrote %s\n", mp4.c_str());
    } else if (!args.quiet) {
      std::printf("crumple render: ffmpeg is not on PATH: no MP4, PNGs only\n");
    }
  }
  return 0;
}

}  // namespace

Run add_render_command(CLI::App& app) {
  auto args = std::make_shared<RenderArgs>();
  app.description(
      "Render a built-in scene (simulated up to --frame), a mesh file or a folder of frames to "
      "PNG\n"
      "without a display (software rasteriser), with the viewer's colouring: shaded surface lit "
      "on\n"
      "both sides, edges in collision in red, vertex-face contacts as green segments.");
  app.add_option(
         "INPUT", args->input,
         "Scene SPEC (see `crumple simulate --help`), a mesh file (.obj .ply .off .x3d; an X3D\n"
         "MassSpring node is simulated like a scene) or a folder of frame files")
      ->capture_default_str();
  app.add_option("-p,--param", args->params, "Scene key=value (repeatable)");
  app.add_option("--frame", args->frame,
                 "Scenes: frames to simulate first; folders: index of the frame (sorted by name);\n"
                 "default 0 (with --video and a folder: the last frame)");
  app.add_option("-o,--out", args->out, "PNG file to write");
  app.add_option("--size", args->size, "Picture size WxH in pixels")->capture_default_str();
  app.add_option(
      "--camera", args->camera,
      "YAW,PITCH[,DISTANCE]: orbit angles in degrees (default 30,20) and distance to the\n"
      "centre of the bounding box (default: fitted to the frame)");
  app.add_flag("--wireframe", args->wireframe, "Draw every mesh edge over the surface");
  app.add_flag("--springs", args->springs, "Draw the masses and springs alone (as in the thesis)");
  app.add_option("--aa", args->supersample, "Anti-aliasing: 1..4 samples per pixel along each axis")
      ->capture_default_str();
  add_detection_options(app, args->detection,
                        {.method_default = std::string("the scene's, or ") + kDefaultMethod +
                                           " for files",
                         .thickness_default = "the scene's, or 1e-3 of the first frame's "
                                              "bounding-box diagonal for files"});
  app.add_option("--response", args->response,
                 "Scenes: self-collision response on|off; default: the scene's");
  app.add_option("-s,--seed", args->seed, "Scenes: seed of the random perturbation; default 1");
  app.add_option(
      "--video", args->video,
      "Write DIR/NNNNNN.png for frames 0..--frame (every --every), and DIR/video.mp4 when\n"
      "ffmpeg is on PATH");
  app.add_option("--every", args->every, "With --video: every K-th frame")->capture_default_str();
  app.add_flag("--force", args->force,
               "With --video: replace the pictures of another video in DIR");
  app.add_flag("-q,--quiet", args->quiet, "Print nothing on success");
  return [args]() { return run_render(*args); };
}

}  // namespace crumple::cli

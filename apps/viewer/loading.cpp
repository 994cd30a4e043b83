#include "loading.hpp"

#include "../cli/sim_glue.hpp"

#include <crumple/core/error.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/io/x3d.hpp>
#include <crumple/mesh/mesh.hpp>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

namespace crumple::viewer {

namespace {

bool is_mesh_file(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".obj" || ext == ".ply" || ext == ".off" || ext == ".x3d";
}

bool mentions(const std::filesystem::path& path, const std::string& needle) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str().find(needle) != std::string::npos;
}

/// The options' method (default `kDefaultMethod`) and thickness over `settings`.
void apply_overrides(const Options& options, sim::Settings& settings) {
  settings.method = MethodSpec::parse(options.method.value_or(kDefaultMethod));
  if (options.thickness) settings.detector.thickness = *options.thickness;
  if (options.response) settings.response = *options.response;
  if (options.untangle) settings.untangle = *options.untangle;
  if (options.response_from >= 0) {
    if (options.response == false) throw InputError("--response-from needs the response on, not --response off");
    settings.response = true;
  }
}

}  // namespace

Loaded load_input(const Options& options) {
  const std::filesystem::path path(options.input);
  const bool is_spec = options.input.find(':') != std::string::npos;
  const bool file = !is_spec && std::filesystem::exists(path);
  Loaded out;
  if (file && std::filesystem::is_directory(path)) {
    std::vector<std::filesystem::path> files;
    for (const auto& e : std::filesystem::directory_iterator(path)) {
      if (e.is_regular_file() && is_mesh_file(e.path())) files.push_back(e.path());
    }
    std::sort(files.begin(), files.end());
    if (files.empty()) throw InputError("folder '" + path.string() + "' holds no .obj .ply .off .x3d frame");
    if (options.response_from >= 0) throw InputError("--response-from needs a simulated scene, not a folder of frames");
    out.frames.emplace(std::move(files));
    out.settings.detector.thickness = default_thickness(out.frames->first().positions());
    apply_overrides(options, out.settings);
    out.source = "frames " + path.string();
    return out;
  }
  if (!file && !path.extension().empty() && !is_spec) {
    throw InputError("no such file, folder or scene: '" + options.input + "'");
  }
  const sim::SceneSpec spec = cli::apply_params(sim::SceneSpec::parse(file ? "file" : options.input), options.params);
  if (!file) {
    out.scene = sim::make_scene(spec, options.seed);
    out.source = "scene " + out.scene->spec;
  } else if (io::format_from_path(path) == io::MeshFormat::X3d && mentions(path, "MassSpring")) {
    const io::MassSpringData data = io::read_mass_spring(path);
    out.scene = sim::make_scene_from_model(cli::model_from_mass_spring(data), cli::state_from_mass_spring(data, 0), spec);
    out.source = "mass-spring " + path.string();
  } else {
    out.scene = sim::make_scene_from_mesh(io::read_mesh(path), spec);
    out.source = "mesh " + path.string();
  }
  out.settings = out.scene->settings;
  apply_overrides(options, out.settings);
  return out;
}

sim::FrameStats Playback::show(std::size_t i, const sim::Settings& settings) {
  Positions x = frames_.positions(i);
  const auto t0 = std::chrono::steady_clock::now();
  const std::string key = settings.method.to_string() + "|" + std::to_string(settings.detector.thickness);
  if (!detector_ || detector_key_ != key) {
    detector_ = make_detector(settings.method, settings.detector);
    detector_->set_topology(frames_.first().topology_ptr());
    detector_key_ = key;
    x_.clear();
  }
  if (x_.size() == x.size()) {
    detector_->update(x_, x, contacts_);
  } else {
    detector_->update(x, contacts_);
  }
  sim::FrameStats stats;
  stats.frame = static_cast<std::int64_t>(i);
  stats.detect_ms = ms_since(t0);
  stats.vf = contacts_.vf.size();
  stats.ee = contacts_.ee.size();
  stats.tt = contacts_.tt.size();
  stats.collision_share = sim::collision_share(topology(), contacts_);
  x_ = std::move(x);
  index_ = i;
  return stats;
}

}  // namespace crumple::viewer

#include "commands.hpp"

#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/io/frames.hpp>
#include <crumple/mesh/shapes.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <unistd.h>

namespace crumple::cli {

namespace {

struct DetectArgs {
  std::vector<std::string> files;
  std::string method = "naive";
  std::optional<double> thickness;
  std::optional<double> thickness_rel;
  std::string kinds = "vf,ee";
  int threads = 0;
  std::string contacts;
  bool json = false;
};

std::string methods_help() {
  std::string out = "Detection method SPEC, NAME[:key=value,...]. Methods:";
  for (const MethodInfo& m : all_methods()) {
    out += "\n  " + std::string(m.name) + " — " + std::string(m.summary);
    for (const ParamInfo& p : m.params) {
      out += "\n      " + std::string(p.key) + "=" + std::string(p.default_value) + "  " +
             std::string(p.description);
    }
  }
  return out;
}

std::string stats_json(const DetectorStats& stats) {
  JsonObject object;
  for (const auto& [key, value] : stats.items()) object.add(key, value);
  return object.str();
}

/// The frames to process: files from the command line, or the built-in scene.
struct Input {
  std::optional<io::FrameSequence> files;
  std::optional<TriMesh> scene;
  std::size_t size() const { return files ? files->size() : 1; }
  const TriMesh& first() const { return files ? files->first() : *scene; }
  std::string name(std::size_t i) const {
    return files ? files->file(i).string() : std::string("builtin:folded-cloth");
  }
  std::string stem(std::size_t i) const {
    return files ? files->file(i).stem().string() : std::string("folded-cloth");
  }
  Positions positions(std::size_t i) const {
    return files ? files->positions(i) : scene->positions();
  }
};

int run_detect(const DetectArgs& args) {
  const MethodSpec spec = MethodSpec::parse(args.method);
  DetectorOptions options;
  options.kinds = ContactKinds::parse(args.kinds);
  options.threads = args.threads;

  Input input;
  Scalar default_thickness = 0;
  if (args.files.empty()) {
    const shapes::FoldedClothParams params;
    input.scene = shapes::folded_cloth(params);
    default_thickness = params.thickness;
  } else {
    std::vector<std::filesystem::path> paths(args.files.begin(), args.files.end());
    input.files.emplace(std::move(paths));
  }
  const TriMesh& mesh = input.first();
  const Scalar diagonal = compute_bounds(mesh.positions()).diagonal();
  if (args.thickness) {
    options.thickness = *args.thickness;
  } else if (args.thickness_rel) {
    options.thickness = *args.thickness_rel * diagonal;
  } else if (input.scene) {
    options.thickness = default_thickness;
  } else {
    options.thickness = 1e-3 * diagonal;
  }

  const bool several = input.size() > 1;
  if (!args.contacts.empty() && several) {
    std::filesystem::create_directories(args.contacts);
  }

  std::unique_ptr<Detector> detector = make_detector(spec, options);
  detector->set_topology(mesh.topology_ptr());
  if (!args.json) {
    std::printf("method %s, thickness %.6g, kinds %s, %d vertices, %d faces, %d edges\n",
                spec.to_string().c_str(), options.thickness, options.kinds.to_string().c_str(),
                mesh.num_vertices(), mesh.num_faces(), mesh.num_edges());
    std::fflush(stdout);
  }
  const bool progress = several && ::isatty(STDERR_FILENO);
  ContactSet contacts;
  Positions previous;
  for (std::size_t i = 0; i < input.size(); ++i) {
    if (progress) std::fprintf(stderr, "\r[%zu/%zu] %s ", i + 1, input.size(), input.name(i).c_str());
    Positions current = input.positions(i);
    const auto start = std::chrono::steady_clock::now();
    detector->update(previous, current, contacts);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (progress) std::fprintf(stderr, "\r\033[K");
    if (args.json) {
      std::cout << JsonObject()
                       .add("frame", i)
                       .add("file", input.name(i))
                       .add("vf", contacts.vf.size())
                       .add("ee", contacts.ee.size())
                       .add("tt", contacts.tt.size())
                       .add("ms", ms)
                       .add_raw("stats", stats_json(detector->stats()))
                       .str()
                << std::endl;
    } else {
      std::printf("frame %zu  %s  vf %zu  ee %zu  tt %zu  %.3f ms\n", i, input.name(i).c_str(),
                  contacts.vf.size(), contacts.ee.size(), contacts.tt.size(), ms);
      std::fflush(stdout);
    }
    if (!args.contacts.empty()) {
      const std::filesystem::path out =
          several ? std::filesystem::path(args.contacts) / (input.stem(i) + ".tsv")
                  : std::filesystem::path(args.contacts);
      write_contacts_file(out, contacts);
    }
    previous = std::move(current);
  }
  return 0;
}

}  // namespace

Run add_detect_command(CLI::App& app) {
  auto args = std::make_shared<DetectArgs>();
  app.description(
      "Detect self-contacts on consecutive frames of one mesh, fed in order to one detector\n"
      "(each frame after the first comes with the previous positions as motion). Without FILE,\n"
      "runs on the built-in folded cloth (32x32 lattice folded over itself, thickness 0.02).\n"
      "Contact: vertex-face or edge-edge pair sharing no vertex closer than the thickness;\n"
      "tt: faces sharing no vertex that intersect.");
  app.add_option("FILE", args->files, "Frame files (.obj .ply .off .x3d), same connectivity")
      ->check(CLI::ExistingFile);
  app.add_option("-m,--method", args->method, methods_help())->capture_default_str();
  auto* thick = app.add_option("-t,--thickness", args->thickness,
                               "Contact thickness h in scene units (default: 1e-3 of the first "
                               "frame's bounding-box diagonal)");
  app.add_option("-r,--thickness-rel", args->thickness_rel,
                 "Thickness as a fraction of the first frame's bounding-box diagonal")
      ->excludes(thick);
  app.add_option("-k,--kinds", args->kinds, "Contact kinds to report: comma-separated vf, ee, tt")
      ->capture_default_str();
  app.add_option("-j,--threads", args->threads, "Worker threads (0 = all cores)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("-c,--contacts", args->contacts,
                 "Write the sorted contact list: to this file for one frame, or into this "
                 "folder as <frame-stem>.tsv for several. Lines: 'vf V F d', 'ee A0 A1 B0 B1 d', "
                 "'tt F0 F1'");
  app.add_flag("--json", args->json,
               "One JSON object per frame: frame, file, vf, ee, tt, ms (detector wall time), "
               "stats");
  return [args]() { return run_detect(*args); };
}

}  // namespace crumple::cli

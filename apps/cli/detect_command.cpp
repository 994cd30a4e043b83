#include "commands.hpp"
#include "options.hpp"
#include "outputs.hpp"
#include "progress.hpp"

#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/io/frames.hpp>
#include <crumple/mesh/shapes.hpp>

#include <chrono>
#include <map>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace crumple::cli {

namespace {

struct DetectArgs {
  std::vector<std::string> files;
  DetectionArgs detection;
  std::string contacts;
  bool json = false;
};

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
  const MethodSpec spec = method_of(args.detection);
  check_detection_args(args.detection);

  Input input;
  std::optional<Scalar> own_thickness;
  if (args.files.empty()) {
    const shapes::FoldedClothParams params;
    input.scene = shapes::folded_cloth(params);
    own_thickness = params.thickness;
  } else {
    input.files.emplace(frame_files(args.files));
  }
  const bool several = input.size() > 1;
  // Outputs checked before any work; one contact file per frame, never one name twice.
  if (!args.contacts.empty()) {
    if (several) {
      std::map<std::string, std::string> names;
      for (std::size_t i = 0; i < input.size(); ++i) {
        const auto [it, fresh] = names.emplace(input.stem(i) + ".tsv", input.name(i));
        if (!fresh) {
          throw InputError("--contacts: frames '" + it->second + "' and '" + input.name(i) +
                           "' would both write " + it->first +
                           "; give frames with distinct file names");
        }
      }
      prepare_output_folder(args.contacts, "--contacts");
    } else {
      check_output_file(args.contacts, "--contacts");
    }
  }
  const TriMesh& mesh = input.first();
  const DetectorOptions options = detector_options(args.detection, mesh.positions(), own_thickness);
  check_contact_budget(mesh.topology(), mesh.positions(), options, args.detection.max_contacts);

  std::unique_ptr<Detector> detector = make_detector(spec, options);
  detector->set_topology(mesh.topology_ptr());
  if (!args.json) {
    std::printf("method %s, thickness %.6g, kinds %s, %d vertices, %d faces, %d edges\n",
                spec.to_string().c_str(), options.thickness, options.kinds.to_string().c_str(),
                mesh.num_vertices(), mesh.num_faces(), mesh.num_edges());
    std::fflush(stdout);
  }
  Progress progress("detect", "frame", input.size(), several);
  ContactSet contacts;
  Positions previous;
  for (std::size_t i = 0; i < input.size(); ++i) {
    Positions current = input.positions(i);
    const auto start = std::chrono::steady_clock::now();
    detector->update(previous, current, contacts);
    const double ms = ms_since(start);
    progress.clear();
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
    progress.update(i + 1);
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
  app.add_option("FILE", args->files,
                 "Frame files (.obj .ply .off .x3d) or folders of them (sorted by name), same "
                 "connectivity");
  add_detection_options(app, args->detection,
                        {.thickness_default = "1e-3 of the first frame's bounding-box diagonal "
                                              "(0.02 for the built-in cloth)"});
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

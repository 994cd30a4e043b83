#include "commands.hpp"
#include "options.hpp"
#include "progress.hpp"

#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/io/frames.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace crumple::cli {

namespace {

struct CompareArgs {
  std::vector<std::string> files;
  DetectionArgs detection;
  std::string against = "naive";
  int n = 24;
  int frames = 60;
  long long seed = 1;
  bool json = false;
};

/// Frame files read on demand.
class FileFrames final : public FrameSource {
 public:
  explicit FileFrames(std::vector<std::filesystem::path> paths) : sequence_(std::move(paths)) {}
  std::size_t size() const override { return sequence_.size(); }
  const TriMesh& mesh() const override { return sequence_.first(); }
  Positions positions(std::size_t i) const override { return sequence_.positions(i); }
  std::string name(std::size_t i) const override { return sequence_.file(i).string(); }

 private:
  io::FrameSequence sequence_;
};

std::string stats_json(const DetectorStats& stats) {
  JsonObject object;
  for (const auto& [key, value] : stats.items()) object.add(key, value);
  return object.str();
}

/// Largest built-in sequence: n x n quads (the naive reference is quadratic in n²).
constexpr int kMaxSize = 1000;
constexpr int kMaxFrames = 100000;

int run_compare(const CompareArgs& args) {
  const MethodSpec method_spec = method_of(args.detection);
  const MethodSpec reference_spec = MethodSpec::parse(args.against);
  check_detection_args(args.detection);

  std::unique_ptr<FrameSource> frames;
  std::optional<Scalar> own_thickness;
  if (args.files.empty()) {
    if (args.n < 2 || args.n > kMaxSize) {
      throw InputError("--size must be between 2 and " + std::to_string(kMaxSize) +
                       " (n x n quads), got " + std::to_string(args.n));
    }
    if (args.frames < 1 || args.frames > kMaxFrames) {
      throw InputError("--frames must be between 1 and " + std::to_string(kMaxFrames) + ", got " +
                       std::to_string(args.frames));
    }
    if (args.seed < 0) throw InputError("--seed must be >= 0");
    auto folding = std::make_unique<FoldingSequence>(
        FoldingParams{.n = args.n, .frames = static_cast<std::size_t>(args.frames),
                      .seed = static_cast<std::uint64_t>(args.seed)});
    own_thickness = folding->thickness();
    frames = std::move(folding);
  } else {
    frames = std::make_unique<FileFrames>(frame_files(args.files));
  }
  const DetectorOptions options =
      detector_options(args.detection, frames->mesh().positions(), own_thickness);
  check_contact_budget(frames->mesh().topology(), frames->mesh().positions(), options, args.detection.max_contacts);

  auto method = make_detector(method_spec, options);
  auto reference = make_detector(reference_spec, options);
  if (!args.json) {
    std::printf("method %s against %s, thickness %.6g, kinds %s, %d vertices, %d faces, %zu frames\n",
                method_spec.to_string().c_str(), reference_spec.to_string().c_str(), options.thickness,
                options.kinds.to_string().c_str(), frames->mesh().num_vertices(),
                frames->mesh().num_faces(), frames->size());
    std::fflush(stdout);
  }
  Progress progress("compare", "frame", frames->size(), frames->size() > 1);
  const auto on_frame = [&](const FrameComparison& f) {
    progress.clear();
    if (args.json) {
      std::cout << JsonObject()
                       .add("frame", f.frame)
                       .add("file", f.name)
                       .add("reference", f.match.reference)
                       .add("found", f.match.found)
                       .add("missed", f.match.missed)
                       .add("false", f.match.false_contacts)
                       .add("recall", f.match.recall())
                       .add("precision", f.match.precision())
                       .add("ms", f.ms)
                       .add("reference_ms", f.reference_ms)
                       .add_raw("stats", stats_json(f.stats))
                       .str()
                << std::endl;
    } else {
      std::printf("frame %zu  %s  reference %zu  found %zu  missed %zu  false %zu  recall %.4f  "
                  "%.3f ms  (reference %.3f ms)\n",
                  f.frame, f.name.c_str(), f.match.reference, f.match.found, f.match.missed,
                  f.match.false_contacts, f.match.recall(), f.ms, f.reference_ms);
      std::fflush(stdout);
    }
    progress.update(f.frame + 1);
  };
  const ComparisonSummary s = compare_detectors(*method, *reference, *frames, on_frame);
  progress.finish();
  if (args.json) {
    std::cout << JsonObject()
                     .add("summary", true)
                     .add("method", method_spec.to_string())
                     .add("against", reference_spec.to_string())
                     .add("frames", s.frames)
                     .add("reference", s.total.reference)
                     .add("found", s.total.found)
                     .add("missed", s.total.missed)
                     .add("false", s.total.false_contacts)
                     .add("recall", s.total.recall())
                     .add("min_recall", s.min_recall)
                     .add("ms", s.mean_ms)
                     .add("reference_ms", s.mean_reference_ms)
                     .str()
              << std::endl;
  } else {
    std::printf("summary  frames %zu  reference %zu  found %zu  missed %zu  false %zu  recall %.4f  "
                "min recall %.4f  %.3f ms/frame  (reference %.3f ms/frame)\n",
                s.frames, s.total.reference, s.total.found, s.total.missed, s.total.false_contacts,
                s.total.recall(), s.min_recall, s.mean_ms, s.mean_reference_ms);
  }
  return 0;
}

}  // namespace

Run add_compare_command(CLI::App& app) {
  auto args = std::make_shared<CompareArgs>();
  app.description(
      "Run a detection method and a reference on the same frames and report, per frame, the\n"
      "reference's contacts found, missed and false (reported but not in the reference), the\n"
      "recall and the time of each, then a summary line. Without FILE, runs on the built-in\n"
      "folding sequence (a lattice folded over itself with a travelling ripple, seeded; thickness\n"
      "a quarter of the edge length; see docs/stochastic.md).");
  app.add_option("FILE", args->files,
                 "Frame files (.obj .ply .off .x3d) or folders of them (sorted by name), same "
                 "connectivity");
  add_detection_options(app, args->detection,
                        {.thickness_default = "the built-in sequence's, or 1e-3 of the first "
                                              "frame's bounding-box diagonal"});
  app.add_option("-a,--against", args->against, "Reference method SPEC")->capture_default_str();
  app.add_option("--size", args->n, "Built-in sequence: lattice resolution n (n x n quads)")
      ->capture_default_str();
  app.add_option("--frames", args->frames, "Built-in sequence: number of frames")->capture_default_str();
  app.add_option("--seed", args->seed, "Built-in sequence: seed")->capture_default_str();
  app.add_flag("--json", args->json,
               "One JSON object per frame (frame, file, reference, found, missed, false, recall, "
               "precision, ms, reference_ms, stats), then a summary object (\"summary\":true)");
  return [args]() { return run_compare(*args); };
}

}  // namespace crumple::cli

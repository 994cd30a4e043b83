#pragma once
// Loading what crumple-view shows — a built-in scene, a mesh or MassSpring file, or a folder of
// frames — and playing a folder of frames back through a detector.

#include "options.hpp"

#include <crumple/detect/detector.hpp>
#include <crumple/io/frames.hpp>
#include <crumple/sim/scene.hpp>
#include <crumple/sim/simulation.hpp>

#include <memory>
#include <optional>
#include <string>

namespace crumple::viewer {

/// The input resolved: either a scene to simulate or frames to play back, with the settings
/// to start from (the options' method and thickness applied).
struct Loaded {
  std::string source;  ///< what was loaded, for the panel ("scene …", "mesh …", "frames …")
  std::optional<sim::Scene> scene;
  std::optional<io::FrameSequence> frames;
  sim::Settings settings;
};

/// Resolves `options.input`: an existing folder (its .obj .ply .off .x3d files in name order),
/// an existing file (a MassSpring X3D model, or a mesh), else a scene spec with the `--param`
/// items. Throws `InputError` on anything else, before any window opens.
Loaded load_input(const Options& options);

/// Frames of one mesh played back through a detector, each frame with the previous as motion.
/// The detector is rebuilt when the method or thickness changes.
class Playback {
 public:
  explicit Playback(io::FrameSequence frames) : frames_(std::move(frames)) {}

  std::size_t size() const { return frames_.size(); }
  std::size_t index() const { return index_; }
  const io::FrameSequence& frames() const { return frames_; }
  /// Detects the contacts of frame `i` with `settings`; returns its figures.
  sim::FrameStats show(std::size_t i, const sim::Settings& settings);

  const Topology& topology() const { return frames_.first().topology(); }
  PositionsView positions() const { return x_; }
  const ContactSet& contacts() const { return contacts_; }
  const Detector* detector() const { return detector_.get(); }

 private:
  io::FrameSequence frames_;
  std::size_t index_ = 0;
  std::unique_ptr<Detector> detector_;
  std::string detector_key_;  ///< method and thickness the detector was made for
  Positions x_;
  ContactSet contacts_;
};

}  // namespace crumple::viewer

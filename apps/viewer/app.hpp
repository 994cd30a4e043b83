#pragma once
// What crumple-view shows and steers: a live simulation or a frame playback (loading.hpp,
// simulation.hpp), the view (camera, drawing options) and the overlays drawn from the
// detector's state. Panels and input (panels.hpp, input.hpp) act on it; main.cpp runs the loop.

#include "gl_draw.hpp"
#include "loading.hpp"
#include "simulation.hpp"

#include <crumple/render/camera.hpp>
#include <crumple/render/colouring.hpp>
#include <crumple/render/rasteriser.hpp>

#include <optional>
#include <string>

namespace crumple::viewer {

class App {
 public:
  /// Takes what `load_input` resolved and starts it (frame 0, or the scene's initial state).
  explicit App(Loaded loaded);

  // Simulation or playback.
  /// Back to the initial state (frame 0 when playing frames), with the current settings.
  void reset();
  /// Applies new settings, keeping the current state; the detector is rebuilt.
  void apply_settings(const sim::Settings& settings);
  /// One simulated frame, or the next frame of the playback (wrapping around).
  void advance();
  /// Runs the frames before `frame` with the response off, then with the settings' response
  /// (a cloth that falls through itself, then untangles); again after each reset. < 0: never.
  void set_response_from(std::int64_t frame);
  std::int64_t response_from() const { return response_from_; }
  /// The response is held off until `response_from()`.
  bool response_delayed() const;
  /// Simulated frames per second over the frames advanced since the last reset (their
  /// `advance` calls' wall time), 0 before the first.
  double simulation_fps() const { return sim_seconds_ > 0 ? sim_frames_ / sim_seconds_ : 0; }
  /// The untangling so far: "intersecting pairs N (C contours)", where it started and when it
  /// reached 0; "not measured" when the response or the untangling is off.
  std::string untangle_text() const;
  /// Intersecting triangle pairs of the current frame (-1: not measured).
  std::int64_t intersecting_pairs() const { return stats_.intersecting_pairs; }
  /// The frame where the count first reached 0 after being above it (-1: not yet).
  std::int64_t clean_frame() const { return clean_frame_; }

  const sim::Settings& settings() const { return settings_; }
  const sim::FrameStats& stats() const { return stats_; }
  const std::string& source() const { return source_; }
  bool simulating() const { return live_.has_value(); }
  LiveSimulation* live() { return live_ ? &*live_ : nullptr; }

  const Topology& topology() const;
  PositionsView positions() const;
  /// The contacts at the current positions (the simulation detects them on demand).
  const ContactSet& contacts();
  /// The detector whose contacts are shown (the simulation's or the playback's).
  const Detector* detector() const;

  // Drawing.
  void draw(GlDraw& gl, int width, int height);
  void fit(double aspect) { camera.fit(compute_bounds(positions()), aspect); }

  // Tools.
  /// Recall of the current contacts against `naive` on the current positions (`recall_text`).
  void compute_recall();
  const std::string& recall_text() const { return recall_; }
  /// Saves the state as X3D: a MassSpring model when simulating, else the mesh.
  void save_x3d(const std::string& path);
  const std::string& message() const { return message_; }
  void set_message(std::string m) { message_ = std::move(m); }

  render::Camera camera;
  render::DrawOptions draw_options;
  render::Lighting lighting;
  bool paused = false;
  bool step_request = false;
  bool show_active_pairs = false;
  int kdop_level = -1;  ///< level of the k-DOP hierarchy drawn, -1 = none
  float speed = 1;      ///< frames advanced per redraw

 private:
  void show_frame(std::size_t i);
  /// The settings the simulation runs with now (the response off while delayed).
  sim::Settings effective_settings() const;
  /// Records the untangling's progress from `stats_`.
  void track_untangling();
  /// The boxes of one level of the kdop detector's hierarchy, as refitted by its last update.
  void kdop_boxes(Batch& batch) const;
  /// The stochastic detector's near (active) pairs after its last update.
  void active_pairs(Batch& batch) const;

  std::string source_;
  sim::Settings settings_;
  sim::FrameStats stats_;
  std::optional<LiveSimulation> live_;
  std::optional<Playback> playback_;
  std::string recall_, message_;
  std::int64_t response_from_ = -1;
  std::int64_t tangled_pairs_ = -1;   ///< the first count above 0 since the reset
  std::int64_t tangled_frame_ = -1;   ///< its frame
  std::int64_t clean_frame_ = -1;
  double sim_seconds_ = 0;
  double sim_frames_ = 0;
};

}  // namespace crumple::viewer

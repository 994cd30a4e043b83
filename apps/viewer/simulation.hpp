#pragma once
// The live simulation crumple-view runs: a scene, its sim::Simulation, rebuilt around the
// current state when the settings change, and the mouse grab that drags a vertex.

#include <crumple/render/camera.hpp>
#include <crumple/sim/scene.hpp>
#include <crumple/sim/simulation.hpp>

#include <optional>

namespace crumple::viewer {

class LiveSimulation {
 public:
  explicit LiveSimulation(sim::Scene scene) : scene_(std::move(scene)) {}

  /// Back to the scene's initial state with `settings`; returns the figures of that state.
  sim::FrameStats reset(const sim::Settings& settings);
  /// Applies `settings`, keeping the current state and frame number.
  sim::FrameStats apply(const sim::Settings& settings);
  sim::FrameStats advance() { return sim_->advance_frame(); }

  sim::Simulation& simulation() { return *sim_; }
  const sim::Simulation& simulation() const { return *sim_; }

  /// Grabs the vertex under the pixel (x, y) of a `width` × `height` view; false when none.
  bool grab(const render::Camera& camera, double x, double y, int width, int height);
  /// Moves the grab's target to the pixel (x, y), at the grabbed vertex's depth.
  void drag(const render::Camera& camera, double x, double y, int width, int height);
  void release();
  Index grabbed() const { return grabbed_; }

  float drag_stiffness = 20;  ///< N/m
  float drag_damping = 0.5f;

 private:
  sim::Scene scene_;
  std::optional<sim::Simulation> sim_;
  Index grabbed_ = -1;
  double grab_depth_ = 1;
};

}  // namespace crumple::viewer

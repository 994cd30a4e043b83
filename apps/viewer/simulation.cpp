#include "simulation.hpp"

#include <utility>
#include <vector>

namespace crumple::viewer {

sim::FrameStats LiveSimulation::reset(const sim::Settings& settings) {
  grabbed_ = -1;
  sim_.reset();
  sim_.emplace(scene_.model, scene_.state, scene_.field, scene_.obstacles, scene_.kinematics, settings);
  return sim_->current_stats();
}

sim::FrameStats LiveSimulation::apply(const sim::Settings& settings) {
  sim::Model model = sim_->model();
  sim::State state = sim_->state();
  sim::ForceField field = sim_->field();
  std::vector<response::Obstacle> obstacles = sim_->obstacles();
  const std::int64_t frame = sim_->frame();
  sim_.reset();
  sim_.emplace(std::move(model), std::move(state), field, std::move(obstacles), scene_.kinematics, settings,
               frame);
  return sim_->current_stats();
}

bool LiveSimulation::grab(const render::Camera& camera, double x, double y, int width, int height) {
  const PositionsView positions(sim_->state().x);
  grabbed_ = render::pick_vertex(camera, positions, x, y, width, height);
  if (grabbed_ < 0) return false;
  const auto s = camera.project(positions[static_cast<std::size_t>(grabbed_)], width, height);
  grab_depth_ = s ? s->depth : camera.distance;
  drag(camera, x, y, width, height);
  return true;
}

void LiveSimulation::drag(const render::Camera& camera, double x, double y, int width, int height) {
  if (grabbed_ < 0) return;
  sim::DragForce force;
  force.vertex = grabbed_;
  force.target = camera.unproject(x, y, grab_depth_, width, height);
  force.stiffness = drag_stiffness;
  force.damping = drag_damping;
  sim_->field().drag = force;
}

void LiveSimulation::release() {
  grabbed_ = -1;
  sim_->field().drag.reset();
}

}  // namespace crumple::viewer

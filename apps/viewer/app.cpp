#include "app.hpp"

#include "../cli/sim_glue.hpp"

#include <crumple/core/error.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/stochastic.hpp>
#include <crumple/io/x3d.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <vector>

namespace crumple::viewer {

App::App(Loaded loaded) : source_(std::move(loaded.source)), settings_(std::move(loaded.settings)) {
  if (loaded.frames) {
    playback_.emplace(std::move(*loaded.frames));
  } else {
    live_.emplace(std::move(*loaded.scene));
  }
  reset();
}

void App::reset() {
  recall_.clear();
  tangled_pairs_ = tangled_frame_ = clean_frame_ = -1;
  sim_seconds_ = sim_frames_ = 0;
  if (playback_) {
    show_frame(0);
  } else {
    stats_ = live_->reset(effective_settings());
    track_untangling();
  }
}

void App::apply_settings(const sim::Settings& settings) {
  settings_ = settings;
  recall_.clear();
  if (playback_) {
    show_frame(playback_->index());
  } else {
    stats_ = live_->apply(effective_settings());
    track_untangling();
  }
}

void App::advance() {
  recall_.clear();
  if (playback_) {
    show_frame((playback_->index() + 1) % playback_->size());
    return;
  }
  const auto start = std::chrono::steady_clock::now();
  if (response_from_ >= 0 && live_->simulation().frame() == response_from_ &&
      live_->simulation().settings().response != settings_.response) {
    stats_ = live_->apply(settings_);  // the delayed response starts here: the tangle measured
    track_untangling();
  }
  stats_ = live_->advance();
  sim_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  sim_frames_ += 1;
  track_untangling();
}

void App::set_response_from(std::int64_t frame) {
  response_from_ = frame;
  if (live_) {
    stats_ = live_->apply(effective_settings());
    track_untangling();
  }
}

bool App::response_delayed() const {
  return live_ && response_from_ >= 0 && live_->simulation().frame() < response_from_;
}

sim::Settings App::effective_settings() const {
  sim::Settings s = settings_;
  if (response_delayed()) s.response = false;
  return s;
}

void App::track_untangling() {
  // Pinch pairs (sharing one vertex) count too: 0 is intersection-free.
  const std::int64_t n = stats_.intersecting_pairs + std::max<std::int64_t>(stats_.pinches, 0);
  if (n > 0 && tangled_pairs_ < 0) {
    tangled_pairs_ = n;
    tangled_frame_ = stats_.frame;
  }
  if (n == 0 && tangled_pairs_ > 0 && clean_frame_ < 0) clean_frame_ = stats_.frame;
  if (n > 0) clean_frame_ = -1;
}

std::string App::untangle_text() const {
  if (playback_) return "intersecting pairs: frames only (simulate to untangle)";
  if (response_delayed()) {
    return "intersecting pairs: response off until frame " + std::to_string(response_from_);
  }
  if (stats_.intersecting_pairs < 0) return "intersecting pairs: not measured (response or untangle off)";
  std::string text = "intersecting pairs: " + std::to_string(stats_.intersecting_pairs);
  if (stats_.pinches > 0) text += " + " + std::to_string(stats_.pinches) + " pinches";
  if (stats_.intersecting_pairs + stats_.pinches > 0) text += " (" + std::to_string(stats_.contours) + " contours)";
  if (tangled_pairs_ > 0) {
    text += ", " + std::to_string(tangled_pairs_) + " at frame " + std::to_string(tangled_frame_);
    if (clean_frame_ >= 0) text += ", 0 from frame " + std::to_string(clean_frame_);
  }
  return text;
}

void App::show_frame(std::size_t i) {
  stats_ = playback_->show(i, settings_);
  recall_.clear();
}

const Topology& App::topology() const {
  return playback_ ? playback_->topology() : live_->simulation().model().topology();
}

PositionsView App::positions() const {
  return playback_ ? playback_->positions() : PositionsView(live_->simulation().state().x);
}

const ContactSet& App::contacts() {
  return playback_ ? playback_->contacts() : live_->simulation().contacts();
}

const Detector* App::detector() const {
  return playback_ ? playback_->detector() : &live_->simulation().detector();
}

void App::draw(GlDraw& gl, int width, int height) {
  gl.begin(camera, width, height, draw_options.palette);
  const Topology& topo = topology();
  const PositionsView x = positions();
  const render::Palette& pal = draw_options.palette;
  const auto point = [&](Index v) { return x[static_cast<std::size_t>(v)]; };
  if (live_) {  // the rigid obstacles, in one grey, where they are at the simulation's time
    const sim::Simulation& s = live_->simulation();
    render::Palette grey = pal;
    grey.front = grey.back = pal.obstacle;
    for (const render::ShapeMesh& m : render::obstacle_meshes(s.obstacles(), s.state().time, x)) {
      gl.surface(m.faces, m.positions, grey, lighting);
    }
  }
  Batch thin, thick;
  if (draw_options.masses_springs) {
    if (live_) {
      const sim::Model& model = live_->simulation().model();
      for (const sim::Spring& s : model.springs()) thin.line(point(s.a), point(s.b), pal.spring);
      for (Index i = 0; i < model.num_particles(); ++i) thin.point(point(i), model.pinned(i) ? pal.pinned : pal.mass);
    } else {
      for (const Edge& e : topo.edges()) thin.line(point(e[0]), point(e[1]), pal.spring);
      for (const Vec3& p : x) thin.point(p, pal.mass);
    }
  } else {
    if (draw_options.surface) gl.surface(topo.faces(), x, pal, lighting);
    if (draw_options.wireframe || !draw_options.surface) {
      for (const Edge& e : topo.edges()) thin.line(point(e[0]), point(e[1]), pal.edge);
    }
  }
  const ContactSet& c = contacts();
  if (draw_options.colliding_edges) {
    const std::vector<bool> hit = render::colliding_edges(topo, c);
    for (Index e = 0; e < topo.num_edges(); ++e) {
      if (hit[static_cast<std::size_t>(e)]) thick.line(point(topo.edge(e)[0]), point(topo.edge(e)[1]), pal.colliding);
    }
  }
  if (draw_options.contact_segments) {
    for (const render::Segment& s : render::contact_segments(topo, x, c)) thin.line(s.a, s.b, pal.contact);
  }
  if (show_active_pairs) active_pairs(thin);
  if (kdop_level >= 0) kdop_boxes(thin);
  if (live_ && live_->grabbed() >= 0 && live_->simulation().field().drag) {
    const Vec3& target = live_->simulation().field().drag->target;
    thin.line(point(live_->grabbed()), target, render::Rgb{255, 140, 0});
    thin.point(target, render::Rgb{255, 140, 0});
  }
  gl.batch(thin, 1.0f, 5.0f);
  gl.batch(thick, 2.5f, 5.0f);
}

void App::kdop_boxes(Batch& batch) const {
  const BoundingHierarchy* kdop = detector() != nullptr ? detector()->hierarchy() : nullptr;
  if (kdop == nullptr) return;
  const render::Rgb colour{60, 170, 90};
  for (const Bounds& b : kdop->node_boxes(kdop_level)) {
    const auto corner = [&](int i) {
      return Vec3(i & 1 ? b.max.x() : b.min.x(), i & 2 ? b.max.y() : b.min.y(), i & 4 ? b.max.z() : b.min.z());
    };
    for (int i = 0; i < 8; ++i) {
      for (int bit : {1, 2, 4}) {
        if (!(i & bit)) batch.line(corner(i), corner(i | bit), colour);
      }
    }
  }
}

void App::active_pairs(Batch& batch) const {
  const auto* stochastic = dynamic_cast<const StochasticDetector*>(detector());
  if (stochastic == nullptr) return;
  const Topology& topo = topology();
  const PositionsView x = positions();
  const auto vertex = [&](Index v) { return x[static_cast<std::size_t>(v)]; };
  const auto edge = [&](Index e) { return 0.5 * (vertex(topo.edge(e)[0]) + vertex(topo.edge(e)[1])); };
  const auto face = [&](Index f) {
    const Face& t = topo.face(f);
    return (vertex(t[0]) + vertex(t[1]) + vertex(t[2])) / 3.0;
  };
  const render::Rgb colour{230, 140, 0};
  for (const PairType type : {PairType::VV, PairType::EE, PairType::VF, PairType::EF}) {
    if (!stochastic->runs(type)) continue;
    for (const PrimitivePair& p : stochastic->near_pairs(type)) {
      switch (type) {
        case PairType::VV: batch.line(vertex(p.a), vertex(p.b), colour); break;
        case PairType::EE: batch.line(edge(p.a), edge(p.b), colour); break;
        case PairType::VF: batch.line(vertex(p.a), face(p.b), colour); break;
        case PairType::EF: batch.line(edge(p.a), face(p.b), colour); break;
      }
    }
  }
}

void App::compute_recall() {
  auto naive = make_detector(MethodSpec(Method::Naive), settings_.detector);
  naive->set_topology(playback_ ? playback_->frames().first().topology_ptr()
                                : live_->simulation().model().topology_ptr());
  ContactSet reference;
  naive->update(positions(), reference);
  const ContactMatch m = match_contacts(contacts(), reference);
  char buf[160];
  std::snprintf(buf, sizeof buf, "recall %.3f (%zu of %zu, %zu false)", m.recall(), m.found, m.reference,
                m.false_contacts);
  recall_ = buf;
}

void App::save_x3d(const std::string& path) {
  try {
    if (live_) {
      io::write_mass_spring(path, cli::to_mass_spring(live_->simulation().model(), live_->simulation().state()));
    } else {
      io::write_x3d(path, positions(), topology().faces());
    }
    message_ = "saved " + path;
  } catch (const Error& e) {
    message_ = e.what();
  }
}

}  // namespace crumple::viewer

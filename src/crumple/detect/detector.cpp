#include <crumple/core/error.hpp>
#include <crumple/detect/budget_spec_detail.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/scale_detail.hpp>

#include <algorithm>
#include <cmath>

namespace crumple {

void DetectorStats::set(std::string_view key, double value) {
  for (auto& [k, v] : items_) {
    if (k == key) {
      v = value;
      return;
    }
  }
  items_.emplace_back(std::string(key), value);
}

void DetectorStats::add(std::string_view key, double value) {
  for (auto& [k, v] : items_) {
    if (k == key) {
      v += value;
      return;
    }
  }
  items_.emplace_back(std::string(key), value);
}

double DetectorStats::get(std::string_view key) const {
  for (const auto& [k, v] : items_) {
    if (k == key) return v;
  }
  return 0;
}

Detector::Detector(DetectorOptions options) : options_(options), thickness_(options.thickness) {
  if (!(std::isfinite(options_.thickness) && options_.thickness >= 0)) {
    throw InputError("thickness must be a finite number >= 0, got " +
                     std::to_string(options_.thickness));
  }
  if (options_.threads < 0) {
    throw InputError("threads must be >= 0 (0 = all), got " + std::to_string(options_.threads));
  }
}

void Detector::set_topology(std::shared_ptr<const Topology> topology) {
  CRUMPLE_CHECK(topology != nullptr, "set_topology: null topology");
  topology_ = std::move(topology);
  stats_.clear();
  framed_ = false;
  on_topology();
}

const Topology& Detector::topology() const {
  CRUMPLE_CHECK(topology_ != nullptr, "detector used before set_topology");
  return *topology_;
}

void Detector::update(PositionsView positions, ContactSet& out) { update({}, positions, out); }

void Detector::update(PositionsView previous, PositionsView positions, ContactSet& out) {
  start_deadline();
  run_update(previous, positions, out);
}

void Detector::start_deadline() {
  const double budget_ms = frame_budget(spec_budget_ms());
  deadline_ = FrameDeadline(budget_ms, budget_clock());
}

void Detector::run_update(PositionsView previous, PositionsView positions, ContactSet& out) {
  const Topology& topo = topology();
  CRUMPLE_CHECK(positions.size() == static_cast<std::size_t>(topo.num_vertices()),
                "update: positions has " + std::to_string(positions.size()) +
                    " entries, the topology " + std::to_string(topo.num_vertices()) + " vertices");
  CRUMPLE_CHECK(previous.empty() || previous.size() == positions.size(),
                "update: previous positions count differs from current");
  stats_.clear();
  try {
    // One power of two for both frames, from the larger magnitude (detect/scale_detail.hpp);
    // the previous frame only for methods that use it (the others are given none).
    if (!capabilities().uses_motion) previous = {};
    const int threads = options_.threads;
    const Scalar magnitude = std::max(detail::finite_magnitude(positions, threads),
                                      previous.empty() ? Scalar(0) : detail::finite_magnitude(previous, threads));
    const int k = detail::detection_exponent(magnitude);
    if (framed_ && k != exponent_) on_rescale();
    framed_ = true;
    exponent_ = k;
    thickness_ = detail::scaled_thickness(options_.thickness, k);
    if (k == 0) {
      detect(previous, positions, out);
    } else {
      detail::scale_positions(positions, k, scaled_, threads, "positions");
      if (!previous.empty()) detail::scale_positions(previous, k, scaled_previous_, threads, "previous positions");
      detect(previous.empty() ? PositionsView() : PositionsView(scaled_previous_), scaled_, out);
      detail::scale_distances(out, -k);
    }
  } catch (...) {
    out.clear();
    throw;
  }
  if (!sorted_output()) out.sort();
}

void Detector::update(const VertexView& positions, ContactSet& out) { update(VertexView(), positions, out); }

void Detector::update(const VertexView& previous, const VertexView& positions, ContactSet& out) {
  start_deadline();
  const auto doubles = [](const VertexView& view, Positions& buffer) {
    if (view.is_native()) return view.native();
    view.convert(buffer);
    return PositionsView(buffer);
  };
  const PositionsView x = doubles(positions, converted_);
  const PositionsView x0 = capabilities().uses_motion ? doubles(previous, converted_previous_) : PositionsView();
  run_update(x0, x, out);
}

void Detector::set_budget(double ms) {
  const std::string name(to_string(method()));
  const auto params = method_info(method()).params;
  if (std::none_of(params.begin(), params.end(), [](const ParamInfo& p) { return p.key == "budget"; })) {
    throw InputError("method " + name + " has no time budget (set_budget)");
  }
  check_budget_ms(ms, name);
  check_budget(ms);
  budget_ms_ = ms;
  budget_set_ = true;
}

void Detector::load_state(std::string_view text) {
  if (text.find_first_not_of(" \t\r\n") == std::string_view::npos) return;
  throw InputError("method " + std::string(to_string(method())) +
                   " keeps no state across frames: cannot restore a saved detector state");
}

}  // namespace crumple

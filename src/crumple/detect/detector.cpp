#include <crumple/core/error.hpp>
#include <crumple/detect/detector.hpp>

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

Detector::Detector(DetectorOptions options) : options_(options) {
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
  on_topology();
}

const Topology& Detector::topology() const {
  CRUMPLE_CHECK(topology_ != nullptr, "detector used before set_topology");
  return *topology_;
}

void Detector::update(PositionsView positions, ContactSet& out) { update({}, positions, out); }

void Detector::update(PositionsView previous, PositionsView positions, ContactSet& out) {
  const Topology& topo = topology();
  CRUMPLE_CHECK(positions.size() == static_cast<std::size_t>(topo.num_vertices()),
                "update: positions has " + std::to_string(positions.size()) +
                    " entries, the topology " + std::to_string(topo.num_vertices()) + " vertices");
  CRUMPLE_CHECK(previous.empty() || previous.size() == positions.size(),
                "update: previous positions count differs from current");
  stats_.clear();
  try {
    detect(previous, positions, out);
  } catch (...) {
    out.clear();
    throw;
  }
  if (!sorted_output()) out.sort();
}

void Detector::update(const VertexView& positions, ContactSet& out) { update(VertexView(), positions, out); }

void Detector::update(const VertexView& previous, const VertexView& positions, ContactSet& out) {
  const auto doubles = [](const VertexView& view, Positions& buffer) {
    if (view.is_native()) return view.native();
    view.convert(buffer);
    return PositionsView(buffer);
  };
  const PositionsView x = doubles(positions, converted_);
  const PositionsView x0 = capabilities().uses_motion ? doubles(previous, converted_previous_) : PositionsView();
  update(x0, x, out);
}

void Detector::load_state(std::string_view text) {
  if (text.find_first_not_of(" \t\r\n") == std::string_view::npos) return;
  throw InputError("method " + std::string(to_string(method())) +
                   " keeps no state across frames: cannot restore a saved detector state");
}

}  // namespace crumple

#pragma once
// The intersecting triangle pairs of a state, as the tests of the fail-safe and the untangler
// count them.

#include <crumple/detect/detector.hpp>
#include <crumple/detect/method.hpp>

#include <memory>
#include <utility>
#include <vector>

namespace crumple::testing {

/// Intersecting triangle pairs (faces sharing no vertex) at `x`, by the exact kdop detector.
inline std::vector<TriangleTriangleContact> intersecting_triangles(std::shared_ptr<const Topology> topology,
                                                                   PositionsView x) {
  DetectorOptions options;
  options.kinds = ContactKinds::parse("tt");
  options.threads = 1;
  auto detector = make_detector(MethodSpec::parse("kdop"), options);
  detector->set_topology(std::move(topology));
  ContactSet contacts;
  detector->update(x, contacts);
  return std::move(contacts.tt);
}

}  // namespace crumple::testing

#pragma once
/// \file
/// A read-only view of a detector's bounding-volume hierarchy (`Detector::hierarchy`), for
/// drawing and inspecting it without knowing the concrete detector.

#include <crumple/core/types.hpp>
#include <crumple/mesh/mesh.hpp>

#include <vector>

namespace crumple {

class BoundingHierarchy {
 public:
  virtual ~BoundingHierarchy() = default;
  /// Number of levels of the current tree (0 before the first update).
  virtual int levels() const = 0;
  /// The axis-aligned boxes of the nodes at `depth` (0 = root) after the last update, as
  /// refitted (inflated, and swept where the method sweeps); empty past the deepest level or
  /// for a negative depth.
  virtual std::vector<Bounds> node_boxes(int depth) const = 0;
  /// The faces of each leaf of the current tree (empty before the first update).
  virtual std::vector<std::vector<Index>> leaf_faces() const = 0;
};

}  // namespace crumple

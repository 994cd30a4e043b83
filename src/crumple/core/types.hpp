#pragma once
/// \file
/// Basic numeric types shared by every crumple subsystem.

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace crumple {

/// The one scalar type of the library (STYLE.md §14).
using Scalar = double;
/// A 3D point or vector.
using Vec3 = Eigen::Matrix<Scalar, 3, 1>;
/// Index of a vertex, edge or face. 32 bits: meshes up to 2^31 elements.
using Index = std::int32_t;
/// A triangle as three vertex ids, in the file's winding order.
using Face = std::array<Index, 3>;
/// An edge as two vertex ids; unique mesh edges always have `v[0] < v[1]`.
using Edge = std::array<Index, 2>;
/// Positions of all vertices, `#V` entries.
using Positions = std::vector<Vec3>;
/// Read-only view over positions (`#V` entries).
using PositionsView = std::span<const Vec3>;

}  // namespace crumple

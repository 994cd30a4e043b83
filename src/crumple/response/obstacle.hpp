#pragma once
/// \file
/// Rigid obstacles (spheres, boxes, planes) and the response of cloth vertices against them
/// (docs/simulation.md). Obstacles are kinematic: they move with a prescribed linear velocity
/// (up to a stop time) and are not pushed back by the cloth.
///
/// Per vertex with signed distance φ(x) to the obstacle's surface and outward unit normal n:
/// when φ < margin, the vertex is projected out, x += (margin − φ) n; its velocity relative to
/// the obstacle, v_r = v − v_obs, loses its approaching normal part (v_r·n < 0 → 0, inelastic)
/// and its tangential part is reduced by Coulomb friction, |v_t| ← max(0, |v_t| − μ |v_r·n|).
/// Pinned vertices (m⁻¹ = 0) are never moved.

#include <crumple/core/types.hpp>

#include <limits>
#include <span>
#include <variant>

namespace crumple::response {

struct Sphere {
  Vec3 center = Vec3::Zero();
  Scalar radius = 1;
};

/// Box with centre, half extents along its own axes and an orientation (columns = axes).
struct Box {
  Vec3 center = Vec3::Zero();
  Vec3 half_extents = Vec3::Ones();
  Eigen::Matrix<Scalar, 3, 3> rotation = Eigen::Matrix<Scalar, 3, 3>::Identity();
};

/// Half-space {x : (x − point)·normal >= 0} is free; the obstacle is the other side (a floor).
struct Plane {
  Vec3 point = Vec3::Zero();
  Vec3 normal = Vec3::UnitY();  ///< unit
};

using Shape = std::variant<Sphere, Box, Plane>;

/// Signed distance (negative inside) and outward unit normal at the closest surface point.
struct SurfaceQuery {
  Scalar distance = 0;
  Vec3 normal = Vec3::UnitY();
};
SurfaceQuery query(const Sphere& sphere, const Vec3& p);
SurfaceQuery query(const Box& box, const Vec3& p);
SurfaceQuery query(const Plane& plane, const Vec3& p);
SurfaceQuery query(const Shape& shape, const Vec3& p);

/// A kinematic obstacle: `shape` is its pose at time 0; at time t it is translated by
/// velocity · min(t, stop_time).
struct Obstacle {
  Shape shape;
  Vec3 velocity = Vec3::Zero();  ///< m/s, until stop_time
  Scalar stop_time = std::numeric_limits<Scalar>::infinity();
  Scalar friction = 0;  ///< Coulomb coefficient μ >= 0
  Scalar margin = 0;    ///< vertices are kept at signed distance >= margin (m)

  /// The shape at time t.
  Shape at_time(Scalar t) const;
  /// Velocity at time t.
  Vec3 velocity_at(Scalar t) const { return t < stop_time ? velocity : Vec3::Zero(); }
};

/// Projects every unpinned vertex out of the obstacle at time t and corrects its velocity
/// (see the file comment). Returns the number of vertices corrected.
std::size_t resolve_obstacle(const Obstacle& obstacle, Scalar t, std::span<const Scalar> inv_mass,
                             std::span<Vec3> positions, std::span<Vec3> velocities);

/// `resolve_obstacle` for each obstacle in turn, vertex by vertex: a vertex's response reads and
/// writes only its own position and velocity, so this gives the bits of the obstacles applied one
/// after the other over all vertices, on any number of `threads` (0: all), in one sweep over the
/// vertices. Returns the sum of the obstacles' counts.
std::size_t resolve_obstacles(std::span<const Obstacle> obstacles, Scalar t, std::span<const Scalar> inv_mass,
                              std::span<Vec3> positions, std::span<Vec3> velocities, int threads);

/// Deepest penetration of any vertex into the obstacle at time t: max(0, −min φ) (m), ignoring
/// the margin.
Scalar max_penetration(const Obstacle& obstacle, Scalar t, std::span<const Vec3> positions);

}  // namespace crumple::response

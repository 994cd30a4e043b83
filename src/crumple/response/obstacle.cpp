#include <crumple/core/error.hpp>
#include <crumple/core/parallel.hpp>
#include <crumple/response/obstacle.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <utility>
#include <variant>
#include <vector>

namespace crumple::response {

SurfaceQuery query(const Sphere& sphere, const Vec3& p) {
  const Vec3 d = p - sphere.center;
  const Scalar len = d.norm();
  SurfaceQuery q;
  q.distance = len - sphere.radius;
  q.normal = len > 0 ? Vec3(d / len) : Vec3::UnitY();
  return q;
}

SurfaceQuery query(const Box& box, const Vec3& p) {
  const Vec3 local = box.rotation.transpose() * (p - box.center);
  const Vec3 excess = local.cwiseAbs() - box.half_extents;  // > 0 outside along that axis
  SurfaceQuery q;
  Vec3 n_local;
  if (excess.maxCoeff() > 0) {
    // Outside: distance to the closest point of the box.
    const Vec3 outside = excess.cwiseMax(0);
    q.distance = outside.norm();
    for (int k = 0; k < 3; ++k) n_local[k] = local[k] < 0 ? -outside[k] : outside[k];
    n_local /= q.distance;
  } else {
    // Inside: the nearest face.
    int axis = 0;
    excess.maxCoeff(&axis);
    q.distance = excess[axis];
    n_local = Vec3::Zero();
    n_local[axis] = local[axis] < 0 ? -1 : 1;
  }
  q.normal = box.rotation * n_local;
  return q;
}

SurfaceQuery query(const Plane& plane, const Vec3& p) {
  return {(p - plane.point).dot(plane.normal), plane.normal};
}

SurfaceQuery query(const Shape& shape, const Vec3& p) {
  return std::visit([&](const auto& s) { return query(s, p); }, shape);
}

Shape Obstacle::at_time(Scalar t) const {
  const Vec3 offset = velocity * std::min(t, stop_time);
  Shape s = shape;
  std::visit(
      [&](auto& x) {
        using T = std::decay_t<decltype(x)>;
        if constexpr (std::is_same_v<T, Plane>) {
          x.point += offset;
        } else {
          x.center += offset;
        }
      },
      s);
  return s;
}

namespace {
/// A cheap test that `p` lies farther than `reach` from the shape's surface on its outside, so
/// that `query(shape, p).distance >= reach` as computed (then `resolve_obstacle` and
/// `max_penetration` leave it alone): false whenever in doubt. The relative slack of 1e-9 is
/// far above the few ulps by which `query` rounds. A vertex far from a box or a sphere (most
/// of a cloth, for a wall) then costs a few comparisons instead of a rotation and a root.
struct FarTest {
  Vec3 center = Vec3::Zero();
  Vec3 extent = Vec3::Constant(std::numeric_limits<Scalar>::infinity());  ///< world AABB half sizes
  Scalar radius = -1;  ///< sphere radius (< 0: not a sphere)
  Scalar reach = 0;

  bool far(const Vec3& p) const {
    const Vec3 d = p - center;
    if (radius >= 0) {
      const Scalar r = radius + reach;
      return r >= 0 && d.squaredNorm() > r * r * (1 + 1e-9) + 1e-300;
    }
    // Every point of the box lies within `extent` of the centre along each world axis, so the
    // distance is at least |d_k| − extent_k.
    for (int k = 0; k < 3; ++k) {
      const Scalar gap = std::abs(d[k]) - extent[k] - reach;
      if (gap > 1e-9 * (std::abs(d[k]) + extent[k] + std::abs(reach)) + 1e-300) return true;
    }
    return false;
  }
};

FarTest far_test(const Shape& shape, Scalar reach) {
  FarTest t;
  t.reach = reach;
  if (const auto* box = std::get_if<Box>(&shape)) {
    t.center = box->center;
    t.extent = box->rotation.cwiseAbs() * box->half_extents;
  } else if (const auto* sphere = std::get_if<Sphere>(&shape)) {
    t.center = sphere->center;
    t.radius = sphere->radius;
  }  // a plane: never far (its query is cheaper than any test); a non-finite input: never far
  return t;
}
}  // namespace

namespace {
/// One obstacle at one time: what every vertex's test and push-out reads.
struct Posed {
  Shape shape;
  Vec3 velocity;
  FarTest test;
  Scalar margin, friction;
};

Posed pose(const Obstacle& obstacle, Scalar t) {
  Shape shape = obstacle.at_time(t);
  const FarTest test = far_test(shape, obstacle.margin);
  return {std::move(shape), obstacle.velocity_at(t), test, obstacle.margin, obstacle.friction};
}

/// The response of one vertex to one posed obstacle (the file comment of the header); true when
/// it was corrected. Inlined into the loops over vertices (GCC otherwise calls it per vertex).
template <class S>
[[gnu::always_inline]] inline bool push_out(const Posed& o, const S& typed, Vec3& x, Vec3& v) {
  if (o.test.far(x)) return false;
  const SurfaceQuery q = query(typed, x);
  if (!(q.distance < o.margin)) return false;
  x += (o.margin - q.distance) * q.normal;
  const Vec3 vr = v - o.velocity;
  const Scalar vn = vr.dot(q.normal);
  if (vn < 0) {
    Vec3 vt = vr - vn * q.normal;
    const Scalar vt_len = vt.norm();
    const Scalar reduced = std::max<Scalar>(0, vt_len - o.friction * (-vn));
    vt = vt_len > 0 ? Vec3(vt * (reduced / vt_len)) : Vec3::Zero();
    v = o.velocity + vt;
  }
  return true;
}

/// One posed obstacle's response over the vertices [begin, end); the number corrected. `o` by
/// value: a local copy that the stores to x and v cannot alias stays in registers.
std::size_t push_out(const Posed o, std::span<const Scalar> inv_mass, std::span<Vec3> x, std::span<Vec3> v,
                     std::size_t begin, std::size_t end) {
  return std::visit(
      [&](const auto& typed) {
        std::size_t count = 0;
        for (std::size_t i = begin; i < end; ++i) {
          if (inv_mass[i] != 0 && push_out(o, typed, x[i], v[i])) ++count;
        }
        return count;
      },
      o.shape);
}
}  // namespace

std::size_t resolve_obstacle(const Obstacle& obstacle, Scalar t, std::span<const Scalar> inv_mass,
                             std::span<Vec3> x, std::span<Vec3> v) {
  CRUMPLE_CHECK(x.size() == inv_mass.size() && v.size() == inv_mass.size(),
                "obstacle response arrays must have #V entries");
  return push_out(pose(obstacle, t), inv_mass, x, v, 0, x.size());
}

std::size_t resolve_obstacles(std::span<const Obstacle> obstacles, Scalar t, std::span<const Scalar> inv_mass,
                              std::span<Vec3> x, std::span<Vec3> v, int threads) {
  CRUMPLE_CHECK(x.size() == inv_mass.size() && v.size() == inv_mass.size(),
                "obstacle response arrays must have #V entries");
  if (obstacles.empty()) return 0;
  std::vector<Posed> posed;
  posed.reserve(obstacles.size());
  for (const Obstacle& o : obstacles) posed.push_back(pose(o, t));
  // Chunks of vertices small enough to stay in the cache while every obstacle passes over them.
  constexpr std::size_t kChunk = 1024;
  std::atomic<std::size_t> count{0};
  parallel_for_chunks(x.size(), threads, kChunk, [&](std::size_t begin, std::size_t end) {
    std::size_t corrected = 0;
    for (std::size_t from = begin; from < end; from += kChunk) {
      const std::size_t to = std::min(end, from + kChunk);
      for (const Posed& o : posed) corrected += push_out(o, inv_mass, x, v, from, to);
    }
    count += corrected;
  });
  return count;
}

Scalar max_penetration(const Obstacle& obstacle, Scalar t, std::span<const Vec3> x) {
  const Shape shape = obstacle.at_time(t);
  const FarTest test = far_test(shape, 0);
  Scalar deepest = 0;
  std::visit(
      [&](const auto& typed) {
        for (const Vec3& p : x) {
          if (!test.far(p)) deepest = std::max(deepest, -query(typed, p).distance);
        }
      },
      shape);
  return deepest;
}

}  // namespace crumple::response

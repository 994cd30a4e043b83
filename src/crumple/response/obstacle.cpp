#include <crumple/core/error.hpp>
#include <crumple/response/obstacle.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <variant>

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

std::size_t resolve_obstacle(const Obstacle& obstacle, Scalar t, std::span<const Scalar> inv_mass,
                             std::span<Vec3> x, std::span<Vec3> v) {
  CRUMPLE_CHECK(x.size() == inv_mass.size() && v.size() == inv_mass.size(),
                "obstacle response arrays must have #V entries");
  const Shape shape = obstacle.at_time(t);
  const Vec3 vo = obstacle.velocity_at(t);
  const FarTest test = far_test(shape, obstacle.margin);
  std::size_t count = 0;
  std::visit(
      [&](const auto& typed) {
        for (std::size_t i = 0; i < x.size(); ++i) {
          if (inv_mass[i] == 0 || test.far(x[i])) continue;
          const SurfaceQuery q = query(typed, x[i]);
          if (!(q.distance < obstacle.margin)) continue;
          ++count;
          x[i] += (obstacle.margin - q.distance) * q.normal;
          const Vec3 vr = v[i] - vo;
          const Scalar vn = vr.dot(q.normal);
          if (vn < 0) {
            Vec3 vt = vr - vn * q.normal;
            const Scalar vt_len = vt.norm();
            const Scalar reduced = std::max<Scalar>(0, vt_len - obstacle.friction * (-vn));
            vt = vt_len > 0 ? Vec3(vt * (reduced / vt_len)) : Vec3::Zero();
            v[i] = vo + vt;
          }
        }
      },
      shape);
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

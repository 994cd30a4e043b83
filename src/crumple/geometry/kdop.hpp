#pragma once
/// \file
/// Discrete oriented polytopes (k-DOPs) with fixed, normalised directions.
///
/// A k-DOP stores, for K/2 fixed unit directions a_j, the slab [min_j, max_j] of a_j . x over
/// the bounded set (Klosowski, Held, Mitchell, Sowizral, Zikan, "Efficient collision detection
/// using bounding volume hierarchies of k-DOPs", IEEE TVCG 4(1), 1998; used for cloth by
/// Mezger, Kimmerle & Etzmuss 2003). Two k-DOPs are disjoint if one slab pair is separated.
///
/// Directions (ALGORITHMS.md §2), in this order:
///   j = 0..2   coordinate axes x, y, z                          (all K)
///   then, K = 14 and 26: cube diagonals (1,1,1), (1,1,-1), (1,-1,1), (1,-1,-1) / sqrt(3)
///   then, K = 18 and 26: edge diagonals (1,1,0), (1,-1,0), (1,0,1), (1,0,-1), (0,1,1),
///                        (0,1,-1) / sqrt(2)
/// Unlike Blender's kdop.c (R16) the table is stored per K, so the 18-DOP really is the 3
/// axes plus the 6 edge diagonals (Blender's KDOP_18 macro picked a non-contiguous range),
/// and the directions are unit vectors, so growing every slab by d is exactly the Minkowski
/// sum with a ball of radius d (Blender grew unnormalised projections by d, i.e. only by
/// d/sqrt(2) or d/sqrt(3) in distance).
///
/// Rounding: projections are evaluated in double (x + y) * (1/sqrt 2) etc., so membership
/// tests are exact up to ~1 ulp of the coordinates; `contains` and `overlaps` use the same
/// projection code as `extend`, so a point that was added is always contained.

#include <crumple/core/types.hpp>

#include <algorithm>
#include <array>
#include <limits>
#include <span>

namespace crumple::geometry {

template <int K>
class Kdop {
  static_assert(K == 6 || K == 14 || K == 18 || K == 26, "Kdop: K must be 6, 14, 18 or 26");

 public:
  /// Number of directions (slabs).
  static constexpr int kAxes = K / 2;
  using Slabs = std::array<Scalar, kAxes>;

  /// The unit directions a_j, `kAxes` rows of (x, y, z).
  static constexpr std::array<std::array<Scalar, 3>, kAxes> kAxisTable = [] {
    constexpr Scalar r3 = 0.57735026918962576451;  // 1/sqrt(3)
    constexpr Scalar r2 = 0.70710678118654752440;  // 1/sqrt(2)
    std::array<std::array<Scalar, 3>, kAxes> t{};
    int j = 0;
    t[j++] = {1, 0, 0};
    t[j++] = {0, 1, 0};
    t[j++] = {0, 0, 1};
    if constexpr (K == 14 || K == 26) {
      t[j++] = {r3, r3, r3};
      t[j++] = {r3, r3, -r3};
      t[j++] = {r3, -r3, r3};
      t[j++] = {r3, -r3, -r3};
    }
    if constexpr (K == 18 || K == 26) {
      t[j++] = {r2, r2, 0};
      t[j++] = {r2, -r2, 0};
      t[j++] = {r2, 0, r2};
      t[j++] = {r2, 0, -r2};
      t[j++] = {0, r2, r2};
      t[j++] = {0, r2, -r2};
    }
    return t;
  }();

  /// Direction a_j as a vector.
  static Vec3 axis(int j) { return Vec3(kAxisTable[j][0], kAxisTable[j][1], kAxisTable[j][2]); }

  /// Projections a_j . p for all j (the same arithmetic as every member function).
  static Slabs project(const Vec3& p) {
    constexpr Scalar r3 = 0.57735026918962576451;
    constexpr Scalar r2 = 0.70710678118654752440;
    const Scalar x = p.x(), y = p.y(), z = p.z();
    Slabs out;
    int j = 0;
    out[j++] = x;
    out[j++] = y;
    out[j++] = z;
    if constexpr (K == 14 || K == 26) {
      out[j++] = (x + y + z) * r3;
      out[j++] = (x + y - z) * r3;
      out[j++] = (x - y + z) * r3;
      out[j++] = (x - y - z) * r3;
    }
    if constexpr (K == 18 || K == 26) {
      out[j++] = (x + y) * r2;
      out[j++] = (x - y) * r2;
      out[j++] = (x + z) * r2;
      out[j++] = (x - z) * r2;
      out[j++] = (y + z) * r2;
      out[j++] = (y - z) * r2;
    }
    return out;
  }

  /// The empty k-DOP: min_j = +inf, max_j = -inf. It overlaps and contains nothing, and is
  /// the identity of `merge`.
  Kdop() {
    min_.fill(std::numeric_limits<Scalar>::infinity());
    max_.fill(-std::numeric_limits<Scalar>::infinity());
  }

  /// Smallest k-DOP holding all points (empty for an empty span).
  static Kdop from_points(std::span<const Vec3> points) {
    Kdop k;
    for (const Vec3& p : points) k.extend(p);
    return k;
  }

  /// Smallest k-DOP holding the triangle (a,b,c) (a convex hull: its corners suffice).
  static Kdop from_triangle(const Vec3& a, const Vec3& b, const Vec3& c) {
    const Slabs pa = project(a), pb = project(b), pc = project(c);
    Kdop k;
    for (int j = 0; j < kAxes; ++j) {
      k.min_[j] = std::min(pa[j], std::min(pb[j], pc[j]));
      k.max_[j] = std::max(pa[j], std::max(pb[j], pc[j]));
    }
    return k;
  }

  Scalar min(int j) const { return min_[j]; }
  Scalar max(int j) const { return max_[j]; }
  const Slabs& mins() const { return min_; }
  const Slabs& maxs() const { return max_; }

  /// True when nothing was added (min_0 > max_0).
  bool empty() const { return min_[0] > max_[0]; }

  /// Grows the slabs to hold point p.
  void extend(const Vec3& p) {
    const Slabs q = project(p);
    for (int j = 0; j < kAxes; ++j) {
      min_[j] = std::min(min_[j], q[j]);
      max_[j] = std::max(max_[j], q[j]);
    }
  }

  /// Union (smallest k-DOP holding both).
  void merge(const Kdop& o) {
    for (int j = 0; j < kAxes; ++j) {
      min_[j] = std::min(min_[j], o.min_[j]);
      max_[j] = std::max(max_[j], o.max_[j]);
    }
  }

  /// Minkowski sum with the ball of radius d >= 0: every slab grows by exactly d on each
  /// side (the directions are unit vectors). An empty k-DOP stays empty.
  void inflate(Scalar d) {
    for (int j = 0; j < kAxes; ++j) {
      min_[j] -= d;
      max_[j] += d;
    }
  }

  /// Minkowski sum with the segment [0, displacement] ("oriented inflation along the
  /// motion"): with p_j = a_j . displacement, max_j += p_j if p_j > 0, else min_j += p_j.
  /// A point moving linearly from x to x + displacement has a_j . x(t) linear in t, so the
  /// swept k-DOP bounds the whole trajectory; tighter than inflating by |displacement|.
  void sweep(const Vec3& displacement) {
    const Slabs q = project(displacement);
    for (int j = 0; j < kAxes; ++j) {
      if (q[j] > 0) {
        max_[j] += q[j];
      } else {
        min_[j] += q[j];
      }
    }
  }

  /// True when every slab pair intersects (closed: touching slabs overlap). Conservative:
  /// may report overlap for disjoint sets, never the reverse. False if either is empty.
  /// Branch-free over the slabs (vectorisable).
  bool overlaps(const Kdop& o) const {
    bool ok = true;
    for (int j = 0; j < kAxes; ++j) ok &= (min_[j] <= o.max_[j]) & (o.min_[j] <= max_[j]);
    return ok;
  }

  /// True when min_j <= a_j . p <= max_j for every j.
  bool contains(const Vec3& p) const {
    const Slabs q = project(p);
    bool ok = true;
    for (int j = 0; j < kAxes; ++j) ok &= (min_[j] <= q[j]) & (q[j] <= max_[j]);
    return ok;
  }

  /// True when every slab of `o` lies inside the matching slab of this one (an empty `o` is
  /// contained in anything).
  bool contains(const Kdop& o) const {
    if (o.empty()) return true;
    bool ok = true;
    for (int j = 0; j < kAxes; ++j) ok &= (min_[j] <= o.min_[j]) & (o.max_[j] <= max_[j]);
    return ok;
  }

 private:
  Slabs min_;
  Slabs max_;
};

}  // namespace crumple::geometry

#pragma once
/// \file
/// Discrete oriented polytopes (k-DOPs) with fixed, normalised directions.
///
/// A k-DOP stores, for K/2 fixed unit directions a_j, the slab [min_j, max_j] of a_j . x over
/// the bounded set (Klosowski, Held, Mitchell, Sowizral, Zikan, "Efficient collision detection
/// using bounding volume hierarchies of k-DOPs", IEEE TVCG 4(1), 1998; used for cloth by
/// Mezger, Kimmerle & Etzmuss 2003). Two k-DOPs are disjoint if one slab pair is separated.
///
/// Directions, in this order:
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
/// Rounding: projections are evaluated in double, (x + y) * (1/sqrt 2) etc., by one formula
/// (`along`) shared by every member, so a point that was added is always `contains`ed and
/// k-DOPs sharing a point always overlap, bit for bit. `inflate` and `sweep` add in double
/// without outward rounding: a point at distance exactly d from a contained point may fall
/// outside `inflate(d)` by ~1 ulp of its coordinates. Where a rigorous broad phase matters
/// at that level, inflate by d plus a few ulps of the scene size.
///
/// Layout: two arrays of K/2 doubles; every member is inline and unrolled at compile time
/// (bench/kernels_bench.cpp times `overlaps` and `from_triangle`).

#include <crumple/core/types.hpp>

#include <array>
#include <limits>
#include <span>
#include <type_traits>
#include <utility>

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

  /// a_J . (x, y, z) for a compile-time axis J, evaluated as (x + y) * (1/sqrt 2) etc. Every
  /// member function projects through this one formula, so results are bitwise consistent
  /// (a point added by `extend` is always `contains`ed).
  template <int J>
  static Scalar along(Scalar x, Scalar y, Scalar z) {
    static_assert(J >= 0 && J < kAxes);
    constexpr Scalar r3 = 0.57735026918962576451;  // 1/sqrt(3)
    constexpr Scalar r2 = 0.70710678118654752440;  // 1/sqrt(2)
    constexpr int kCube = (K == 14 || K == 26) ? 4 : 0;  // cube diagonals follow the axes
    if constexpr (J == 0) return x;
    else if constexpr (J == 1) return y;
    else if constexpr (J == 2) return z;
    else if constexpr (J - 3 < kCube) {
      if constexpr (J == 3) return (x + y + z) * r3;
      else if constexpr (J == 4) return (x + y - z) * r3;
      else if constexpr (J == 5) return (x - y + z) * r3;
      else return (x - y - z) * r3;
    } else {
      constexpr int e = J - 3 - kCube;  // edge diagonals
      if constexpr (e == 0) return (x + y) * r2;
      else if constexpr (e == 1) return (x - y) * r2;
      else if constexpr (e == 2) return (x + z) * r2;
      else if constexpr (e == 3) return (x - z) * r2;
      else if constexpr (e == 4) return (y + z) * r2;
      else return (y - z) * r2;
    }
  }

  /// Calls f(std::integral_constant<int, J>) for J = 0 .. kAxes-1 (unrolled at compile time,
  /// which keeps the projections in registers: with arrays of projections GCC's vectoriser
  /// reloaded pairs of scalar stores as vectors, a store-forwarding stall costing ~10x).
  template <class F>
  static void for_each_axis(F&& f) {
    [&]<int... J>(std::integer_sequence<int, J...>) {
      (f(std::integral_constant<int, J>{}), ...);
    }(std::make_integer_sequence<int, kAxes>{});
  }

  /// Projections a_j . p for all j.
  static Slabs project(const Vec3& p) {
    Slabs out;
    const Scalar x = p.x(), y = p.y(), z = p.z();
    for_each_axis([&](auto j) { out[j] = along<j>(x, y, z); });
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

  /// The k-DOP with these slabs, as given (min_j, max_j along axis j).
  static Kdop from_slabs(const Slabs& mins, const Slabs& maxs) {
    Kdop k{Uninitialized{}};
    k.min_ = mins;
    k.max_ = maxs;
    return k;
  }

  /// Smallest k-DOP holding the triangle (a,b,c) (a convex hull: its corners suffice). The same
  /// slabs as `from_points` of the three, bit for bit: a NaN projection is skipped, as `extend`
  /// skips it (a nested `lo(u, lo(v, w))` would take u alone when v is NaN, leaving out c).
  static Kdop from_triangle(const Vec3& a, const Vec3& b, const Vec3& c) {
    Kdop k{Uninitialized{}};
    constexpr Scalar inf = std::numeric_limits<Scalar>::infinity();
    for_each_axis([&](auto j) {
      const Scalar u = along<j>(a.x(), a.y(), a.z());
      const Scalar v = along<j>(b.x(), b.y(), b.z());
      const Scalar w = along<j>(c.x(), c.y(), c.z());
      k.min_[j] = lo(lo(lo(inf, u), v), w);
      k.max_[j] = hi(hi(hi(-inf, u), v), w);
    });
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
    const Scalar x = p.x(), y = p.y(), z = p.z();
    for_each_axis([&](auto j) {
      const Scalar q = along<j>(x, y, z);
      min_[j] = lo(min_[j], q);
      max_[j] = hi(max_[j], q);
    });
  }

  /// Union (smallest k-DOP holding both).
  void merge(const Kdop& o) {
    for (int j = 0; j < kAxes; ++j) {
      min_[j] = lo(min_[j], o.min_[j]);
      max_[j] = hi(max_[j], o.max_[j]);
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
    const Scalar x = displacement.x(), y = displacement.y(), z = displacement.z();
    for_each_axis([&](auto j) {
      const Scalar q = along<j>(x, y, z);
      // Branch-free: adds q to exactly one side (the other gets +0).
      max_[j] += hi(q, 0);
      min_[j] += lo(q, 0);
    });
  }

  /// True when every slab pair intersects (closed: touching slabs overlap). Conservative:
  /// may report overlap for disjoint sets, never the reverse. False if either is empty.
  /// Early exit on the first separating slab, coordinate axes first: cheaper than a
  /// branch-free loop over all slabs for disjoint and overlapping pairs alike
  /// (bench/kernels_bench.cpp compares the two).
  bool overlaps(const Kdop& o) const {
    for (int j = 0; j < kAxes; ++j) {
      if (min_[j] > o.max_[j] || o.min_[j] > max_[j]) return false;
    }
    return true;
  }

  /// True when min_j <= a_j . p <= max_j for every j.
  bool contains(const Vec3& p) const {
    const Scalar x = p.x(), y = p.y(), z = p.z();
    return [&]<int... J>(std::integer_sequence<int, J...>) {
      const auto inside = [&](auto j) {
        const Scalar q = along<j>(x, y, z);
        return min_[j] <= q && q <= max_[j];
      };
      return (inside(std::integral_constant<int, J>{}) && ...);  // stops at the first miss
    }(std::make_integer_sequence<int, kAxes>{});
  }

  /// True when every slab of `o` lies inside the matching slab of this one (an empty `o` is
  /// contained in anything).
  bool contains(const Kdop& o) const {
    if (o.empty()) return true;
    for (int j = 0; j < kAxes; ++j) {
      if (!(min_[j] <= o.min_[j] && o.max_[j] <= max_[j])) return false;
    }
    return true;
  }

 private:
  // By value (std::min on references compiles to address selects and data-dependent
  // branches here); these become minsd/maxsd.
  static Scalar lo(Scalar x, Scalar y) { return y < x ? y : x; }
  static Scalar hi(Scalar x, Scalar y) { return x < y ? y : x; }

  struct Uninitialized {};
  explicit Kdop(Uninitialized) {}

  Slabs min_;
  Slabs max_;
};

}  // namespace crumple::geometry

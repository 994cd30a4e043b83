#pragma once
/// \file
/// Exact intersection test of two closed triangles in 3D.
///
/// Every decision is the sign of an exact orientation predicate (predicates.hpp), so the
/// answer is the exact answer for the given double coordinates: no tolerance, no false
/// positive or negative from rounding, touching counts as intersecting.
///
/// Method (not Moller's interval test, which needs divisions): two closed convex sets
/// intersect iff a boundary point of one lies in the other, so triangles A and B intersect
/// iff some edge of A meets B or some edge of B meets A.
///  1. Plane rejection: if all corners of B lie strictly on one side of the plane of A (or
///     vice versa), they are disjoint (6 orient3d; the common case).
///  2. Non-coplanar, non-degenerate triangles: an edge pq of A that reaches the plane of B
///     meets B iff orient3d(p,q,b_k,b_{k+1}) for k = 0,1,2 are all >= 0 or all <= 0 (the
///     line pq passes on the same side of the three edge lines of B). An edge lying in the
///     plane of B is tested in 2D. Edges of A are tried first, then those of B.
///  3. Coplanar non-degenerate triangles: 2D test (edges of A against B, then a corner of B
///     inside A) in a coordinate projection chosen exactly so that it is injective on the
///     common plane.
///  4. Degenerate triangles (collinear or coincident corners) are the segments they span:
///     their three edges are tested against the other triangle (segment-segment tests
///     exactly, in all three coordinate projections when coplanar).
/// Cost: ~6 filtered orient3d for separated pairs, up to ~24 when they intersect; the exact
/// fallback (expansion arithmetic) only runs on (near-)degenerate configurations. `triangles_intersect`, which
/// need not say how, decides pairs that strictly straddle each other's planes with 2 more
/// (Guigue & Devillers 2003) and sends the others through steps 2-4.

#include <crumple/core/types.hpp>

#include <cstdint>

namespace crumple::geometry {

/// How the intersection was found.
enum class Piercing : std::uint8_t {
  None,          ///< the triangles are disjoint
  EdgeOfFirst,   ///< side `edge` of the first triangle meets the second triangle
  EdgeOfSecond,  ///< side `edge` of the second triangle meets the first (sides of the first are
                 ///< tried first, except when only the second triangle is degenerate)
  Coplanar,      ///< both triangles are non-degenerate, lie in one plane, and overlap (in 2D)
};

/// Result of `triangle_triangle_intersection`.
struct TriangleIntersection {
  bool intersects;
  Piercing piercing;
  /// Side k (corners k, (k+1)%3) of the piercing triangle; the first such side in the order
  /// 0, 1, 2. -1 when `piercing` is None or Coplanar. A degenerate triangle is reported
  /// through its sides (EdgeOfFirst/EdgeOfSecond), never as Coplanar.
  int edge;
};

/// Exact test of closed triangles (a0,a1,a2) and (b0,b1,b2), degenerate ones included.
/// Symmetric: swapping the triangles gives the same `intersects` (and Coplanar stays
/// Coplanar). Inputs must be finite (see predicates.hpp for the range).
TriangleIntersection triangle_triangle_intersection(const Vec3& a0, const Vec3& a1,
                                                    const Vec3& a2, const Vec3& b0,
                                                    const Vec3& b1, const Vec3& b2);

/// `triangle_triangle_intersection(...).intersects` (by a shorter path for pairs in general
/// position; see the file comment).
bool triangles_intersect(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0,
                         const Vec3& b1, const Vec3& b2);

/// Exact test of the closed segment [p,q] against the closed triangle (t0,t1,t2), both
/// possibly degenerate.
bool segment_triangle_intersect(const Vec3& p, const Vec3& q, const Vec3& t0, const Vec3& t1,
                                const Vec3& t2);

/// Exact test of closed segments [p0,p1] and [q0,q1] in 3D, possibly degenerate.
bool segments_intersect(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1);

}  // namespace crumple::geometry

#pragma once
/// \file
/// Distance kernels between points, segments and triangles in 3D (pure functions).
///
/// All results carry the *squared* distance, the parameters of the closest points and the
/// closest points themselves. Sources: D. Eberly, Geometric Tools (GTE),
/// `DistSegmentSegment.h` (robust conjugate-gradient version, "ComputeRobust") and
/// `DistPointTriangle.h` (region classification); P. Schneider & D. Eberly,
/// *Geometric Tools for Computer Graphics*, 2003, §10. Two numerical deviations from GTE,
/// described in distance_impl.hpp, make them accurate on near-parallel segments and on
/// sliver triangles.
///
/// Accuracy: the distance is within a few eps*L of the exact distance of the given double
/// inputs (eps = 2^-53, L = largest |coordinate|), including parallel, near-parallel and
/// zero-length segments and degenerate or sliver triangles; tests/geometry/distance_test.cpp
/// measures below 8 eps*L against binary128 oracles. Parameters and barycentrics reproduce
/// the returned closest points up to rounding, but are ill-conditioned where the closest
/// points are (parallel segments, slivers). Inputs must be finite, with coordinate
/// differences of magnitude between ~1e-150 and ~1e150 (squared lengths must neither
/// underflow nor overflow).
///
/// The implementations are inline (in distance_impl.hpp): the O(n^2) reference detector calls
/// them hundreds of millions of times per frame. No heap, no exceptions.

#include <crumple/core/types.hpp>

#include <cstdint>

namespace crumple::geometry {

/// Closest point on segment [a,b] to a point: closest = a + t (b - a), t in [0,1].
struct PointSegmentResult {
  Scalar sqr_distance;
  Scalar t;
  Vec3 closest;
};

/// Closest points of segments P(s) = p0 + s (p1 - p0) and Q(t) = q0 + t (q1 - q0), s,t in [0,1].
struct SegmentSegmentResult {
  Scalar sqr_distance;
  Scalar s;
  Scalar t;
  Vec3 closest0;  ///< P(s)
  Vec3 closest1;  ///< Q(t)
};

/// Feature of triangle (a,b,c) that holds the closest point.
enum class TriangleRegion : std::uint8_t {
  Face,     ///< interior
  EdgeAB,   ///< open side a-b
  EdgeBC,   ///< open side b-c
  EdgeCA,   ///< open side c-a
  VertexA,
  VertexB,
  VertexC,
};

/// Closest point on triangle (a,b,c): closest = w0 a + w1 b + w2 c with barycentric = (w0,w1,w2),
/// each w >= 0 and summing to 1. For a degenerate triangle (collinear or coincident corners)
/// the result is the closest point over its three sides, reported as an edge or vertex region.
struct PointTriangleResult {
  Scalar sqr_distance;
  Vec3 barycentric;
  Vec3 closest;
  TriangleRegion region;
};

/// |p - q|^2.
inline Scalar point_point_sqr_distance(const Vec3& p, const Vec3& q) { return (p - q).squaredNorm(); }

/// Point to segment [a,b]. A zero-length segment gives t = 0.
PointSegmentResult point_segment(const Vec3& p, const Vec3& a, const Vec3& b);

/// Segment to segment, robust for parallel, near-parallel and zero-length segments
/// (no division by |u x v|^2). When several pairs of closest points exist (parallel
/// overlapping segments) one of them is returned, deterministically.
SegmentSegmentResult segment_segment(const Vec3& p0, const Vec3& p1, const Vec3& q0,
                                     const Vec3& q1);

/// Point to triangle (a,b,c), degenerate triangles included. `region` is exact with respect
/// to the returned barycentrics: Vertex* iff two of them are 0 (then `closest` is that corner,
/// bit for bit), Edge* iff exactly one is 0, Face iff none is.
PointTriangleResult point_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

}  // namespace crumple::geometry

#include <crumple/geometry/distance_impl.hpp>

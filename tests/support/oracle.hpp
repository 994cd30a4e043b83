#pragma once
// An independent contact oracle for tests: different code from the library's kernels and
// detectors, so that agreement means something.
//  - Candidate pairs come from a uniform grid over face bounding boxes inflated by h (not an
//    O(n^2) loop, so it runs on real meshes in CI), then every VF and EE sub-pair of each
//    candidate face pair is tested.
//  - Distances are computed in long double: point–triangle by projection onto the plane and
//    an inside test, else the closest of the three sides; segment–segment as the minimum of
//    the interior critical point (when it exists) and the four endpoint–segment distances.

#include <crumple/mesh/mesh.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <set>
#include <tuple>
#include <unordered_map>
#include <vector>

namespace crumple::oracle {

using Real = long double;
struct V3 {
  Real x, y, z;
};
inline V3 v3(const Vec3& p) { return {p.x(), p.y(), p.z()}; }
inline V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V3 operator*(Real s, V3 a) { return {s * a.x, s * a.y, s * a.z}; }
inline Real dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline V3 cross(V3 a, V3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

/// Distance from p to segment [a, b].
inline Real point_segment(V3 p, V3 a, V3 b) {
  const V3 d = b - a;
  const Real len2 = dot(d, d);
  Real t = len2 > 0 ? dot(p - a, d) / len2 : 0;
  t = std::clamp<Real>(t, 0, 1);
  const V3 q = a + t * d;
  return std::sqrt(dot(p - q, p - q));
}

/// Distance from p to triangle (a, b, c).
inline Real point_triangle(V3 p, V3 a, V3 b, V3 c) {
  const V3 n = cross(b - a, c - a);
  const Real n2 = dot(n, n);
  Real best = std::min({point_segment(p, a, b), point_segment(p, b, c), point_segment(p, c, a)});
  if (n2 > 0) {
    const Real h = dot(p - a, n) / n2;
    const V3 q = p - h * n;  // projection onto the plane
    // q inside iff it is on the inner side of the three edges.
    const Real s0 = dot(cross(b - a, q - a), n);
    const Real s1 = dot(cross(c - b, q - b), n);
    const Real s2 = dot(cross(a - c, q - c), n);
    if (s0 >= 0 && s1 >= 0 && s2 >= 0) best = std::min(best, std::fabs(h) * std::sqrt(n2));
  }
  return best;
}

/// Distance between segments [p0, p1] and [q0, q1].
inline Real segment_segment(V3 p0, V3 p1, V3 q0, V3 q1) {
  Real best = std::min({point_segment(p0, q0, q1), point_segment(p1, q0, q1),
                        point_segment(q0, p0, p1), point_segment(q1, p0, p1)});
  const V3 u = p1 - p0, v = q1 - q0, w = p0 - q0;
  const Real a = dot(u, u), b = dot(u, v), c = dot(v, v), d = dot(u, w), e = dot(v, w);
  const Real den = a * c - b * b;
  if (den > 1e-24L * a * c) {
    const Real s = (b * e - c * d) / den;
    const Real t = (a * e - b * d) / den;
    if (s > 0 && s < 1 && t > 0 && t < 1) {
      const V3 diff = (p0 + s * u) - (q0 + t * v);
      best = std::min(best, std::sqrt(dot(diff, diff)));
    }
  }
  return best;
}

/// Oracle contacts: VF keyed (vertex, face), EE keyed (a0, a1, b0, b1) with the canonical
/// order of the contact file format; value = distance.
struct Contacts {
  std::map<std::pair<Index, Index>, Real> vf;
  std::map<std::array<Index, 4>, Real> ee;
};

/// All VF and EE pairs (sharing no vertex) with distance < `limit`, found through a grid.
inline Contacts brute_force(const Topology& topo, PositionsView x, Real limit) {
  Contacts out;
  const Index nf = topo.num_faces();
  if (nf == 0) return out;
  // Face boxes inflated by limit/2 on each side: faces within `limit` have overlapping boxes.
  std::vector<std::array<V3, 2>> box(static_cast<std::size_t>(nf));
  V3 lo{1e300L, 1e300L, 1e300L}, hi{-1e300L, -1e300L, -1e300L};
  Real edge_sum = 0;
  for (Index f = 0; f < nf; ++f) {
    const Face& t = topo.face(f);
    V3 mn{1e300L, 1e300L, 1e300L}, mx{-1e300L, -1e300L, -1e300L};
    for (Index v : t) {
      const V3 p = v3(x[static_cast<std::size_t>(v)]);
      mn = {std::min(mn.x, p.x), std::min(mn.y, p.y), std::min(mn.z, p.z)};
      mx = {std::max(mx.x, p.x), std::max(mx.y, p.y), std::max(mx.z, p.z)};
    }
    const Real r = limit / 2 * (1 + 1e-9L);
    mn = {mn.x - r, mn.y - r, mn.z - r};
    mx = {mx.x + r, mx.y + r, mx.z + r};
    box[static_cast<std::size_t>(f)] = {mn, mx};
    lo = {std::min(lo.x, mn.x), std::min(lo.y, mn.y), std::min(lo.z, mn.z)};
    hi = {std::max(hi.x, mx.x), std::max(hi.y, mx.y), std::max(hi.z, mx.z)};
    edge_sum += std::max({mx.x - mn.x, mx.y - mn.y, mx.z - mn.z});
  }
  const Real cell = std::max<Real>(edge_sum / nf, 1e-30L);
  const auto cell_of = [&](Real value, Real origin) {
    return static_cast<long long>(std::floor((value - origin) / cell));
  };
  std::unordered_map<long long, std::vector<Index>> grid;
  const auto key = [](long long i, long long j, long long k) {
    return (i * 73856093LL) ^ (j * 19349663LL) ^ (k * 83492791LL);
  };
  for (Index f = 0; f < nf; ++f) {
    const auto& [mn, mx] = box[static_cast<std::size_t>(f)];
    for (long long i = cell_of(mn.x, lo.x); i <= cell_of(mx.x, lo.x); ++i)
      for (long long j = cell_of(mn.y, lo.y); j <= cell_of(mx.y, lo.y); ++j)
        for (long long k = cell_of(mn.z, lo.z); k <= cell_of(mx.z, lo.z); ++k)
          grid[key(i, j, k)].push_back(f);
  }
  std::set<std::pair<Index, Index>> face_pairs;
  for (auto& [k, faces] : grid) {
    std::sort(faces.begin(), faces.end());
    faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
    for (std::size_t a = 0; a < faces.size(); ++a) {
      for (std::size_t b = a + 1; b < faces.size(); ++b) {
        const auto& A = box[static_cast<std::size_t>(faces[a])];
        const auto& B = box[static_cast<std::size_t>(faces[b])];
        if (A[0].x > B[1].x || B[0].x > A[1].x || A[0].y > B[1].y || B[0].y > A[1].y ||
            A[0].z > B[1].z || B[0].z > A[1].z)
          continue;
        face_pairs.insert({faces[a], faces[b]});
      }
    }
  }
  const auto P = [&](Index v) { return v3(x[static_cast<std::size_t>(v)]); };
  const auto shares = [](const Face& t, Index v) { return t[0] == v || t[1] == v || t[2] == v; };
  const auto test_vf = [&](Index v, Index f) {
    const Face& t = topo.face(f);
    if (shares(t, v)) return;
    if (out.vf.count({v, f})) return;
    const Real d = point_triangle(P(v), P(t[0]), P(t[1]), P(t[2]));
    if (d < limit) out.vf[{v, f}] = d;
  };
  const auto test_ee = [&](Index a0, Index a1, Index b0, Index b1) {
    if (a0 > a1) std::swap(a0, a1);
    if (b0 > b1) std::swap(b0, b1);
    if (a0 == b0 || a0 == b1 || a1 == b0 || a1 == b1) return;
    std::array<Index, 4> k = std::make_pair(a0, a1) < std::make_pair(b0, b1)
                                 ? std::array<Index, 4>{a0, a1, b0, b1}
                                 : std::array<Index, 4>{b0, b1, a0, a1};
    if (out.ee.count(k)) return;
    const Real d = segment_segment(P(k[0]), P(k[1]), P(k[2]), P(k[3]));
    if (d < limit) out.ee[k] = d;
  };
  // A vertex within `limit` of a face lies in some face incident to it (isolated ones below), whose
  // box then overlaps the face's box; likewise for the faces incident to two close edges.
  for (const auto& [f0, f1] : face_pairs) {
    const Face& A = topo.face(f0);
    const Face& B = topo.face(f1);
    for (Index v : A) test_vf(v, f1);
    for (Index v : B) test_vf(v, f0);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) test_ee(A[i], A[(i + 1) % 3], B[j], B[(j + 1) % 3]);
  }
  // Isolated vertices (used by no face) have no box of their own: test them against every face.
  for (Index v = 0; v < topo.num_vertices(); ++v) {
    if (topo.vertex_faces()[v].empty()) {
      for (Index f = 0; f < nf; ++f) test_vf(v, f);
    }
  }
  return out;
}

}  // namespace crumple::oracle

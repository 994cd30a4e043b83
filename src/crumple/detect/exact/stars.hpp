#pragma once
/// \file
/// Internal to the exact detector and the continuous query: the face pairs around a star
/// (orphans.hpp) that may hold an orphan sub-pair within reach, found from a box tree.

#include <crumple/detect/broad_phase/box_tree_detail.hpp>
#include <crumple/detect/broad_phase/broad_phase.hpp>
#include <crumple/detect/exact/orphans.hpp>

#include <algorithm>
#include <utility>
#include <vector>

namespace crumple::exact {

/// Buffers of `star_pairs`, reused from star to star.
struct StarScratch {
  std::vector<Index> faces;
  std::vector<Box> boxes;
  std::vector<std::pair<Index, Index>> pairs;
  detail::BoxTree tree;
};

/// Calls each(f, g), f < g, once for every pair of faces around star v whose smallest shared
/// vertex is v and where the owned features without v of one (`far_box(f)`: their box, empty
/// if none) meet the other's box (`face_box(g)`); both boxes already grown by half the reach.
/// Every orphan sub-pair of two faces around v has an owned feature without v: the vertex of a
/// vertex-face sub-pair (v is on both faces), or one of two edges that share no vertex. So a
/// sub-pair within reach lies in a pair passed to `each`, and a face that owns no such feature
/// asks nothing (n copies of one face cost O(n log n)). Returns the number of pairs passed.
template <class FaceBox, class FarBox, class Each>
std::size_t star_pairs(const Topology& topo, Index v, StarScratch& s, const FaceBox& face_box, const FarBox& far_box,
                       const Each& each) {
  const auto around = topo.vertex_faces()[v];
  s.faces.assign(around.begin(), around.end());
  std::sort(s.faces.begin(), s.faces.end());
  s.faces.erase(std::unique(s.faces.begin(), s.faces.end()), s.faces.end());
  s.boxes.resize(s.faces.size());
  for (std::size_t k = 0; k < s.faces.size(); ++k) s.boxes[k] = face_box(s.faces[k]);
  s.tree.build(s.boxes);
  s.pairs.clear();
  for (std::size_t k = 0; k < s.faces.size(); ++k) {
    const Box far = far_box(s.faces[k]);
    if (!(far.lo[0] <= far.hi[0])) continue;  // owns nothing without v (or only NaN points)
    s.tree.query(far, [&](std::uint32_t j) {
      if (j != k) s.pairs.emplace_back(std::min(s.faces[k], s.faces[j]), std::max(s.faces[k], s.faces[j]));
    });
  }
  std::sort(s.pairs.begin(), s.pairs.end());
  s.pairs.erase(std::unique(s.pairs.begin(), s.pairs.end()), s.pairs.end());
  std::size_t passed = 0;
  for (const auto& [f, g] : s.pairs) {
    if (smallest_shared_vertex(topo, f, g) != v) continue;
    each(f, g);
    ++passed;
  }
  return passed;
}

/// The box of the points of(u) of the features without v that face f owns under `own` (its
/// corners other than v, the ends of its sides without v), grown by r; empty if none. `of(u)`
/// returns a `Box` (a point's, or a swept one's).
template <class Of>
Box owned_far_box(const Topology& topo, const FeatureOwnership& own, Index f, Index v, Scalar r, const Of& of) {
  const Face& t = topo.face(f);
  const unsigned vertices = own.vertex_mask[static_cast<std::size_t>(f)];
  const unsigned edges = own.edge_mask[static_cast<std::size_t>(f)];
  Box b = Box::empty();
  for (std::size_t k = 0; k < 3; ++k) {
    const Index u = t[k], w = t[(k + 1) % 3];
    if ((vertices >> k & 1u) && u != v) b.merge(of(u));
    if ((edges >> k & 1u) && u != v && w != v) {
      b.merge(of(u));
      b.merge(of(w));
    }
  }
  b.inflate(r);
  return b;
}

}  // namespace crumple::exact

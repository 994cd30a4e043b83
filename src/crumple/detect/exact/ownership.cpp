#include <crumple/detect/exact/ownership.hpp>

#include <algorithm>

namespace crumple::exact {

namespace {

enum : std::uint8_t { kOpen, kNoEdges, kEdges };

/// Per face, kNoEdges for the faces that will own no edge (an independent set: every edge
/// keeps a face that owns edges), kEdges or kOpen for the others.
std::vector<std::uint8_t> edgeless_faces(const Topology& topo) {
  const Index nf = topo.num_faces();
  std::vector<std::uint8_t> edges_state(static_cast<std::size_t>(nf), kOpen);
  const auto state = [&](Index f) -> std::uint8_t& { return edges_state[static_cast<std::size_t>(f)]; };
  for (Index f = 0; f < nf; ++f) {
    if (state(f) != kOpen) continue;
    bool can = true;
    for (const Index e : topo.face_edges(f)) {
      bool other = false;
      for (const Index g : topo.edge_faces()[e]) other = other || (g != f && state(g) != kNoEdges);
      can = can && other;
    }
    if (!can) continue;
    state(f) = kNoEdges;
    for (const Index e : topo.face_edges(f)) {
      for (const Index g : topo.edge_faces()[e]) {
        if (g != f) state(g) = kEdges;
      }
    }
  }
  return edges_state;
}

}  // namespace

std::vector<std::uint8_t> FeatureOwnership::face_owns() const {
  std::vector<std::uint8_t> owns(vertex_mask.size());
  for (std::size_t f = 0; f < owns.size(); ++f) {
    owns[f] = static_cast<std::uint8_t>((vertex_mask[f] != 0 ? 1u : 0u) | (edge_mask[f] != 0 ? 2u : 0u));
  }
  return owns;
}

FeatureOwnership own_features(const Topology& topo) {
  const Index nf = topo.num_faces();
  const Index nv = topo.num_vertices();
  FeatureOwnership own;
  own.vertex_mask.assign(static_cast<std::size_t>(nf), 0);
  own.edge_mask.assign(static_cast<std::size_t>(nf), 0);
  const std::vector<std::uint8_t> edges_state = edgeless_faces(topo);
  const auto owns_edges = [&](Index f) { return edges_state[static_cast<std::size_t>(f)] != kNoEdges; };
  std::vector<std::uint8_t> corners_left(static_cast<std::size_t>(nf), 3);
  for (Index v = 0; v < nv; ++v) {
    const auto faces = topo.vertex_faces()[v];
    if (faces.empty()) {
      own.isolated.push_back(v);
      continue;
    }
    Index f = faces[0];
    int best = -1;
    for (const Index g : faces) {
      const auto i = static_cast<std::size_t>(g);
      const int score = (own.vertex_mask[i] != 0 ? 100 : 0) + (owns_edges(g) ? 10 : 0) + corners_left[i];
      if (score > best) {
        best = score;
        f = g;
      }
    }
    for (const Index g : faces) --corners_left[static_cast<std::size_t>(g)];
    const Face& t = topo.face(f);
    for (int k = 0; k < 3; ++k) {
      if (t[k] == v) own.vertex_mask[static_cast<std::size_t>(f)] |= static_cast<std::uint8_t>(1u << k);
    }
  }
  for (Index e = 0; e < topo.num_edges(); ++e) {
    const auto faces = topo.edge_faces()[e];  // one of them owns edges (`edgeless_faces`)
    const Index f = *std::find_if(faces.begin(), faces.end(), owns_edges);
    const auto& fe = topo.face_edges(f);
    for (int k = 0; k < 3; ++k) {
      if (fe[k] == e) own.edge_mask[static_cast<std::size_t>(f)] |= static_cast<std::uint8_t>(1u << k);
    }
  }
  return own;
}

}  // namespace crumple::exact

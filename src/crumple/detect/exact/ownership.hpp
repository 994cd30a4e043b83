#pragma once
/// \file
/// Internal to the exact detector: feature ownership, the pipeline's first per-topology stage
/// ("representative triangles", Curtis, Tamstorf & Manocha 2008). Every vertex and every edge
/// is owned by exactly one of its faces, so that the narrow phase tests each vertex-face and
/// edge-edge sub-pair in exactly one face pair: VF (v, g) only in {owner(v), g}, EE (e1, e2)
/// only in {owner(e1), owner(e2)}.

#include <crumple/core/types.hpp>
#include <crumple/mesh/mesh.hpp>

#include <cstdint>
#include <vector>

namespace crumple::exact {

struct FeatureOwnership {
  std::vector<std::uint8_t> vertex_mask;  ///< per face, bit k: the face owns corner k
  std::vector<std::uint8_t> edge_mask;    ///< per face, bit k: the face owns side k (corners k, k+1)
  std::vector<Index> isolated;            ///< vertices used by no face (owned by none)
  /// Per face, bit 0: owns a vertex, bit 1: owns an edge (`FrameInput::owns`).
  std::vector<std::uint8_t> face_owns() const;
};

/// Chooses the owners so that many faces own no vertex and many no edge: a pair of faces of
/// which neither owns a vertex and not both own an edge holds no sub-pair, and a proximity
/// query's broad phase may leave it out.
///  - Edges: the faces that own none are an independent set, chosen greedily in face order (a
///    face is left without when each of its edges has another face not left without; those
///    faces then keep theirs); an edge belongs to its first face that owns edges.
///  - Vertices: to the first of its faces that owns a vertex already, else that owns edges,
///    else that has the most corners not yet owned (greedily in vertex order), so that few
///    faces own vertices, and mostly those that own edges.
/// Deterministic: depends on the topology's order only.
FeatureOwnership own_features(const Topology& topo);

}  // namespace crumple::exact

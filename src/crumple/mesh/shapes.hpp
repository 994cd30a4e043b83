#pragma once
/// \file
/// Built-in, deterministic meshes shared by the CLI, the tests and the benchmarks.

#include <crumple/mesh/mesh.hpp>

namespace crumple::shapes {

/// A flat `nx` × `ny` lattice of quads, each split into two triangles, in the z = 0 plane,
/// spanning [0, width] × [0, height]. Vertex (i, j) — i along x in 0..nx, j along y in 0..ny —
/// has id j (nx+1) + i. Quad (i, j) gives faces (v00, v10, v11) and (v00, v11, v01), in that
/// order, quads visited row by row (j outer). Counter-clockwise seen from +z.
TriMesh lattice(Index nx, Index ny, Scalar width = 1, Scalar height = 1);

/// Parameters of the built-in folded cloth.
struct FoldedClothParams {
  Index n = 32;             ///< lattice resolution (n × n quads over the unit square)
  Scalar gap = 0.02;        ///< distance between the two flat layers after the fold
  Scalar wave = 0.006;      ///< amplitude of a ripple on the upper layer (so layers touch in places)
  Scalar thickness = 0.02;  ///< suggested contact thickness for this scene
};

/// The unit-square lattice folded over itself along x = 0.5: the half x > 0.5 wraps around a
/// half-cylinder of diameter `gap` and lies back over the lower half, rippled so that the
/// distance between the layers varies around `gap`. Many vertex–face and edge–edge pairs are
/// near the suggested thickness, none share a vertex. Deterministic.
TriMesh folded_cloth(const FoldedClothParams& params = {});

}  // namespace crumple::shapes

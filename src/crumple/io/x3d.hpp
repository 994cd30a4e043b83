#pragma once
/// \file
/// The thesis' X3D `MassSpring` node (docs/simulation.md), with crumple's `Face` extension.
///
/// ```xml
/// <X3D><Scene><Shape>
///   <MassSpring>
///     <Vertex point="0 0 0, 1 0 0, 0 1 0, 1 1 0" mass="0 1" velocity="0 0 0"/>
///     <Edge vertex="0 1, 1 3, 3 2, 2 0, 1 2" stiffness="5000" dampingRatio="0.1" length="1"/>
///     <Face vertex="0 1 2, 2 1 3"/>
///   </MassSpring>
/// </Shape></Scene></X3D>
/// ```
///
/// Nodes and fields (commas between values are optional, as everywhere in X3D):
///  - `Vertex` (exactly one): `point` #V×3 positions (required); `mass` #V masses
///    (kg, >= 0; **0 pins the vertex**); `velocity` #V×3 velocities (m/s).
///  - `Edge` (at most one; none means no springs): `vertex` #S×2 vertex ids (0-based) of the
///    springs; `stiffness` #S (N/m, >= 0); `dampingRatio` #S (dimensionless, >= 0); `length` #S
///    rest lengths (m, >= 0).
///  - `Face` (crumple's extension, at most one; optional): `vertex` #F×3 vertex ids of the
///    triangles, in the winding order of the file. No -1 separators, triangles only.
///  - Other attributes of `MassSpring` (`ccw`, `convex`, `solid`) and other children are ignored.
///
/// Per-element lists (`mass`, `velocity`, `stiffness`, `dampingRatio`, `length`):
///  - absent or empty: every element gets the default — `MassSpringDefaults` for mass,
///    stiffness and damping ratio, velocity 0, and rest length = the distance between the
///    spring's two endpoints in the file's positions;
///  - shorter than the element count: the given values apply to the first elements and **the
///    last given value is repeated** for the remaining ones (e.g. `mass="0 1"` on 4 vertices
///    gives 0 1 1 1; `velocity="0 0 1"` gives every vertex velocity (0,0,1));
///  - longer than the element count: an error.
/// Also errors (`ParseError` naming the file, the line of the offending element and what was
/// expected): a token that is not a number (not an integer for ids), a non-finite value, a
/// negative mass/stiffness/damping ratio/length, a `point`, `velocity` or `Face` list whose
/// length is not a multiple of 3 (of 2 for `Edge vertex`), a vertex id out of range, and a
/// spring from a vertex to itself.

#include <crumple/core/types.hpp>

#include <filesystem>
#include <vector>

namespace crumple::io {

/// A mass–spring system as stored in a `MassSpring` node; every list is complete.
struct MassSpringData {
  Positions positions;          ///< #V positions
  std::vector<Scalar> masses;   ///< #V masses; 0 = pinned vertex
  Positions velocities;         ///< #V velocities
  std::vector<Edge> springs;    ///< #S springs as two vertex ids, in file order (not reordered)
  std::vector<Scalar> stiffness;      ///< #S spring stiffnesses
  std::vector<Scalar> damping_ratio;  ///< #S spring damping ratios
  std::vector<Scalar> rest_length;    ///< #S spring rest lengths
  std::vector<Face> faces;            ///< #F triangles from the `Face` node; may be empty
};

/// Values used for elements whose list is absent or empty (see the file comment).
struct MassSpringDefaults {
  Scalar mass = 1;
  Scalar stiffness = 1000;
  Scalar damping_ratio = 0.1;
};

/// Reads the first `MassSpring` node of an X3D file, filling short lists by the rules above.
/// Throws `ParseError` when the file has no `MassSpring` node or breaks a rule above.
MassSpringData read_mass_spring(const std::filesystem::path& path,
                                const MassSpringDefaults& defaults = {});

/// Writes an X3D file with one `MassSpring` node holding every list in full (no shortening), so
/// that `read_mass_spring` gives back exactly `data` (values printed as the shortest text that
/// reads back to the same double). Atomic (temporary file + rename). Throws `PreconditionError`
/// when the list sizes disagree, an id is out of range or a value is not finite.
void write_mass_spring(const std::filesystem::path& path, const MassSpringData& data);

}  // namespace crumple::io

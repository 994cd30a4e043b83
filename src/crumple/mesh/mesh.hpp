#pragma once
/// \file
/// Validated indexed triangle mesh and its derived topology (computed once).
///
/// Conventions (stable, relied on by file writers, detectors and the contact format):
///  - Vertices and faces keep exactly the order given to the factory.
///  - Unique edges are numbered in order of first appearance when visiting faces
///    f = 0..#F-1 and, inside a face (v0,v1,v2), its sides (v0,v1), (v1,v2), (v2,v0).
///    Each edge is stored as (min id, max id).
///  - `face_edges(f)[k]` is the edge of side k, i.e. between corners k and (k+1)%3.
///  - Every adjacency list is sorted by increasing id.

#include <crumple/core/types.hpp>

#include <atomic>
#include <cstddef>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

namespace crumple {

/// Compressed adjacency lists: `(*this)[i]` is the sorted list of neighbours of element i.
class Adjacency {
 public:
  Adjacency() = default;
  /// Builds from per-element lists (each list is sorted and deduplicated here).
  static Adjacency from_lists(std::vector<std::vector<Index>> lists);
  /// Takes compressed rows as they are: row i is `data[offsets[i] .. offsets[i+1])`, each
  /// already sorted and without repeats (not checked).
  static Adjacency from_csr(std::vector<std::size_t> offsets, std::vector<Index> data);

  std::span<const Index> operator[](Index i) const {
    return {data_.data() + offsets_[static_cast<std::size_t>(i)],
            data_.data() + offsets_[static_cast<std::size_t>(i) + 1]};
  }
  /// Number of elements (rows).
  Index size() const { return static_cast<Index>(offsets_.empty() ? 0 : offsets_.size() - 1); }
  /// Total number of entries over all rows.
  std::size_t total() const { return data_.size(); }
  /// Position of row i's first entry among all entries.
  std::size_t row_start(Index i) const { return offsets_[static_cast<std::size_t>(i)]; }
  /// Bytes held by the lists (capacity, not size).
  std::size_t memory_bytes() const {
    return offsets_.capacity() * sizeof(std::size_t) + data_.capacity() * sizeof(Index);
  }

 private:
  std::vector<std::size_t> offsets_;  // size()+1 entries
  std::vector<Index> data_;
};

/// What the validating factory accepted but counted (a mesh with these is still usable).
struct MeshReport {
  std::size_t zero_area_faces = 0;     ///< faces with (near) zero area, see `Topology::build`
  std::size_t non_manifold_edges = 0;  ///< edges with more than two incident faces
  std::size_t boundary_edges = 0;      ///< edges with exactly one incident face
  std::size_t isolated_vertices = 0;   ///< vertices used by no face
  std::size_t duplicate_faces = 0;     ///< faces with the same vertex set as an earlier face
  /// Human-readable one-line-per-item summary.
  std::string to_string() const;
};

/// Connectivity of a triangle mesh with every derived adjacency, immutable once built.
/// `build` takes time and memory linear in #V + #F, whatever the valences or repeated faces.
/// The two lists whose size can grow with the square of a valence (`edge_edges`, `face_faces`:
/// a fan of n faces around one vertex has n^2 face pairs) are built on first use (thread-safe),
/// in time linear in their size, so that loading a mesh never pays for them.
class Topology {
 public:
  /// Validates and builds. Throws `InputError` naming the face on an out-of-range index or
  /// a vertex repeated in a face. `num_vertices` may exceed the ids used (isolated vertices).
  static Topology build(Index num_vertices, std::vector<Face> faces);

  Index num_vertices() const { return num_vertices_; }
  Index num_faces() const { return static_cast<Index>(faces_.size()); }
  Index num_edges() const { return static_cast<Index>(edges_.size()); }

  std::span<const Face> faces() const { return faces_; }
  std::span<const Edge> edges() const { return edges_; }
  const Face& face(Index f) const { return faces_[static_cast<std::size_t>(f)]; }
  const Edge& edge(Index e) const { return edges_[static_cast<std::size_t>(e)]; }
  /// Edge of each side of face f (side k joins corners k and (k+1)%3).
  const std::array<Index, 3>& face_edges(Index f) const {
    return face_edges_[static_cast<std::size_t>(f)];
  }

  const Adjacency& edge_faces() const { return edge_faces_; }         ///< faces incident to an edge
  const Adjacency& vertex_edges() const { return vertex_edges_; }     ///< edges incident to a vertex
  const Adjacency& vertex_faces() const { return vertex_faces_; }     ///< faces incident to a vertex
  const Adjacency& vertex_vertices() const { return vertex_vertices_; }  ///< one-ring
  /// Edges sharing at least one vertex with the edge (itself excluded). Built on first use:
  /// sum over vertices of valence^2 entries.
  const Adjacency& edge_edges() const;
  /// Faces sharing at least one vertex with the face (itself excluded). Built on first use:
  /// up to sum over vertices of (faces around it)^2 entries.
  const Adjacency& face_faces() const;

  /// True when face f has v as a corner.
  bool face_has_vertex(Index f, Index v) const {
    const Face& t = face(f);
    return t[0] == v || t[1] == v || t[2] == v;
  }
  /// True when edges a and b share a vertex (or are the same edge).
  bool edges_adjacent(Index a, Index b) const {
    const Edge& x = edge(a);
    const Edge& y = edge(b);
    return x[0] == y[0] || x[0] == y[1] || x[1] == y[0] || x[1] == y[1];
  }
  /// True when faces a and b share a vertex (or are the same face).
  bool faces_adjacent(Index a, Index b) const;

  /// Topological part of the report (everything except zero-area faces, which need positions).
  const MeshReport& report() const { return report_; }

  /// Bytes held by the topology now: capacities of every array, the on-first-use lists only
  /// once built.
  std::size_t memory_bytes() const;

 private:
  struct Lazy {
    std::once_flag edge_edges_once, face_faces_once;
    std::atomic<bool> edge_edges_built{false}, face_faces_built{false};
    Adjacency edge_edges, face_faces;
  };

  Index num_vertices_ = 0;
  std::vector<Face> faces_;
  std::vector<Edge> edges_;
  std::vector<std::array<Index, 3>> face_edges_;
  Adjacency edge_faces_, vertex_edges_, vertex_faces_, vertex_vertices_;
  std::unique_ptr<Lazy> lazy_ = std::make_unique<Lazy>();
  MeshReport report_;
};

/// A triangle mesh: shared immutable topology plus the current positions.
class TriMesh {
 public:
  /// Validating factory. Throws `InputError` naming the element on a non-finite coordinate,
  /// an out-of-range index or a vertex repeated in a face. Zero-area faces and non-manifold
  /// edges are accepted and counted in `report()`.
  static TriMesh create(Positions positions, std::vector<Face> faces);

  const Topology& topology() const { return *topology_; }
  /// Shared handle, for detectors that must keep the topology alive.
  std::shared_ptr<const Topology> topology_ptr() const { return topology_; }
  const Positions& positions() const { return positions_; }
  /// Replaces the positions (same count; finite values checked by `CRUMPLE_CHECK`).
  void set_positions(Positions positions);

  Index num_vertices() const { return topology_->num_vertices(); }
  Index num_faces() const { return topology_->num_faces(); }
  Index num_edges() const { return topology_->num_edges(); }

  /// Topological report plus zero-area faces counted with the current positions.
  const MeshReport& report() const { return report_; }

 private:
  std::shared_ptr<const Topology> topology_;
  Positions positions_;
  MeshReport report_;
};

/// Throws `InputError` naming the first vertex with a non-finite coordinate.
void check_finite(PositionsView positions);

/// Axis-aligned bounds of positions; both corners are NaN-free only for a non-empty input.
struct Bounds {
  Vec3 min;
  Vec3 max;
  /// Length of max - min without overflow or underflow on the way: infinite only when the
  /// length itself exceeds the largest double.
  Scalar diagonal() const;
};
Bounds compute_bounds(PositionsView positions);

/// The contact thickness used when the user gives none: `kDefaultThicknessRel` times the
/// bounding-box diagonal of `positions` (a scale-free choice: the same relative gap on any mesh).
inline constexpr Scalar kDefaultThicknessRel = 1e-3;
Scalar default_thickness(PositionsView positions);

/// Lengths of the unique edges.
struct EdgeLengthStats {
  Scalar min = 0;
  Scalar mean = 0;
  Scalar max = 0;
};
/// Min, mean and max length of the edges of finite length (a NaN or infinite vertex would make
/// the mean NaN or infinite, unrelated to the mesh's scale); all zero when there is none.
/// Scale-free: right for coordinates anywhere in the range of doubles (1e-300 or 1e300).
EdgeLengthStats edge_length_stats(const Topology& topology, PositionsView positions);

/// Number of faces whose area is at most `1e-14 * (longest side)^2` (degenerate slivers),
/// tested on the sides scaled to unit size, so at any scale.
std::size_t count_zero_area_faces(const Topology& topology, PositionsView positions);

}  // namespace crumple

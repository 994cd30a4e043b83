#include <crumple/core/error.hpp>
#include <crumple/mesh/mesh.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <unordered_map>

namespace crumple {

Adjacency Adjacency::from_lists(std::vector<std::vector<Index>> lists) {
  Adjacency adj;
  adj.offsets_.reserve(lists.size() + 1);
  adj.offsets_.push_back(0);
  std::size_t total = 0;
  for (auto& list : lists) {
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    total += list.size();
  }
  adj.data_.reserve(total);
  for (const auto& list : lists) {
    adj.data_.insert(adj.data_.end(), list.begin(), list.end());
    adj.offsets_.push_back(adj.data_.size());
  }
  return adj;
}

std::string MeshReport::to_string() const {
  std::ostringstream out;
  out << "zero-area faces: " << zero_area_faces << "\n"
      << "non-manifold edges: " << non_manifold_edges << "\n"
      << "boundary edges: " << boundary_edges << "\n"
      << "isolated vertices: " << isolated_vertices << "\n"
      << "duplicate faces: " << duplicate_faces << "\n";
  return out.str();
}

namespace {

std::string face_text(Index f, const Face& t) {
  return "face " + std::to_string(f) + " (" + std::to_string(t[0]) + " " + std::to_string(t[1]) +
         " " + std::to_string(t[2]) + ")";
}

std::uint64_t edge_key(Index a, Index b) {
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) |
         static_cast<std::uint32_t>(b);
}

/// Rows of the transpose of `adj` (which has `cols` possible column values).
std::vector<std::vector<Index>> transpose_rows(const std::vector<std::vector<Index>>& rows,
                                               Index cols) {
  std::vector<std::vector<Index>> out(static_cast<std::size_t>(cols));
  for (std::size_t i = 0; i < rows.size(); ++i) {
    for (Index c : rows[i]) out[static_cast<std::size_t>(c)].push_back(static_cast<Index>(i));
  }
  return out;
}

}  // namespace

Topology Topology::build(Index num_vertices, std::vector<Face> faces) {
  if (num_vertices < 0) throw InputError("negative vertex count " + std::to_string(num_vertices));
  if (faces.size() > static_cast<std::size_t>(std::numeric_limits<Index>::max())) {
    throw InputError("too many faces (" + std::to_string(faces.size()) + ")");
  }
  for (std::size_t fi = 0; fi < faces.size(); ++fi) {
    const Face& t = faces[fi];
    const Index f = static_cast<Index>(fi);
    for (Index v : t) {
      if (v < 0 || v >= num_vertices) {
        throw InputError(face_text(f, t) + ": vertex index " + std::to_string(v) +
                         " out of range [0, " + std::to_string(num_vertices) + ")");
      }
    }
    if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) {
      throw InputError(face_text(f, t) + ": a vertex is repeated in the face");
    }
  }

  Topology topo;
  topo.num_vertices_ = num_vertices;
  topo.faces_ = std::move(faces);
  const std::size_t nf = topo.faces_.size();
  const std::size_t nv = static_cast<std::size_t>(num_vertices);

  // Unique edges in order of first appearance (faces in order, sides (0,1), (1,2), (2,0)).
  std::unordered_map<std::uint64_t, Index> edge_ids;
  edge_ids.reserve(nf * 2);
  topo.face_edges_.resize(nf);
  std::vector<std::vector<Index>> edge_faces;
  edge_faces.reserve(nf * 3 / 2 + 3);
  for (std::size_t f = 0; f < nf; ++f) {
    const Face& t = topo.faces_[f];
    for (int k = 0; k < 3; ++k) {
      Index a = t[static_cast<std::size_t>(k)];
      Index b = t[static_cast<std::size_t>((k + 1) % 3)];
      if (a > b) std::swap(a, b);
      auto [it, inserted] = edge_ids.try_emplace(edge_key(a, b), static_cast<Index>(topo.edges_.size()));
      if (inserted) {
        topo.edges_.push_back({a, b});
        edge_faces.emplace_back();
      }
      topo.face_edges_[f][static_cast<std::size_t>(k)] = it->second;
      edge_faces[static_cast<std::size_t>(it->second)].push_back(static_cast<Index>(f));
    }
  }
  const Index ne = static_cast<Index>(topo.edges_.size());

  std::vector<std::vector<Index>> vertex_edges(nv);
  for (Index e = 0; e < ne; ++e) {
    for (Index v : topo.edges_[static_cast<std::size_t>(e)]) vertex_edges[static_cast<std::size_t>(v)].push_back(e);
  }
  std::vector<std::vector<Index>> face_rows(nf);
  for (std::size_t f = 0; f < nf; ++f) face_rows[f].assign(topo.faces_[f].begin(), topo.faces_[f].end());
  std::vector<std::vector<Index>> vertex_faces = transpose_rows(face_rows, num_vertices);

  std::vector<std::vector<Index>> vertex_vertices(nv);
  for (const Edge& e : topo.edges_) {
    vertex_vertices[static_cast<std::size_t>(e[0])].push_back(e[1]);
    vertex_vertices[static_cast<std::size_t>(e[1])].push_back(e[0]);
  }

  // Edge-edge: edges sharing a vertex; face-face: faces sharing a vertex (self excluded).
  std::vector<std::vector<Index>> edge_edges(static_cast<std::size_t>(ne));
  for (Index e = 0; e < ne; ++e) {
    auto& row = edge_edges[static_cast<std::size_t>(e)];
    for (Index v : topo.edges_[static_cast<std::size_t>(e)]) {
      for (Index o : vertex_edges[static_cast<std::size_t>(v)]) {
        if (o != e) row.push_back(o);
      }
    }
  }
  std::vector<std::vector<Index>> face_faces(nf);
  for (std::size_t f = 0; f < nf; ++f) {
    for (Index v : topo.faces_[f]) {
      for (Index o : vertex_faces[static_cast<std::size_t>(v)]) {
        if (o != static_cast<Index>(f)) face_faces[f].push_back(o);
      }
    }
  }

  // Report (topological part).
  MeshReport& r = topo.report_;
  for (const auto& fs : edge_faces) {
    if (fs.size() > 2) ++r.non_manifold_edges;
    if (fs.size() == 1) ++r.boundary_edges;
  }
  for (const auto& fs : vertex_faces) {
    if (fs.empty()) ++r.isolated_vertices;
  }
  {
    std::vector<Face> sorted_faces(topo.faces_);
    for (Face& t : sorted_faces) std::sort(t.begin(), t.end());
    std::sort(sorted_faces.begin(), sorted_faces.end());
    for (std::size_t i = 1; i < sorted_faces.size(); ++i) {
      if (sorted_faces[i] == sorted_faces[i - 1]) ++r.duplicate_faces;
    }
  }

  topo.edge_faces_ = Adjacency::from_lists(std::move(edge_faces));
  topo.vertex_edges_ = Adjacency::from_lists(std::move(vertex_edges));
  topo.vertex_faces_ = Adjacency::from_lists(std::move(vertex_faces));
  topo.vertex_vertices_ = Adjacency::from_lists(std::move(vertex_vertices));
  topo.edge_edges_ = Adjacency::from_lists(std::move(edge_edges));
  topo.face_faces_ = Adjacency::from_lists(std::move(face_faces));
  return topo;
}

bool Topology::faces_adjacent(Index a, Index b) const {
  const Face& x = face(a);
  for (Index v : face(b)) {
    if (x[0] == v || x[1] == v || x[2] == v) return true;
  }
  return false;
}

void check_finite(PositionsView positions) {
  for (std::size_t i = 0; i < positions.size(); ++i) {
    if (!positions[i].allFinite()) {
      std::ostringstream msg;
      msg.precision(17);
      msg << "vertex " << i << " has a non-finite coordinate (" << positions[i].x() << " "
          << positions[i].y() << " " << positions[i].z() << ")";
      throw InputError(msg.str());
    }
  }
}

Bounds compute_bounds(PositionsView positions) {
  const Scalar inf = std::numeric_limits<Scalar>::infinity();
  Bounds b{Vec3::Constant(inf), Vec3::Constant(-inf)};
  for (const Vec3& p : positions) {
    b.min = b.min.cwiseMin(p);
    b.max = b.max.cwiseMax(p);
  }
  return b;
}

Scalar default_thickness(PositionsView positions) {
  return kDefaultThicknessRel * compute_bounds(positions).diagonal();
}

EdgeLengthStats edge_length_stats(const Topology& topology, PositionsView positions) {
  EdgeLengthStats out;
  Scalar sum = 0;
  std::size_t finite = 0;
  out.min = std::numeric_limits<Scalar>::infinity();
  for (const Edge& e : topology.edges()) {
    const Scalar len = (positions[static_cast<std::size_t>(e[1])] - positions[static_cast<std::size_t>(e[0])]).norm();
    if (!std::isfinite(len)) continue;
    out.min = std::min(out.min, len);
    out.max = std::max(out.max, len);
    sum += len;
    ++finite;
  }
  if (finite == 0) return {};
  out.mean = sum / static_cast<Scalar>(finite);
  return out;
}

std::size_t count_zero_area_faces(const Topology& topology, PositionsView positions) {
  std::size_t count = 0;
  for (const Face& t : topology.faces()) {
    const Vec3& a = positions[static_cast<std::size_t>(t[0])];
    const Vec3 e0 = positions[static_cast<std::size_t>(t[1])] - a;
    const Vec3 e1 = positions[static_cast<std::size_t>(t[2])] - a;
    const Scalar longest = std::max({e0.squaredNorm(), e1.squaredNorm(), (e1 - e0).squaredNorm()});
    // |e0 x e1| = 2 area; compare squared quantities.
    if (e0.cross(e1).squaredNorm() <= 4e-28 * longest * longest) ++count;
  }
  return count;
}

TriMesh TriMesh::create(Positions positions, std::vector<Face> faces) {
  check_finite(positions);
  if (positions.size() > static_cast<std::size_t>(std::numeric_limits<Index>::max())) {
    throw InputError("too many vertices (" + std::to_string(positions.size()) + ")");
  }
  TriMesh mesh;
  mesh.topology_ = std::make_shared<const Topology>(
      Topology::build(static_cast<Index>(positions.size()), std::move(faces)));
  mesh.positions_ = std::move(positions);
  mesh.report_ = mesh.topology_->report();
  mesh.report_.zero_area_faces = count_zero_area_faces(*mesh.topology_, mesh.positions_);
  return mesh;
}

void TriMesh::set_positions(Positions positions) {
  CRUMPLE_CHECK(positions.size() == positions_.size(), "set_positions: vertex count changed");
  check_finite(positions);
  positions_ = std::move(positions);
}

}  // namespace crumple

#include <crumple/core/error.hpp>
#include <crumple/mesh/mesh.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

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

/// Offsets of a CSR from per-row counts (in place: counts become the start of each row, and
/// one entry holding the total is appended).
std::vector<std::size_t> offsets_from_counts(std::vector<std::size_t> counts) {
  std::size_t total = 0;
  for (std::size_t& c : counts) {
    const std::size_t n = c;
    c = total;
    total += n;
  }
  counts.push_back(total);
  return counts;
}

}  // namespace

Adjacency Adjacency::from_csr(std::vector<std::size_t> offsets, std::vector<Index> data) {
  Adjacency adj;
  adj.offsets_ = std::move(offsets);
  adj.data_ = std::move(data);
  return adj;
}

// Every list below is filled by visiting its source elements in increasing id order, which
// leaves each row sorted without a sort, in time and memory linear in #F + #V.
Topology Topology::build(Index num_vertices, std::vector<Face> faces) {
  if (num_vertices < 0) throw InputError("negative vertex count " + std::to_string(num_vertices));
  if (faces.size() > static_cast<std::size_t>(std::numeric_limits<Index>::max() / 3)) {
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
  const auto corner = [&](std::size_t h, std::size_t k) {  // corner k of side h = 3f + s
    return static_cast<std::size_t>(topo.faces_[h / 3][(h % 3 + k) % 3]);
  };

  // Unique edges in order of first appearance (faces in order, sides (0,1), (1,2), (2,0)).
  // Sides h = 3f + k are bucketed by their smaller vertex (in increasing h); inside a bucket,
  // `first_side[b]` holds the first side seen towards b, stamped with the bucket's vertex.
  std::vector<Index> first_of(3 * nf);  // first side of the same edge, then the edge's id
  {
    std::vector<std::size_t> start(nv, 0);
    for (std::size_t h = 0; h < 3 * nf; ++h) ++start[std::min(corner(h, 0), corner(h, 1))];
    start = offsets_from_counts(std::move(start));
    std::vector<Index> sides(3 * nf);
    std::vector<std::size_t> fill(start.begin(), start.end() - 1);
    for (std::size_t h = 0; h < 3 * nf; ++h) {
      sides[fill[std::min(corner(h, 0), corner(h, 1))]++] = static_cast<Index>(h);
    }
    std::vector<Index> stamp(nv, -1), first_side(nv, -1);
    for (std::size_t a = 0; a < nv; ++a) {
      for (std::size_t i = start[a]; i < start[a + 1]; ++i) {
        const auto h = static_cast<std::size_t>(sides[i]);
        const std::size_t b = corner(h, 0) == a ? corner(h, 1) : corner(h, 0);
        if (stamp[b] != static_cast<Index>(a)) {
          stamp[b] = static_cast<Index>(a);
          first_side[b] = static_cast<Index>(h);
        }
        first_of[h] = first_side[b];
      }
    }
  }
  std::vector<std::size_t> edge_face_count;
  edge_face_count.reserve(nf * 3 / 2 + 3);
  for (std::size_t h = 0; h < 3 * nf; ++h) {
    const auto first = static_cast<std::size_t>(first_of[h]);
    if (first == h) {  // a new edge; earlier sides already hold their edge id
      const auto a = static_cast<Index>(corner(h, 0)), b = static_cast<Index>(corner(h, 1));
      first_of[h] = static_cast<Index>(topo.edges_.size());
      topo.edges_.push_back({std::min(a, b), std::max(a, b)});
      edge_face_count.push_back(0);
    } else {
      first_of[h] = first_of[first];
    }
    ++edge_face_count[static_cast<std::size_t>(first_of[h])];
  }
  topo.edges_.shrink_to_fit();
  const std::size_t ne = topo.edges_.size();
  topo.face_edges_.resize(nf);
  for (std::size_t f = 0; f < nf; ++f) {
    for (std::size_t k = 0; k < 3; ++k) topo.face_edges_[f][k] = first_of[3 * f + k];
  }
  first_of = {};

  {  // edge -> faces, by increasing face
    std::vector<std::size_t> offsets = offsets_from_counts(std::move(edge_face_count));
    std::vector<Index> data(offsets.back());
    std::vector<std::size_t> fill(offsets.begin(), offsets.end() - 1);
    for (std::size_t f = 0; f < nf; ++f) {
      for (Index e : topo.face_edges_[f]) data[fill[static_cast<std::size_t>(e)]++] = static_cast<Index>(f);
    }
    topo.edge_faces_ = Adjacency::from_csr(std::move(offsets), std::move(data));
  }
  {  // vertex -> edges, by increasing edge
    std::vector<std::size_t> counts(nv, 0);
    for (const Edge& e : topo.edges_) {
      ++counts[static_cast<std::size_t>(e[0])];
      ++counts[static_cast<std::size_t>(e[1])];
    }
    std::vector<std::size_t> offsets = offsets_from_counts(std::move(counts));
    std::vector<Index> data(offsets.back());
    std::vector<std::size_t> fill(offsets.begin(), offsets.end() - 1);
    for (std::size_t e = 0; e < ne; ++e) {
      for (Index v : topo.edges_[e]) data[fill[static_cast<std::size_t>(v)]++] = static_cast<Index>(e);
    }
    topo.vertex_edges_ = Adjacency::from_csr(std::move(offsets), std::move(data));
  }
  {  // vertex -> faces, by increasing face
    std::vector<std::size_t> counts(nv, 0);
    for (const Face& t : topo.faces_) {
      for (Index v : t) ++counts[static_cast<std::size_t>(v)];
    }
    std::vector<std::size_t> offsets = offsets_from_counts(std::move(counts));
    std::vector<Index> data(offsets.back());
    std::vector<std::size_t> fill(offsets.begin(), offsets.end() - 1);
    for (std::size_t f = 0; f < nf; ++f) {
      for (Index v : topo.faces_[f]) data[fill[static_cast<std::size_t>(v)]++] = static_cast<Index>(f);
    }
    topo.vertex_faces_ = Adjacency::from_csr(std::move(offsets), std::move(data));
  }
  {  // vertex -> vertices: the other end of each incident edge, visiting u in increasing order
    std::vector<std::size_t> offsets(nv + 1);
    for (std::size_t v = 0; v <= nv; ++v) offsets[v] = v < nv ? topo.vertex_edges_.row_start(static_cast<Index>(v)) : topo.vertex_edges_.total();
    std::vector<Index> data(offsets.back());
    std::vector<std::size_t> fill(offsets.begin(), offsets.end() - 1);
    for (std::size_t u = 0; u < nv; ++u) {
      for (Index e : topo.vertex_edges_[static_cast<Index>(u)]) {
        const Edge& ends = topo.edges_[static_cast<std::size_t>(e)];
        const auto w = static_cast<std::size_t>(ends[0] == static_cast<Index>(u) ? ends[1] : ends[0]);
        data[fill[w]++] = static_cast<Index>(u);
      }
    }
    topo.vertex_vertices_ = Adjacency::from_csr(std::move(offsets), std::move(data));
  }

  // Report (topological part).
  MeshReport& r = topo.report_;
  for (std::size_t e = 0; e < ne; ++e) {
    const std::size_t n = topo.edge_faces_[static_cast<Index>(e)].size();
    if (n > 2) ++r.non_manifold_edges;
    if (n == 1) ++r.boundary_edges;
  }
  for (std::size_t v = 0; v < nv; ++v) {
    if (topo.vertex_faces_[static_cast<Index>(v)].empty()) ++r.isolated_vertices;
  }
  {
    std::vector<Face> sorted_faces(topo.faces_);
    for (Face& t : sorted_faces) std::sort(t.begin(), t.end());
    std::sort(sorted_faces.begin(), sorted_faces.end());
    for (std::size_t i = 1; i < sorted_faces.size(); ++i) {
      if (sorted_faces[i] == sorted_faces[i - 1]) ++r.duplicate_faces;
    }
  }
  return topo;
}

const Adjacency& Topology::edge_edges() const {
  std::call_once(lazy_->edge_edges_once, [this] {
    // Row e merges the (sorted) edge lists of its two ends, which share only e itself.
    const std::size_t ne = edges_.size();
    std::vector<std::size_t> offsets(ne + 1, 0);
    for (std::size_t e = 0; e < ne; ++e) {
      const Edge& ends = edges_[e];
      offsets[e + 1] = offsets[e] + vertex_edges_[ends[0]].size() + vertex_edges_[ends[1]].size() - 2;
    }
    std::vector<Index> data;
    data.reserve(offsets.back());
    for (std::size_t e = 0; e < ne; ++e) {
      const auto a = vertex_edges_[edges_[e][0]], b = vertex_edges_[edges_[e][1]];
      const auto self = static_cast<Index>(e);
      std::size_t i = 0, j = 0;
      while (i < a.size() || j < b.size()) {
        const Index next = j == b.size() || (i < a.size() && a[i] < b[j]) ? a[i++] : b[j++];
        if (next != self) data.push_back(next);
      }
    }
    lazy_->edge_edges = Adjacency::from_csr(std::move(offsets), std::move(data));
    lazy_->edge_edges_built.store(true, std::memory_order_release);
  });
  return lazy_->edge_edges;
}

const Adjacency& Topology::face_faces() const {
  std::call_once(lazy_->face_faces_once, [this] {
    // Row f merges the (sorted) face lists of its three corners, without repeats: the work is
    // at most three times the row's size.
    const std::size_t nf = faces_.size();
    std::vector<std::size_t> offsets(1, 0);
    offsets.reserve(nf + 1);
    std::vector<Index> data;
    for (std::size_t f = 0; f < nf; ++f) {
      std::array<std::span<const Index>, 3> lists;
      for (std::size_t k = 0; k < 3; ++k) lists[k] = vertex_faces_[faces_[f][k]];
      std::array<std::size_t, 3> at{0, 0, 0};
      const auto self = static_cast<Index>(f);
      Index last = -1;
      for (;;) {
        Index next = std::numeric_limits<Index>::max();
        for (std::size_t k = 0; k < 3; ++k) {
          if (at[k] < lists[k].size()) next = std::min(next, lists[k][at[k]]);
        }
        if (next == std::numeric_limits<Index>::max()) break;
        for (std::size_t k = 0; k < 3; ++k) {
          if (at[k] < lists[k].size() && lists[k][at[k]] == next) ++at[k];
        }
        if (next != self && next != last) data.push_back(next);
        last = next;
      }
      offsets.push_back(data.size());
    }
    data.shrink_to_fit();
    lazy_->face_faces = Adjacency::from_csr(std::move(offsets), std::move(data));
    lazy_->face_faces_built.store(true, std::memory_order_release);
  });
  return lazy_->face_faces;
}

std::size_t Topology::memory_bytes() const {
  std::size_t lazy = 0;
  if (lazy_->edge_edges_built.load(std::memory_order_acquire)) lazy += lazy_->edge_edges.memory_bytes();
  if (lazy_->face_faces_built.load(std::memory_order_acquire)) lazy += lazy_->face_faces.memory_bytes();
  return faces_.capacity() * sizeof(Face) + edges_.capacity() * sizeof(Edge) +
         face_edges_.capacity() * sizeof(face_edges_[0]) + edge_faces_.memory_bytes() +
         vertex_edges_.memory_bytes() + vertex_faces_.memory_bytes() + vertex_vertices_.memory_bytes() +
         lazy;
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

namespace {
/// 2 |half|, with half = (b - a) / 2 computed exactly from halves (no overflow): bit for bit
/// the plain |b - a| in the normal range, a scaled norm where the squares would overflow or
/// underflow.
Scalar length_from_half(const Vec3& half) {
  const Scalar plain = half.norm();
  return 2 * (std::isfinite(plain) && plain > 1e-150 ? plain : half.stableNorm());
}
}  // namespace

Scalar Bounds::diagonal() const { return length_from_half(max * 0.5 - min * 0.5); }

Scalar default_thickness(PositionsView positions) {
  return kDefaultThicknessRel * compute_bounds(positions).diagonal();
}

EdgeLengthStats edge_length_stats(const Topology& topology, PositionsView positions) {
  EdgeLengthStats out;
  Scalar sum = 0;
  std::size_t finite = 0;
  out.min = std::numeric_limits<Scalar>::infinity();
  for (const Edge& e : topology.edges()) {
    // Halves first and a scaled norm: no overflow (nor underflow) unless the length does.
    const Vec3 half = positions[static_cast<std::size_t>(e[1])] * 0.5 - positions[static_cast<std::size_t>(e[0])] * 0.5;
    const Scalar len = length_from_half(half);
    if (!std::isfinite(len)) continue;
    out.min = std::min(out.min, len);
    out.max = std::max(out.max, len);
    sum += len;
    ++finite;
  }
  if (finite == 0) return {};
  out.mean = sum / static_cast<Scalar>(finite);
  if (!std::isfinite(out.mean)) {  // the sum overflowed: a running mean cannot
    Scalar mean = 0;
    std::size_t k = 0;
    for (const Edge& e : topology.edges()) {
      const Scalar len = length_from_half(positions[static_cast<std::size_t>(e[1])] * 0.5 -
                                          positions[static_cast<std::size_t>(e[0])] * 0.5);
      if (std::isfinite(len)) mean += (len - mean) / static_cast<Scalar>(++k);
    }
    out.mean = std::clamp(mean, out.min, out.max);
  }
  return out;
}

std::size_t count_zero_area_faces(const Topology& topology, PositionsView positions) {
  std::size_t count = 0;
  for (const Face& t : topology.faces()) {
    // Sides scaled so that the largest coordinate is about 1: the squares below neither
    // overflow at 1e300 nor underflow at 1e-300.
    const Vec3 a = positions[static_cast<std::size_t>(t[0])] * 0.5;
    Vec3 e0 = positions[static_cast<std::size_t>(t[1])] * 0.5 - a;
    Vec3 e1 = positions[static_cast<std::size_t>(t[2])] * 0.5 - a;
    const Scalar largest = std::max(e0.cwiseAbs().maxCoeff(), e1.cwiseAbs().maxCoeff());
    if (!(largest > 0) || !std::isfinite(largest)) {
      count += largest == 0;
      continue;
    }
    // A power of two: exact, so the test below does not depend on the scale at all.
    const Scalar scale = std::ldexp(1.0, -std::ilogb(largest));
    e0 *= scale;
    e1 *= scale;
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

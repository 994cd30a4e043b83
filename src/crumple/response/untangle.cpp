#include <crumple/core/error.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/geometry/triangle_intersection.hpp>
#include <crumple/response/union_find_detail.hpp>
#include <crumple/response/untangle.hpp>

#include <algorithm>
#include <cmath>
#include <tuple>
#include <utility>

namespace crumple::response {

namespace {
inline std::size_t at(Index i) { return static_cast<std::size_t>(i); }

/// A contour is a *band* (`Contour::band`) when it has at least this many crossings ...
constexpr std::size_t kBandCrossings = 32;
/// ... and at least this many crossings per inside vertex.
constexpr std::size_t kBandRatio = 4;
/// A closed curve between pinches enclosing at most this many vertices is a short fold
/// (`Contour::short_fold`).
constexpr std::size_t kShortFoldInside = 4;

using detail::root;

/// Barycentric coordinates (w.r.t. a, b, c) of the point where segment pq meets the triangle:
/// the plane crossing when pq is not parallel to the plane, clamped into the triangle by taking
/// the triangle's closest point to it.
Vec3 crossing_point(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const Scalar vp = n.dot(p - a), vq = n.dot(q - a);
  const Scalar s = vp != vq ? std::clamp(vp / (vp - vq), Scalar(0), Scalar(1)) : Scalar(0.5);
  return geometry::point_triangle(p + s * (q - p), a, b, c).barycentric;
}

/// One (edge, face) crossing found on pair `pair`.
struct Record {
  Index edge, face, pair;
  bool operator<(const Record& o) const { return std::tie(edge, face, pair) < std::tie(o.edge, o.face, o.pair); }
};

/// The fewest mesh edges crossed going from a face that a boundary crossing of `k` passes
/// through to the cloth's border (its last edge a boundary edge), not crossing `cut` edges;
/// empty when there is none. Breadth-first over faces; `came_from` (#F, all -1) is left so.
void closure_to_border(const Topology& topology, const std::vector<Crossing>& crossings, const Contour& k,
                       const std::vector<char>& cut, std::vector<Index>& came_from, std::vector<Index>& queue,
                       std::vector<Index>& closure) {
  queue.clear();
  for (Index i : k.crossings) {
    const Crossing& c = crossings[at(i)];
    if (topology.edge_faces()[c.edge].size() == 1 && came_from[at(c.face)] < 0) {
      came_from[at(c.face)] = c.face;  // a start: its own origin
      queue.push_back(c.face);
    }
  }
  Index end_face = -1, end_edge = -1;
  for (std::size_t head = 0; head < queue.size() && end_face < 0; ++head) {
    const Index f = queue[head];
    for (Index e : topology.face_edges(f)) {
      if (cut[at(e)]) continue;
      const auto faces = topology.edge_faces()[e];
      if (faces.size() == 1) {
        end_face = f;
        end_edge = e;
        break;
      }
      for (Index g : faces) {
        if (came_from[at(g)] < 0) {
          came_from[at(g)] = f;
          queue.push_back(g);
        }
      }
    }
  }
  if (end_face >= 0) {
    closure.push_back(end_edge);
    for (Index f = end_face; came_from[at(f)] != f; f = came_from[at(f)]) {
      const Index g = came_from[at(f)];
      for (Index e : topology.face_edges(f)) {
        const auto faces = topology.edge_faces()[e];
        if (faces.size() == 2 && (faces[0] == g || faces[1] == g)) closure.push_back(e);
      }
    }
  }
  for (Index f : queue) came_from[at(f)] = -1;
}

Vec3 unit_normal(const Face& f, PositionsView x) {
  const Vec3 n = (x[at(f[1])] - x[at(f[0])]).cross(x[at(f[2])] - x[at(f[0])]);
  const Scalar len = n.norm();
  return len > 0 ? Vec3(n / len) : Vec3::Zero();
}
}  // namespace

std::vector<PinchCrossing> find_pinch_crossings(const Topology& topology, PositionsView x) {
  CRUMPLE_CHECK(x.size() == at(topology.num_vertices()), "positions must have #V entries");
  std::vector<PinchCrossing> out;
  for (Index v = 0; v < topology.num_vertices(); ++v) {
    const auto star = topology.vertex_faces()[v];
    for (std::size_t i = 0; i < star.size(); ++i) {
      for (std::size_t j = i + 1; j < star.size(); ++j) {
        const Face& a = topology.face(star[i]);
        const Face& b = topology.face(star[j]);
        const auto in_b = [&](Index u) { return u == b[0] || u == b[1] || u == b[2]; };
        if (in_b(a[0]) + in_b(a[1]) + in_b(a[2]) != 1) continue;
        // Two triangles meeting only at v intersect elsewhere exactly when the side opposite v
        // of one meets the other (their common part is a segment from v, which leaves them
        // through such a side); the sides through v meet the other's plane at v only.
        for (const auto& [f, g] : {std::pair{star[i], star[j]}, std::pair{star[j], star[i]}}) {
          const Face& t = topology.face(g);
          for (Index e : topology.face_edges(f)) {
            const Edge& ed = topology.edge(e);
            if (ed[0] == v || ed[1] == v) continue;
            if (geometry::segment_triangle_intersect(x[at(ed[0])], x[at(ed[1])], x[at(t[0])], x[at(t[1])],
                                                     x[at(t[2])])) {
              out.push_back({v, e, f, g});
            }
          }
        }
      }
    }
  }
  return out;
}

std::size_t count_pinch_pairs(const Topology& topology, PositionsView x) {
  const std::vector<PinchCrossing> c = find_pinch_crossings(topology, x);
  std::size_t n = 0;
  for (std::size_t i = 0; i < c.size(); ++i) {
    n += i == 0 || c[i - 1].vertex != c[i].vertex ||
         std::minmax(c[i - 1].edge_face, c[i - 1].face) != std::minmax(c[i].edge_face, c[i].face);
  }
  return n;
}

IntersectionAnalysis analyse_intersections(const Topology& topology, PositionsView x,
                                           std::span<const TriangleTriangleContact> pairs,
                                           std::span<const Scalar> inv_mass) {
  CRUMPLE_CHECK(x.size() == at(topology.num_vertices()), "positions must have #V entries");
  CRUMPLE_CHECK(inv_mass.empty() || inv_mass.size() == x.size(), "inv_mass must be empty or have #V entries");
  IntersectionAnalysis out;
  out.pairs = pairs.size();
  out.tangle.assign(x.size(), 0);

  // 1. Crossings.
  std::vector<Record> records;
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    const Index faces[2] = {pairs[p].face0, pairs[p].face1};
    for (int side = 0; side < 2; ++side) {
      const Index f = faces[side], g = faces[1 - side];
      const Face& t = topology.face(g);
      for (Index c : topology.face(f)) out.tangle[at(c)] = 1;
      for (Index e : topology.face_edges(f)) {
        const Edge& ed = topology.edge(e);
        if (geometry::segment_triangle_intersect(x[at(ed[0])], x[at(ed[1])], x[at(t[0])], x[at(t[1])],
                                                 x[at(t[2])])) {
          records.push_back({e, g, static_cast<Index>(p)});
        }
      }
    }
  }
  // 1b. Pinches: a vertex whose star passes through itself. A curve of a single sheet that ends
  // without reaching the border ends at such vertices, its two preimages meeting there: the
  // pinch's crossings join the pinch to the curve, and the flood fill below goes around the
  // pinch. A pinch with no `tt` pair near it is a curve of its own (inside one star).
  const std::vector<PinchCrossing> pinch_crossings = find_pinch_crossings(topology, x);
  std::vector<Index> pinch_vertex;  // per pinch pair, after the `tt` pairs
  for (std::size_t i = 0; i < pinch_crossings.size(); ++i) {
    const PinchCrossing& c = pinch_crossings[i];
    // Crossings of one pinch pair (its two faces, either way round) are listed together.
    const bool same_pair = i > 0 && pinch_crossings[i - 1].vertex == c.vertex &&
                           std::minmax(pinch_crossings[i - 1].edge_face, pinch_crossings[i - 1].face) ==
                               std::minmax(c.edge_face, c.face);
    if (!same_pair) pinch_vertex.push_back(c.vertex);
    records.push_back({c.edge, c.face, static_cast<Index>(pairs.size() + pinch_vertex.size() - 1)});
    // Intersecting faces, like those of the `tt` pairs: their corners are the tangle.
    for (Index f : {c.edge_face, c.face}) {
      for (Index v : topology.face(f)) out.tangle[at(v)] = 1;
    }
  }
  out.pinch_pairs = pinch_vertex.size();
  std::sort(records.begin(), records.end());
  std::vector<Index> record_crossing(records.size());
  for (std::size_t r = 0; r < records.size(); ++r) {
    if (r == 0 || records[r].edge != records[r - 1].edge || records[r].face != records[r - 1].face) {
      const Record& rec = records[r];
      const Edge& ed = topology.edge(rec.edge);
      const Face& t = topology.face(rec.face);
      Crossing c;
      c.edge = rec.edge;
      c.face = rec.face;
      c.barycentric = crossing_point(x[at(ed[0])], x[at(ed[1])], x[at(t[0])], x[at(t[1])], x[at(t[2])]);
      out.crossings.push_back(c);
    }
    record_crossing[r] = static_cast<Index>(out.crossings.size()) - 1;
  }

  // 2. Contours: the crossings of one pair are on one curve.
  std::vector<Index> parent(out.crossings.size());
  for (std::size_t i = 0; i < parent.size(); ++i) parent[i] = static_cast<Index>(i);
  std::vector<Index> pair_first(pairs.size() + pinch_vertex.size(), -1);
  for (std::size_t r = 0; r < records.size(); ++r) {
    Index& first = pair_first[at(records[r].pair)];
    if (first < 0) {
      first = record_crossing[r];
    } else {
      parent[at(root(parent, record_crossing[r]))] = root(parent, first);
    }
  }
  std::vector<Index> contour_of_root(parent.size(), -1);
  for (std::size_t i = 0; i < out.crossings.size(); ++i) {
    const Index r = root(parent, static_cast<Index>(i));
    if (contour_of_root[at(r)] < 0) {
      contour_of_root[at(r)] = static_cast<Index>(out.contours.size());
      out.contours.emplace_back();
    }
    Crossing& c = out.crossings[i];
    c.contour = contour_of_root[at(r)];
    Contour& k = out.contours[at(c.contour)];
    k.crossings.push_back(static_cast<Index>(i));
    k.open = k.open || topology.edge_faces()[c.edge].size() == 1;
  }
  for (std::size_t p = 0; p < pair_first.size(); ++p) {
    if (pair_first[p] < 0) continue;
    Contour& k = out.contours[at(out.crossings[at(pair_first[p])].contour)];
    if (p < pairs.size()) {
      ++k.pairs;
    } else {
      k.pinches.push_back(pinch_vertex[p - pairs.size()]);
    }
  }
  for (Contour& k : out.contours) {
    std::sort(k.pinches.begin(), k.pinches.end());
    k.pinches.erase(std::unique(k.pinches.begin(), k.pinches.end()), k.pinches.end());
    for (Index v : k.pinches) out.tangle[at(v)] = 1;
  }

  // 3. Regions: flood fill with the contour's crossing edges cut, the outside chosen in each
  // connected piece of the mesh (two separate sheets each have theirs).
  const Index nv = topology.num_vertices();
  std::vector<char> cut(at(topology.num_edges()), 0);
  std::vector<Index> part(at(nv), -1), piece(at(nv), -1), stack;
  std::vector<std::size_t> size;
  std::vector<char> pinned;
  std::vector<char> inside_any(at(nv), 0);
  std::vector<char> blocked(at(nv), 0);  // the current contour's pinches: on the curve
  // Labels the parts of the mesh reachable along edges that are not cut; returns their count.
  const auto fill = [&](std::vector<Index>& label) {
    std::fill(label.begin(), label.end(), -1);
    size.clear();
    pinned.clear();
    for (Index seed = 0; seed < nv; ++seed) {
      if (label[at(seed)] >= 0 || blocked[at(seed)] || topology.vertex_edges()[seed].empty()) continue;
      const Index id = static_cast<Index>(size.size());
      size.push_back(0);
      pinned.push_back(0);
      label[at(seed)] = id;
      stack.assign(1, seed);
      while (!stack.empty()) {
        const Index v = stack.back();
        stack.pop_back();
        ++size[at(id)];
        if (!inv_mass.empty() && inv_mass[at(v)] == 0) pinned[at(id)] = 1;
        for (Index e : topology.vertex_edges()[v]) {
          if (cut[at(e)]) continue;
          const Edge& ed = topology.edge(e);
          const Index w = ed[0] == v ? ed[1] : ed[0];
          if (label[at(w)] < 0 && !blocked[at(w)]) {
            label[at(w)] = id;
            stack.push_back(w);
          }
        }
      }
    }
    return size.size();
  };
  const std::size_t pieces = fill(piece);
  std::vector<Index> piece_of_part;
  std::vector<Index> outside_of_piece(pieces);
  std::vector<char> piece_pinned(pieces);
  std::vector<Index> came_from(at(topology.num_faces()), -1), queue;
  for (Contour& k : out.contours) {
    for (Index i : k.crossings) cut[at(out.crossings[at(i)].edge)] = 1;
    for (Index v : k.pinches) blocked[at(v)] = 1;
    k.parts = fill(part);
    if (k.parts == pieces && k.open && !k.pinches.empty() && k.pairs > 0) {
      // A curve from the border to a pinch cuts nothing off: its second preimage ends inside the
      // face its border side passes through. Closed from that face to the border along the
      // fewest mesh edges, it cuts off the flap on that side of the curve, which goes through.
      closure_to_border(topology, out.crossings, k, cut, came_from, queue, k.closure);
      for (Index e : k.closure) cut[at(e)] = 1;
      if (!k.closure.empty()) k.parts = fill(part);
      for (Index e : k.closure) cut[at(e)] = 0;
    }
    for (Index i : k.crossings) cut[at(out.crossings[at(i)].edge)] = 0;
    for (Index v : k.pinches) blocked[at(v)] = 0;
    if (k.parts == pieces) continue;  // the curve cuts nothing off
    piece_of_part.assign(k.parts, -1);
    for (Index v = 0; v < nv; ++v) {
      if (part[at(v)] >= 0) piece_of_part[at(part[at(v)])] = piece[at(v)];
    }
    // In each piece: the largest part, or the largest pinned one when the piece has pins.
    std::fill(outside_of_piece.begin(), outside_of_piece.end(), -1);
    std::fill(piece_pinned.begin(), piece_pinned.end(), 0);
    for (std::size_t id = 0; id < k.parts; ++id) piece_pinned[at(piece_of_part[id])] |= pinned[id];
    for (std::size_t id = 0; id < k.parts; ++id) {
      const Index pc = piece_of_part[id];
      if (piece_pinned[at(pc)] && !pinned[id]) continue;
      Index& outside = outside_of_piece[at(pc)];
      if (outside < 0 || size[id] > size[at(outside)]) outside = static_cast<Index>(id);
    }
    if (!k.closure.empty()) {
      // The closure chose the flap; one holding a pin cannot go through (and the rest of the
      // cloth is no flap): the curve is left with no inside.
      bool pinned_flap = false;
      for (std::size_t id = 0; id < k.parts; ++id) {
        pinned_flap |= size[id] > size[at(outside_of_piece[at(piece_of_part[id])])];
      }
      if (pinned_flap) {
        k.closure.clear();
        k.parts = pieces;
        continue;
      }
    }
    for (Index v = 0; v < nv; ++v) {
      const Index id = part[at(v)];
      if (id >= 0 && id != outside_of_piece[at(piece[at(v)])] && !pinned[at(id)]) {
        k.inside.push_back(v);
        inside_any[at(v)] = 1;
        out.tangle[at(v)] = 1;
      }
    }
    k.band = !k.inside.empty() && k.crossings.size() >= kBandCrossings &&
             k.inside.size() * kBandRatio <= k.crossings.size();
    k.short_fold = !k.open && k.pairs > 0 && k.pinches.size() >= 2 && !k.inside.empty() &&
                   k.inside.size() <= kShortFoldInside;
  }
  // A curve ending at a pinch is a fold folded beyond flat there, its two sides through each
  // other (between two pinches, or from a pinch to the border or to itself). Flipping it back
  // moves its vertices through faces next to the intersecting ones, which the contacts and the
  // fail-safe would hold: the vertices one edge from the curve's crossing edges and crossed
  // faces join the tangle.
  std::vector<char> ring(at(nv), 0);
  for (const Contour& k : out.contours) {
    if (k.pinches.empty()) continue;
    for (Index i : k.crossings) {
      const Crossing& c = out.crossings[at(i)];
      for (Index v : topology.edge(c.edge)) ring[at(v)] = 1;
      for (Index v : topology.face(c.face)) ring[at(v)] = 1;
    }
  }
  for (Index v = 0; v < nv; ++v) {
    if (!ring[at(v)]) continue;
    for (Index e : topology.vertex_edges()[v]) {
      for (Index w : topology.edge(e)) out.tangle[at(w)] = 1;
    }
  }
  out.inside_vertices = static_cast<std::size_t>(std::count(inside_any.begin(), inside_any.end(), 1));
  return out;
}

bool touches_tangle_on_both_sides(const Stencil& s, std::span<const char> tangle) {
  if (tangle.empty()) return false;
  const auto in = [&](int k) { return s.vertex[at(k)] >= 0 && tangle[at(s.vertex[at(k)])] != 0; };
  const bool first = s.edge_edge ? in(0) || in(1) : in(0);
  const bool second = s.edge_edge ? in(2) || in(3) : in(1) || in(2) || in(3);
  return first && second;
}

namespace {
UntangleOptions checked(UntangleOptions o) {
  if (!(o.thickness >= 0) || !std::isfinite(o.thickness)) throw InputError("untangle thickness must be finite and >= 0");
  if (!(o.max_step > 0) || !std::isfinite(o.max_step)) throw InputError("untangle step must be finite and > 0");
  if (!(o.contour_step >= 0) || !std::isfinite(o.contour_step)) {
    throw InputError("untangle contour step must be finite and >= 0");
  }
  if (!(o.border_step >= 0) || !std::isfinite(o.border_step)) {
    throw InputError("untangle border step must be finite and >= 0");
  }
  return o;
}
}  // namespace

Untangler::Untangler(std::shared_ptr<const Topology> topology, UntangleOptions options)
    : topology_(std::move(topology)), options_(checked(options)) {
  CRUMPLE_CHECK(topology_ != nullptr, "untangler needs a topology");
  DetectorOptions detection;
  detection.kinds = ContactKinds::parse("tt");
  detection.threads = options_.threads;
  detector_ = make_detector(MethodSpec(Method::Kdop), detection);
  detector_->set_topology(topology_);
  analysis_.tangle.assign(at(topology_->num_vertices()), 0);
}

std::size_t Untangler::count(PositionsView x) {
  detector_->update(x, contacts_);
  analysis_ = {};
  analysis_.pairs = contacts_.tt.size();
  analysis_.pinch_pairs = count_pinch_pairs(*topology_, x);
  analysis_.tangle.assign(x.size(), 0);
  pulls_.clear();
  shifts_.clear();
  return contacts_.tt.size();
}

std::size_t Untangler::analyse(PositionsView x, std::span<const Scalar> inv_mass) {
  detector_->update(x, contacts_);
  analysis_ = analyse_intersections(*topology_, x, contacts_.tt, inv_mass);
  pulls_.clear();
  held_face_.clear();
  shifts_.clear();
  const Topology& topo = *topology_;
  for (const Crossing& c : analysis_.crossings) {
    const Contour& k = analysis_.contours[at(c.contour)];
    const Edge& ed = topo.edge(c.edge);
    const Face& t = topo.face(c.face);
    const Vec3 n = unit_normal(t, x);
    if (n == Vec3::Zero()) continue;
    // A pinch is on the curve: the part of an edge between it and the crossing is inside.
    const auto in = [&](Index v) {
      return std::binary_search(k.inside.begin(), k.inside.end(), v) ||
             std::binary_search(k.pinches.begin(), k.pinches.end(), v);
    };
    const bool in0 = in(ed[0]), in1 = in(ed[1]);
    if (in0 != in1) {
      const Index inner = in0 ? ed[0] : ed[1], outer = in0 ? ed[1] : ed[0];
      const Scalar side = n.dot(x[at(outer)] - x[at(inner)]);
      if (side == 0) continue;
      pulls_.push_back(vertex_face_stencil(inner, t, c.barycentric, side > 0 ? n : Vec3(-n)));
      held_face_.push_back(k.band ? 1 : 0);
      // A short fold's crossings are also shortened (below): pulled alone, its curve walked
      // along the fold rather than closing.
      if (!k.short_fold) continue;
    } else if (!k.inside.empty() && !k.short_fold) {
      continue;
    }
    if (k.pairs == 0) {
      // A pinch alone: its star folded beyond flat. The end of the crossing side nearer the
      // face's plane goes back through it.
      const Scalar d0 = n.dot(x[at(ed[0])] - x[at(t[0])]), d1 = n.dot(x[at(ed[1])] - x[at(t[0])]);
      const Index inner = std::abs(d0) < std::abs(d1) ? ed[0] : ed[1];
      const Scalar side = std::abs(d0) < std::abs(d1) ? d1 : d0;
      if (side != 0) {
        pulls_.push_back(vertex_face_stencil(inner, t, c.barycentric, side > 0 ? n : Vec3(-n)));
        held_face_.push_back(0);
      }
      continue;
    }
    // No inside, or a short fold: shorten the curve (contour minimisation).
    const Vec3 p = c.barycentric[0] * x[at(t[0])] + c.barycentric[1] * x[at(t[1])] + c.barycentric[2] * x[at(t[2])];
    const Vec3 along = x[at(ed[1])] - x[at(ed[0])];
    if (along.norm() == 0) continue;
    const Vec3 e = along.normalized();
    const Scalar en = e.dot(n);
    Vec3 g = Vec3::Zero();
    for (Index f : topo.edge_faces()[c.edge]) {
      const Face& face = topo.face(f);
      const Vec3 m = unit_normal(face, x);
      Vec3 r = n.cross(m);
      if (m == Vec3::Zero() || r.norm() == 0) continue;
      r.normalize();
      Index opposite = face[0];
      for (Index v : face) {
        if (v != ed[0] && v != ed[1]) opposite = v;
      }
      Vec3 into = x[at(opposite)] - p;
      into -= into.dot(e) * e;
      if (r.dot(into) < 0) r = -r;
      g += std::abs(en) > 1e-3 ? Vec3(r - (e.dot(r) / en) * n) : r;
    }
    if (!(g.norm() > 0) || !g.allFinite()) continue;
    Shift s;
    s.vertex = {ed[0], ed[1], t[0], t[1], t[2]};
    s.direction = g.normalized();
    const bool border_end = !k.pinches.empty() && topo.edge_faces()[c.edge].size() == 1;
    s.step = border_end ? options_.border_step : options_.contour_step;
    shifts_.push_back(s);
  }
  return analysis_.pairs;
}

Stencil Untangler::acting_pull(std::size_t p) const {
  // A pull of a band moves the inside end alone (its stencil cut to the vertex; the gap is
  // still measured to the face), and removes that end's own velocity against the pull.
  Stencil s = pulls_[p];
  if (held_face_[p]) s.count = 1;
  return s;
}

Scalar Untangler::pull_impulse(std::size_t p, const Stencil& s, std::span<const Scalar> inv_mass,
                               PositionsView x) const {
  const Scalar gap = relative_normal(pulls_[p], x);
  const Scalar denom = inverse_effective_mass(s, inv_mass);
  if (!(denom > 0) || !(gap < options_.thickness)) return 0;
  return std::min(options_.thickness - gap, options_.max_step) / denom;
}

std::size_t Untangler::pull_moves(std::span<const Scalar> inv_mass, PositionsView x, std::vector<PullMove>& out) const {
  std::size_t count = 0;
  for (std::size_t p = 0; p < pulls_.size(); ++p) {
    const Stencil s = acting_pull(p);
    const Scalar mu = pull_impulse(p, s, inv_mass, x);
    if (!(mu > 0)) continue;
    for (int k = 0; k < s.count; ++k) {
      const Index i = s.vertex[at(k)];
      const Scalar move = s.weight[at(k)] * inv_mass[at(i)] * mu;
      if (move != 0) out.push_back({i, s.normal, move});
    }
    ++count;
  }
  return count;
}

UntangleStats Untangler::apply(std::span<const Scalar> inv_mass, std::span<Vec3> x, std::span<Vec3> v,
                               bool pulls_moved) const {
  UntangleStats stats;
  for (std::size_t p = 0; p < pulls_.size(); ++p) {
    const Stencil s = acting_pull(p);
    const Scalar mu = pulls_moved ? 0 : pull_impulse(p, s, inv_mass, x);
    if (mu > 0) {
      for (int k = 0; k < s.count; ++k) {
        const Index i = s.vertex[at(k)];
        x[at(i)] += (s.weight[at(k)] * inv_mass[at(i)] * mu) * s.normal;
      }
      ++stats.pulls;
    }
    correct_velocity(s, inv_mass, v);
  }
  for (const Shift& s : shifts_) {
    if (!(s.step > 0)) continue;
    bool moved = false;
    for (int k = 0; k < 5; ++k) {
      const Index i = s.vertex[at(k)];
      if (inv_mass[at(i)] == 0) continue;
      const Vec3 d = k < 2 ? Vec3(s.direction) : Vec3(-s.direction);
      x[at(i)] += s.step * d;
      // The move is kept: a velocity against it would undo it at the next step.
      const Scalar back = v[at(i)].dot(d);
      if (back < 0) v[at(i)] -= back * d;
      moved = true;
    }
    stats.contour_moves += moved ? 1 : 0;
  }
  return stats;
}

}  // namespace crumple::response

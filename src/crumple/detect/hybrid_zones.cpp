// The hybrid detector's leaves and zones (hybrid_detail.hpp): patches grown over the face
// adjacency, each frame's leaf boxes, the zones (overlapping leaf pairs) merged across frames and
// ordered for examination, the kept pairs filed under their zones, and the risk report.

#include <crumple/detect/hybrid_detail.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace crumple {

using hybrid_detail::due;
using hybrid_detail::kEE;
using hybrid_detail::kEF;
using hybrid_detail::kVF;
using hybrid_detail::pair_key;
using hybrid_detail::volume;

void HybridDetector::Impl::build(const Topology& topo, int leaf_size) {
  const Index nf = topo.num_faces();
  face_leaf.assign(static_cast<std::size_t>(nf), -1);
  leaf_faces = {};
  // Patches grown breadth-first over edge-adjacent faces, seeded next to the last patch (so
  // patches tile the surface compactly), else at the lowest unassigned face.
  std::vector<Index> queue, frontier;
  Index next_seed = 0;
  Index leaf = 0;
  while (true) {
    Index seed = -1;
    while (!frontier.empty() && seed < 0) {
      const Index f = frontier.back();
      frontier.pop_back();
      if (face_leaf[static_cast<std::size_t>(f)] < 0) seed = f;
    }
    if (seed < 0) {
      while (next_seed < nf && face_leaf[static_cast<std::size_t>(next_seed)] >= 0) ++next_seed;
      if (next_seed == nf) break;
      seed = next_seed;
    }
    queue.assign(1, seed);
    face_leaf[static_cast<std::size_t>(seed)] = leaf;
    std::size_t head = 0;
    int count = 1;
    std::vector<Index> left_over;
    while (head < queue.size()) {
      const Index f = queue[head++];
      leaf_faces.data.push_back(f);
      for (const Index e : topo.face_edges(f)) {
        for (const Index g : topo.edge_faces()[e]) {
          if (face_leaf[static_cast<std::size_t>(g)] >= 0) continue;
          if (count < leaf_size) {
            face_leaf[static_cast<std::size_t>(g)] = leaf;
            queue.push_back(g);
            ++count;
          } else {
            left_over.push_back(g);
          }
        }
      }
    }
    leaf_faces.end_row();
    // Seeds for the next patches: the faces this one could not take, nearest last.
    frontier.insert(frontier.end(), left_over.rbegin(), left_over.rend());
    ++leaf;
  }
  const Index nl = leaf;
  vertex_owner.assign(static_cast<std::size_t>(topo.num_vertices()), -1);
  for (Index v = 0; v < topo.num_vertices(); ++v) {
    const auto faces = topo.vertex_faces()[v];
    if (!faces.empty()) vertex_owner[static_cast<std::size_t>(v)] = face_leaf[static_cast<std::size_t>(faces[0])];
  }
  edge_owner.assign(static_cast<std::size_t>(topo.num_edges()), -1);
  for (Index e = 0; e < topo.num_edges(); ++e) {
    const auto faces = topo.edge_faces()[e];
    if (!faces.empty()) edge_owner[static_cast<std::size_t>(e)] = face_leaf[static_cast<std::size_t>(faces[0])];
  }
  leaf_verts = {};
  owned_verts = {};
  owned_edges = {};
  std::vector<Index> mark(static_cast<std::size_t>(topo.num_vertices()), -1);
  std::vector<Index> emark(static_cast<std::size_t>(topo.num_edges()), -1);
  for (Index l = 0; l < nl; ++l) {
    for (const Index f : leaf_faces[l]) {
      for (const Index v : topo.face(f)) {
        if (mark[static_cast<std::size_t>(v)] == l) continue;
        mark[static_cast<std::size_t>(v)] = l;
        leaf_verts.data.push_back(v);
        if (vertex_owner[static_cast<std::size_t>(v)] == l) owned_verts.data.push_back(v);
      }
      for (const Index e : topo.face_edges(f)) {
        if (emark[static_cast<std::size_t>(e)] == l) continue;
        emark[static_cast<std::size_t>(e)] = l;
        if (edge_owner[static_cast<std::size_t>(e)] == l) owned_edges.data.push_back(e);
      }
    }
    leaf_verts.end_row();
    owned_verts.end_row();
    owned_edges.end_row();
  }
  boxes.assign(static_cast<std::size_t>(nl), Box::empty());
  previous_boxes = boxes;
  motion.assign(static_cast<std::size_t>(nl), 0);
  near_factor.assign(static_cast<std::size_t>(nl), 2);
  leaf_zones.assign(static_cast<std::size_t>(nl), 0);
  face_box.assign(static_cast<std::size_t>(nf), Box::empty());
  face_box_gen.assign(static_cast<std::size_t>(nf), 0);
  edge_box.assign(static_cast<std::size_t>(topo.num_edges()), Box::empty());
  edge_box_gen.assign(static_cast<std::size_t>(topo.num_edges()), 0);
  box_gen = 0;
}

void HybridDetector::Impl::refit_leaves(PositionsView previous, PositionsView x, Scalar h, double near) {
  const bool has_previous = !previous.empty();
  const Index nl = static_cast<Index>(leaf_faces.offsets.size() - 1);
  for (Index l = 0; l < nl; ++l) {
    Box b = Box::empty(), pb = Box::empty();
    Scalar move2 = 0;
    for (const Index v : leaf_verts[l]) {
      const Vec3& p = x[static_cast<std::size_t>(v)];
      b.grow(p);
      if (has_previous) {
        const Vec3& q = previous[static_cast<std::size_t>(v)];
        pb.grow(q);
        move2 = std::max(move2, (p - q).squaredNorm());
      }
    }
    const auto i = static_cast<std::size_t>(l);
    const Scalar move = std::sqrt(move2);
    motion[i] = move;
    near_factor[i] = near > 0 ? near : std::clamp<Scalar>(h > 0 ? 1 + 2 * move / h : 2, 2, 8);
    previous_boxes[i] = has_previous ? pb : b;
    if (has_previous) b.merge(pb);
    b.inflate(0.5 * near_factor[i] * h + move);
    boxes[i] = b;
  }
  if (++box_gen == 0) {
    std::fill(face_box_gen.begin(), face_box_gen.end(), 0);
    std::fill(edge_box_gen.begin(), edge_box_gen.end(), 0);
    box_gen = 1;
  }
}

std::vector<HybridDetector::Impl::Kept> HybridDetector::Impl::merge_zones() {
  tree.build(boxes);
  tree.pairs(zone_keys);
  std::sort(zone_keys.begin(), zone_keys.end());
  std::vector<Zone> merged;
  merged.reserve(zone_keys.size());
  {
    std::size_t j = 0, k = 0;
    for (const std::uint64_t key : zone_keys) {
      Zone z;
      z.a = static_cast<Index>(key >> 32);
      z.b = static_cast<Index>(key & 0xffffffffu);
      while (j < zones.size() && zones[j].key() < key) ++j;
      if (j < zones.size() && zones[j].key() == key) {
        z.age = zones[j].age + 1;
        z.never = zones[j].never;
        z.contacts = zones[j].contacts;
      } else {
        z.age = 1;
      }
      while (k < kept.size() && kept[k].zone < key) ++k;  // pairs of vanished zones are dropped
      z.kept_begin = k;
      while (k < kept.size() && kept[k].zone == key) ++k;
      z.kept_end = k;
      merged.push_back(z);
    }
  }
  zones.swap(merged);
  std::fill(leaf_zones.begin(), leaf_zones.end(), 0);
  for (const Zone& z : zones) {
    ++leaf_zones[static_cast<std::size_t>(z.a)];
    if (z.a != z.b) ++leaf_zones[static_cast<std::size_t>(z.b)];
  }
  std::vector<Kept> old_kept;
  old_kept.swap(kept);
  return old_kept;
}

std::vector<std::size_t> HybridDetector::Impl::schedule(Scalar h, bool has_previous, int every) {
  // Priority: contacts at the last examination first, then closeness and approach speed.
  for (Zone& z : zones) {
    const Box& A = boxes[static_cast<std::size_t>(z.a)];
    const Box& B = boxes[static_cast<std::size_t>(z.b)];
    double closeness = 0, approach = 0;
    if (z.a == z.b) {  // a folded patch: its box is thick for its size
      const Scalar r = 0.5 * near_factor[static_cast<std::size_t>(z.a)] * h + motion[static_cast<std::size_t>(z.a)];
      Scalar lo = std::numeric_limits<Scalar>::infinity(), hi = 0;
      for (std::size_t k = 0; k < 3; ++k) {
        lo = std::min(lo, A.hi[k] - A.lo[k] - 2 * r);
        hi = std::max(hi, A.hi[k] - A.lo[k]);
      }
      closeness = hi > 0 ? std::clamp<double>(lo / hi, 0, 1) : 0;
    } else {
      Box inter = A;
      for (std::size_t k = 0; k < 3; ++k) {
        inter.lo[k] = std::max(A.lo[k], B.lo[k]);
        inter.hi[k] = std::min(A.hi[k], B.hi[k]);
      }
      const Scalar small = std::min(volume(A), volume(B));
      closeness = small > 0 ? std::clamp<double>(volume(inter) / small, 0, 1) : 1;
      if (has_previous && h > 0) {
        const Box& pA = previous_boxes[static_cast<std::size_t>(z.a)];
        const Box& pB = previous_boxes[static_cast<std::size_t>(z.b)];
        Vec3 d, rel;
        for (int k = 0; k < 3; ++k) {
          const auto u = static_cast<std::size_t>(k);
          d[k] = 0.5 * ((B.lo[u] + B.hi[u]) - (A.lo[u] + A.hi[u]));
          rel[k] = 0.5 * ((B.lo[u] + B.hi[u]) - (pB.lo[u] + pB.hi[u]) - (A.lo[u] + A.hi[u]) + (pA.lo[u] + pA.hi[u]));
        }
        const Scalar len = d.norm();
        if (len > 0) approach = std::clamp<double>(-d.dot(rel) / len / h, 0, 4);
      }
    }
    z.score = 10.0 * z.contacts + 4 * closeness + approach;
  }
  std::vector<std::size_t> order(zones.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) {
    const Zone& a = zones[i];
    const Zone& b = zones[j];
    const bool da = due(a, every), db = due(b, every);
    if (da != db) return da;
    if (da) {
      if (a.never != b.never) return a.never;
      if (a.age != b.age) return a.age > b.age;
    }
    return a.score > b.score;
  });
  return order;
}

void HybridDetector::Impl::keep_pairs(const std::vector<Kept>& carried) {
  kept.clear();
  const auto file = [&](int type, const std::vector<PrimitivePair>& pairs) {
    for (const PrimitivePair& p : pairs) kept.push_back({zone_of(type, p), static_cast<std::uint8_t>(type), p});
  };
  file(kEE, ee.near_pairs());
  file(kEE, ee.walking_pairs());
  file(kVF, vf.near_pairs());
  file(kVF, vf.walking_pairs());
  file(kEF, ef.near_pairs());
  file(kEF, ef.walking_pairs());
  kept.insert(kept.end(), carried.begin(), carried.end());
  std::sort(kept.begin(), kept.end());
  kept.erase(std::unique(kept.begin(), kept.end()), kept.end());
}

HybridDetector::Impl::Risk HybridDetector::Impl::report(const ContactSet& out, int every) {
  const auto count = [&](Index la, Index lb) {
    if (la < 0 || lb < 0) return;
    const std::ptrdiff_t i = find_zone(pair_key(std::min(la, lb), std::max(la, lb)));
    if (i >= 0) ++zones[static_cast<std::size_t>(i)].found;
  };
  const auto at = [](const std::vector<Index>& owner, Index i) { return owner[static_cast<std::size_t>(i)]; };
  for (const auto& c : out.vf) count(at(vertex_owner, c.vertex), at(face_leaf, c.face));
  for (const auto& c : out.ee) count(at(edge_owner, c.edge0), at(edge_owner, c.edge1));
  for (const auto& c : out.tt) count(at(face_leaf, c.face0), at(face_leaf, c.face1));
  double est_missed = 0;
  int oldest = 0;
  std::size_t due_left = 0;
  infos.clear();
  for (Zone& z : zones) {
    if (z.examined) {
      z.age = 0;
      z.never = false;
      z.contacts = z.found;
    } else {
      est_missed += std::max(0, z.contacts - z.found);
      oldest = std::max(oldest, z.age);
      due_left += due(z, every) ? 1 : 0;
    }
    infos.push_back({z.a, z.b, z.age, z.examined, z.contacts});
  }
  return {est_missed, oldest, due_left};
}

}  // namespace crumple

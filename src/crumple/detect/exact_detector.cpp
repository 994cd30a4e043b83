#include <crumple/core/parallel.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/exact_detector.hpp>
#include <crumple/detect/gather.hpp>
#include <crumple/detect/narrow_phase.hpp>
#include <crumple/geometry/separation.hpp>
#include <crumple/geometry/triangle_intersection.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <string>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

namespace crumple {

namespace {

/// The vertex-face sub-pairs of a candidate face pair, indexed by `mask_a | mask_b << 3` (bit k
/// of each: the face owns corner k, and it lies in the other face's box): codes `side << 2 | k`
/// (side 0: corner k of the first face against the second face; side 1: the other way round),
/// with their counts. Unused codes are 0. The codes are 16-bit and the rows padded to 8, so that
/// listing a candidate's codes is one vector operation (8-bit codes, widened one by one, cost a
/// stall each).
struct VertexFaceTable {
  std::array<std::array<std::uint16_t, 8>, 64> codes{};
  std::array<std::uint8_t, 64> count{};
  constexpr VertexFaceTable() {
    for (unsigned key = 0; key < 64; ++key) {
      const unsigned ma = key & 7u, mb = key >> 3;
      unsigned n = 0;
      for (unsigned k = 0; k < 3; ++k) {
        if (ma >> k & 1u) codes[key][n++] = static_cast<std::uint16_t>(k);
        if (mb >> k & 1u) codes[key][n++] = static_cast<std::uint16_t>(4u | k);
      }
      count[key] = static_cast<std::uint8_t>(n);
    }
  }
};
constexpr VertexFaceTable kVertexFace{};

/// The edge-edge sub-pairs of a candidate face pair, indexed by a 9-bit mask (bit 3i + j: side i
/// of the first face and side j of the second are both owned and their boxes meet): codes
/// `i << 2 | j`, with their counts, rows padded to 16 as above.
struct EdgeEdgeTable {
  std::array<std::array<std::uint16_t, 16>, 512> codes{};
  std::array<std::uint8_t, 512> count{};
  constexpr EdgeEdgeTable() {
    for (unsigned m = 0; m < 512; ++m) {
      unsigned n = 0;
      for (unsigned b = 0; b < 9; ++b) {
        if (m >> b & 1u) codes[m][n++] = static_cast<std::uint16_t>((b / 3) << 2 | b % 3);
      }
      count[m] = static_cast<std::uint8_t>(n);
    }
  }
};
constexpr EdgeEdgeTable kEdgeEdge{};

/// Four float lanes (GCC's vector extensions: SSE on x86-64 without asking for more).
using F4 = float __attribute__((vector_size(16)));
using I4 = std::int32_t __attribute__((vector_size(16)));

__attribute__((always_inline)) inline F4 load4(const std::array<float, 4>& a) {
  F4 v;
  std::memcpy(&v, a.data(), sizeof v);
  return v;
}
/// Bit l set: lane l of v is true (all ones), for the lanes 0-2.
__attribute__((always_inline)) inline unsigned lanes3(const I4& v) {
#if defined(__SSE__)
  return static_cast<unsigned>(__builtin_ia32_movmskps(std::bit_cast<F4>(v))) & 7u;
#else
  return (v[0] != 0 ? 1u : 0u) | (v[1] != 0 ? 2u : 0u) | (v[2] != 0 ? 4u : 0u);
#endif
}
/// 1 when every lane of v is true (all ones), else 0.
__attribute__((always_inline)) inline unsigned all_lanes(const I4& v) {
#if defined(__SSE__)
  return (static_cast<unsigned>(__builtin_ia32_movmskps(std::bit_cast<F4>(v))) + 1) >> 4;
#else
  return (v[0] != 0) & (v[1] != 0) & (v[2] != 0) & (v[3] != 0) ? 1u : 0u;
#endif
}
__attribute__((always_inline)) inline F4 min4(const F4& a, const F4& b) { return a < b ? a : b; }
__attribute__((always_inline)) inline F4 max4(const F4& a, const F4& b) { return a > b ? a : b; }
template <int L>
__attribute__((always_inline)) inline F4 lane(const F4& v) {
  return __builtin_shufflevector(v, v, L, L, L, L);
}

/// A face's corners rounded to float (`coarse_coordinate`), axis by axis: coordinate d of
/// corner k in lane k of axes[d], and of corner 0 again in lane 3; from the corners' (x, y, z,
/// 0) lanes.
using CoarseAxes = std::array<F4, 3>;
__attribute__((always_inline)) inline CoarseAxes coarse_axes(const F4& c0, const F4& c1, const F4& c2) {
  const F4 xy = __builtin_shufflevector(c0, c1, 0, 4, 1, 5);  // x0 x1 y0 y1
  const F4 zz = __builtin_shufflevector(c0, c1, 2, 6, 2, 6);  // z0 z1 z0 z1
  return {__builtin_shufflevector(xy, c2, 0, 1, 4, 0), __builtin_shufflevector(xy, c2, 2, 3, 5, 2),
          __builtin_shufflevector(zz, c2, 0, 1, 6, 0)};
}

/// The box rejections of a candidate face pair's sub-pairs, in float lanes on the faces'
/// corners rounded to float (`coarse_axes`). `vf`: bit k, corner k of the first face lies in
/// the second face's box padded by `pad` (bit 3 + k: corner k of the second in the first's
/// box); `ee`: bit 3i + j, the boxes of side i of the first face and side j of the second, each
/// padded by `half`, meet. The pads must cover the float rounding (`coarse_pad`), so that these
/// boxes hold the exact ones: a bit that is 0 is a sub-pair beyond the padded thickness. NaN: 0.
struct CoarseMasks {
  unsigned vf = 0, ee = 0;
};
__attribute__((always_inline)) inline CoarseMasks coarse_masks(const CoarseAxes& a, const CoarseAxes& b, float half,
                                                               float pad) {
  I4 in_a = {-1, -1, -1, -1}, in_b = in_a, meet0 = in_a, meet1 = in_a, meet2 = in_a;
  for (std::size_t d = 0; d < 3; ++d) {
    const F4 ca = a[d], cb = b[d];
    // Side k joins corners k and k + 1.
    const F4 na = __builtin_shufflevector(ca, ca, 1, 2, 0, 3), nb = __builtin_shufflevector(cb, cb, 1, 2, 0, 3);
    const F4 alo = min4(ca, na) - half, ahi = max4(ca, na) + half;
    const F4 blo = min4(cb, nb) - half, bhi = max4(cb, nb) + half;
    meet0 &= (lane<0>(alo) <= bhi) & (blo <= lane<0>(ahi));
    meet1 &= (lane<1>(alo) <= bhi) & (blo <= lane<1>(ahi));
    meet2 &= (lane<2>(alo) <= bhi) & (blo <= lane<2>(ahi));
    // The faces' boxes, in every lane (lane 3 repeats corner 0).
    const auto least = [](const F4& v) {
      const F4 m = min4(v, __builtin_shufflevector(v, v, 2, 3, 0, 1));
      return min4(m, __builtin_shufflevector(m, m, 1, 0, 3, 2));
    };
    const auto most = [](const F4& v) {
      const F4 m = max4(v, __builtin_shufflevector(v, v, 2, 3, 0, 1));
      return max4(m, __builtin_shufflevector(m, m, 1, 0, 3, 2));
    };
    in_a &= (least(cb) - pad <= ca) & (ca <= most(cb) + pad);
    in_b &= (least(ca) - pad <= cb) & (cb <= most(ca) + pad);
  }
  return {lanes3(in_a) | lanes3(in_b) << 3, lanes3(meet0) | lanes3(meet1) << 3 | lanes3(meet2) << 6};
}

/// A pad for `coarse_masks` that covers the float rounding of coordinates up to `extent` in
/// magnitude: the boxes it pads then hold the exact ones padded by `pad`. Corners are rounded
/// by at most u * extent (u = 2^-24), and a box's bound once more by u of itself: (pad + 3u
/// extent) / (1 - u) is enough, rounded up to a float; 8u is used.
float coarse_pad(Scalar pad, Scalar extent) {
  constexpr Scalar u = 0x1p-24;
  const Scalar wide = (pad + 8 * u * extent) * (1 + 8 * u) + 1e-37;
  auto f = static_cast<float>(wide);
  if (static_cast<Scalar>(f) < wide) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

/// c rounded to float, for the float-lane box tests; beyond the float range clamped to it (the
/// tests are then off: `coarse_pad`'s caller gives infinite pads).
inline float coarse_coordinate(Scalar c) {
  constexpr Scalar kMax = std::numeric_limits<float>::max();
  return static_cast<float>(std::clamp(c, -kMax, kMax));
}

/// Sorts `items` by major(item) in [0, majors), then `minor_less` within a major: a counting
/// sort on the major, then a sort of each major's few items: for the set-up's lists of hundreds
/// of thousands of items keyed by a vertex, a face or an edge (their `std::sort`s were 76 of
/// cloth-ball's 220 ms of set-up). With no two items equal under (major, minor_less), the order
/// is the one `std::sort` gives.
template <class T, class Major, class MinorLess>
void sort_by_major(std::vector<T>& items, std::size_t majors, const Major& major, const MinorLess& minor_less) {
  std::vector<std::size_t> start(majors + 1, 0);
  for (const T& t : items) ++start[static_cast<std::size_t>(major(t)) + 1];
  for (std::size_t k = 0; k < majors; ++k) start[k + 1] += start[k];
  std::vector<T> out(items.size());
  std::vector<std::size_t> next(start.begin(), start.end() - 1);
  for (const T& t : items) out[next[static_cast<std::size_t>(major(t))]++] = t;
  for (std::size_t k = 0; k < majors; ++k) {
    std::sort(out.begin() + static_cast<std::ptrdiff_t>(start[k]), out.begin() + static_cast<std::ptrdiff_t>(start[k + 1]),
              minor_less);
  }
  items.swap(out);
}

#if CRUMPLE_SEPARATION_LANES
/// Keeps, in order, the codes of list[0, n) that the plane (kLine false) or line (kLine true)
/// test of their points(code) (`geometry::SeparationPoints`) leaves within pad, four at a time
/// (`geometry::beyond_x4`); returns their number. Compiled for AVX2: only where the CPU has it.
template <bool kLine, class Points>
__attribute__((target("avx2"))) std::size_t sift_separated_x4(std::uint16_t* list, std::size_t n, Scalar pad,
                                                              const Points& points) {
  std::size_t kept = 0;
  for (std::size_t s = 0; s < n; s += 4) {
    std::array<std::uint16_t, 4> code;
    std::array<geometry::SeparationPoints, 4> at;
    for (std::size_t l = 0; l < 4; ++l) {
      code[l] = list[std::min(s + l, n - 1)];  // past the end, the last code again (not kept)
      at[l] = points(code[l]);
    }
    const unsigned beyond = geometry::beyond_x4<kLine>(at, pad);
    for (std::size_t l = 0; l < std::min<std::size_t>(4, n - s); ++l) {
      list[kept] = code[l];
      kept += (beyond >> l & 1u) ^ 1u;
    }
  }
  return kept;
}
#endif

/// Contacts found by one chunk of work, kept until the frame's set is gathered.
struct LocalContacts {
  explicit LocalContacts(KeyedContacts&& spare) : keyed(std::move(spare)) {}
  KeyedContacts keyed;
  ContactSet& set = keyed.set;
  std::size_t vf_tests = 0, ee_tests = 0, tt_tests = 0;
  narrow::VertexFaceBatch vf_batch;  ///< vertex-face pairs queued for the kernel, four at a time
  narrow::EdgeEdgeBatch ee_batch;    ///< edge pairs queued for the kernel, four at a time
  narrow::TriangleTriangleBatch tt_batch;  ///< face pairs queued for the intersection test
};

}  // namespace

ExactParams ExactParams::from_spec(const MethodSpec& spec) {
  ExactParams p;
  const long long cap = spec.get_int("max_contacts", 0);
  if (cap < 0) throw InputError("method " + spec.to_string() + ": max_contacts must be >= 0");
  p.max_contacts = static_cast<std::size_t>(cap);
  static constexpr std::array<std::string_view, 2> kOverflow{"error", "truncate"};
  p.overflow_error = spec.get_choice("overflow", "error", kOverflow) == "error";
  return p;
}

ExactDetector::ExactDetector(DetectorOptions options, ExactParams params, std::unique_ptr<BroadPhase> broad_phase)
    : Detector(options), params_(params), broad_phase_(std::move(broad_phase)) {
  CRUMPLE_CHECK(broad_phase_ != nullptr, "ExactDetector: null broad phase");
}

ExactDetector::~ExactDetector() = default;

void ExactDetector::on_topology() {
  const Topology& topo = topology();
  const Index nf = topo.num_faces();
  const Index nv = topo.num_vertices();
  // Ownership: each vertex and edge belongs to one of its faces (bit k of the masks: corner k,
  // side k), so that a candidate face pair tests each feature pair once. Chosen so that many
  // faces own no vertex, and many no edge: a pair of faces of which neither owns a vertex and
  // one owns no edge holds no sub-pair, and a proximity query's broad phase leaves it out
  // (`FrameInput::owns`; 43-46% of the candidates of cloth-ball and rod-twist, against 7-29%
  // when every feature went to its first face).
  //  - Edges: the faces that own none are an independent set, chosen greedily in face order (a
  //    face is left without when each of its edges has another face not left without; those
  //    faces then keep theirs); an edge belongs to its first face that owns edges.
  //  - Vertices: to the first of its faces that owns a vertex already, else that owns edges,
  //    else that has the most corners not yet owned (greedily in vertex order), so that few
  //    faces own vertices, and mostly those that own edges.
  std::vector<std::uint8_t> vertex_mask(static_cast<std::size_t>(nf), 0);
  std::vector<std::uint8_t> edge_mask(static_cast<std::size_t>(nf), 0);
  enum : std::uint8_t { kOpen, kNoEdges, kEdges };
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
  std::vector<std::uint8_t> corners_left(static_cast<std::size_t>(nf), 3);
  isolated_.clear();
  for (Index v = 0; v < nv; ++v) {
    const auto faces = topo.vertex_faces()[v];
    if (faces.empty()) {
      isolated_.push_back(v);
      continue;
    }
    Index f = faces[0];
    int best = -1;
    for (const Index g : faces) {
      const auto i = static_cast<std::size_t>(g);
      const int score = (vertex_mask[i] != 0 ? 100 : 0) + (state(g) != kNoEdges ? 10 : 0) + corners_left[i];
      if (score > best) {
        best = score;
        f = g;
      }
    }
    for (const Index g : faces) --corners_left[static_cast<std::size_t>(g)];
    const Face& t = topo.face(f);
    for (int k = 0; k < 3; ++k) {
      if (t[k] == v) vertex_mask[static_cast<std::size_t>(f)] |= static_cast<std::uint8_t>(1u << k);
    }
  }
  for (Index e = 0; e < topo.num_edges(); ++e) {
    const auto faces = topo.edge_faces()[e];  // one of them owns edges (see above)
    const Index f = *std::find_if(faces.begin(), faces.end(), [&](Index g) { return state(g) != kNoEdges; });
    const auto& fe = topo.face_edges(f);
    for (int k = 0; k < 3; ++k) {
      if (fe[k] == e) edge_mask[static_cast<std::size_t>(f)] |= static_cast<std::uint8_t>(1u << k);
    }
  }
  // Rank of each edge in (first vertex, second vertex) order: the key of the edge-edge gather.
  edge_rank_.resize(static_cast<std::size_t>(topo.num_edges()));
  {
    std::vector<Index> by_vertices(edge_rank_.size());
    std::iota(by_vertices.begin(), by_vertices.end(), 0);
    sort_by_major(
        by_vertices, static_cast<std::size_t>(nv), [&](Index e) { return topo.edge(e)[0]; },
        [&](Index a, Index b) { return topo.edge(a)[1] < topo.edge(b)[1]; });
    for (std::size_t r = 0; r < by_vertices.size(); ++r) {
      edge_rank_[static_cast<std::size_t>(by_vertices[r])] = static_cast<Index>(r);
    }
  }
  // Orphan sub-pairs: owned features of face pairs that share a vertex, not excluded.
  orphan_vf_.clear();
  orphan_ee_.clear();
  for (Index f = 0; f < nf; ++f) {
    const Face& a = topo.face(f);
    const auto& fa = topo.face_edges(f);
    for (Index g : topo.face_faces()[f]) {
      if (g <= f) continue;
      const Face& b = topo.face(g);
      const auto& fb = topo.face_edges(g);
      for (int k = 0; k < 3; ++k) {
        if ((vertex_mask[static_cast<std::size_t>(f)] >> k & 1u) && !topo.face_has_vertex(g, a[k]))
          orphan_vf_.push_back({a[k], g});
        if ((vertex_mask[static_cast<std::size_t>(g)] >> k & 1u) && !topo.face_has_vertex(f, b[k]))
          orphan_vf_.push_back({b[k], f});
      }
      for (int i = 0; i < 3; ++i) {
        if (!(edge_mask[static_cast<std::size_t>(f)] >> i & 1u)) continue;
        for (int j = 0; j < 3; ++j) {
          if (!(edge_mask[static_cast<std::size_t>(g)] >> j & 1u)) continue;
          if (topo.edges_adjacent(fa[i], fb[j])) continue;
          const Index e0 = std::min(fa[i], fb[j]), e1 = std::max(fa[i], fb[j]);
          orphan_ee_.push_back({{e0, e1}, topo.edge(e0), topo.edge(e1)});
        }
      }
    }
  }
  // By (face, vertex) and by (first edge, second edge); no two the same (a feature has one
  // owner, so a sub-pair comes from one pair of faces).
  sort_by_major(
      orphan_vf_, static_cast<std::size_t>(nf), [](const auto& o) { return o[1]; },
      [](const auto& a, const auto& b) { return a[0] < b[0]; });
  sort_by_major(
      orphan_ee_, static_cast<std::size_t>(topo.num_edges()), [](const OrphanEdges& o) { return o.e[0]; },
      [](const OrphanEdges& a, const OrphanEdges& b) { return a.e[1] < b.e[1]; });
  // Orphan blocks, the vertices each uses, and its runs of sub-pairs of the same key(i).
  // (A vertex is listed once per block by marking it with the block's number, then the block's
  // few distinct vertices sorted: sorting every corner of its sub-pairs, then removing the
  // repeats, was 100 of cloth-ball's 220 ms of set-up.)
  std::vector<std::size_t> listed_in(static_cast<std::size_t>(nv), ~std::size_t{0});
  const auto cut = [&listed_in](OrphanBlocks& blocks, std::size_t items, const auto& verts_of, const auto& key) {
    std::fill(listed_in.begin(), listed_in.end(), ~std::size_t{0});
    const std::size_t count = (items + kOrphanBlock - 1) / kOrphanBlock;
    blocks.begin.assign(1, 0);
    blocks.verts.clear();
    blocks.run_begin.assign(1, 0);
    blocks.runs.clear();
    for (std::size_t b = 0; b < count; ++b) {
      const std::size_t first = blocks.verts.size();
      const std::size_t end = std::min(items, (b + 1) * kOrphanBlock);
      for (std::size_t i = b * kOrphanBlock; i < end; ++i) {
        for (const Index v : verts_of(i)) {
          if (std::exchange(listed_in[static_cast<std::size_t>(v)], b) != b) blocks.verts.push_back(v);
        }
        if (i == b * kOrphanBlock || key(i) != key(i - 1)) blocks.runs.push_back(0);
        ++blocks.runs.back();
      }
      blocks.run_begin.push_back(blocks.runs.size());
      std::sort(blocks.verts.begin() + static_cast<std::ptrdiff_t>(first), blocks.verts.end());
      blocks.begin.push_back(blocks.verts.size());
    }
    blocks.bound.assign(count, 0);
    blocks.awake.assign(count, 1);
  };
  cut(
      vf_blocks_, orphan_vf_.size(),
      [&](std::size_t i) {
        const auto [v, g] = orphan_vf_[i];
        const Face& t = topo.face(g);
        return std::array<Index, 4>{v, t[0], t[1], t[2]};
      },
      [&](std::size_t i) { return orphan_vf_[i][1]; });
  cut(
      ee_blocks_, orphan_ee_.size(),
      [&](std::size_t i) {
        const OrphanEdges& o = orphan_ee_[i];
        return std::array<Index, 4>{o.a[0], o.a[1], o.b[0], o.b[1]};
      },
      [&](std::size_t i) { return orphan_ee_[i].e[0]; });
  face_owns_.resize(static_cast<std::size_t>(nf));
  for (std::size_t f = 0; f < face_owns_.size(); ++f) {
    face_owns_[f] = static_cast<std::uint8_t>((vertex_mask[f] != 0 ? 1u : 0u) | (edge_mask[f] != 0 ? 2u : 0u));
  }
  orphan_ref_.clear();
  packed_.assign(static_cast<std::size_t>(nf), PackedFace{});
  for (Index f = 0; f < nf; ++f) {
    PackedFace& pf = packed_[static_cast<std::size_t>(f)];
    pf.v = topo.face(f);
    pf.e = topo.face_edges(f);
    pf.vertex_mask = vertex_mask[static_cast<std::size_t>(f)];
    pf.edge_mask = edge_mask[static_cast<std::size_t>(f)];
  }
  broad_phase_->build(topo);
}

void ExactDetector::detect(PositionsView previous, PositionsView x, ContactSet& out) {
  const int threads = options().threads;
  overflowed_ = false;
  candidates_.clear();

  // Padded thickness (see the file comment of broad_phase.hpp), from the largest coordinate
  // magnitude of the frame, found in the same parallel pass over the positions that rounds them
  // to float for the narrow phase's box tests (a serial pass for the magnitude alone left the
  // second thread idle for 40 us of armadillo's 3.9 ms frame).
  const auto t0 = std::chrono::steady_clock::now();
  // Intersection only: the thickness plays no part, the boxes only need the rounding margin.
  const bool proximity = options().kinds.vf || options().kinds.ee;
  Scalar magnitude = 0;
  {
    if (proximity) coarse_x_.resize(x.size());
    std::mutex mutex;
    parallel_for_chunks(x.size(), threads, 4096, [&](std::size_t begin, std::size_t end) {
      Scalar m = 0;  // std::max keeps m for a NaN
      for (std::size_t v = begin; v < end; ++v) {
        m = std::max(m, x[v].cwiseAbs().maxCoeff());
        if (!previous.empty()) m = std::max(m, previous[v].cwiseAbs().maxCoeff());
        if (proximity) {
          for (std::size_t a = 0; a < 3; ++a) coarse_x_[v][a] = coarse_coordinate(x[v][a]);
          coarse_x_[v][3] = 0;
        }
      }
      const std::lock_guard lock(mutex);
      magnitude = std::max(magnitude, m);
    });
  }
  const Scalar h = options().thickness;
  const Scalar pad = (proximity ? h * (1 + 1e-6) : 0) + 1e-9 * magnitude;

  FrameInput in{previous, x, pad / 2, threads, !proximity, {}};
  if (!options().kinds.tt) in.owns = face_owns_;
  broad_phase_->update(in, stats_);
  broad_phase_->self_pairs(candidates_, stats_);
  stats_.set("candidates", static_cast<double>(candidates_.total()));
  stats_.set("broad_ms", ms_since(t0));

  narrow_phase(x, pad, magnitude, candidates_, out);  // sets narrow_ms and sort_ms
  candidates_.clear();

  const std::size_t total = out.size();
  stats_.set("contacts", static_cast<double>(total));
  if (params_.max_contacts > 0 && total > params_.max_contacts) {
    overflowed_ = true;
    stats_.set("overflow", 1);
    stats_.set("contacts_dropped", static_cast<double>(total - params_.max_contacts));
    if (params_.overflow_error) {
      throw ContactOverflowError("exact detector: " + std::to_string(total) +
                                 " contacts exceed max_contacts=" +
                                 std::to_string(params_.max_contacts));
    }
    // Keep the first max_contacts in canonical order (VF, then EE, then TT; the gather's):
    // deterministic.
    std::size_t keep = params_.max_contacts;
    const auto cut = [&keep](auto& v) {
      if (v.size() > keep) v.resize(keep);
      keep -= v.size();
    };
    cut(out.vf);
    cut(out.ee);
    cut(out.tt);
  } else {
    stats_.set("overflow", 0);
  }
}

bool ExactDetector::wake_orphan_blocks(PositionsView x, Scalar pad, int threads) {
  const auto wake_all = [&] {
    for (OrphanBlocks* set : {&vf_blocks_, &ee_blocks_}) set->awake.assign(set->size(), 1);
  };
  if (orphan_ref_.size() != x.size()) {  // first frame (or new topology): refresh
    wake_all();
    orphan_refreshed_ = true;
    orphan_backoff_ = orphan_wait_ = 0;
    return true;
  }
  if (orphan_wait_ > 0) {  // backing off: every block, no bounds
    --orphan_wait_;
    wake_all();
    return false;
  }
  // Marks every stride-th block; returns how many were woken by the motion, how many are awake
  // (for that or because they hold a pair within pad), and how many were looked at.
  struct Count {
    std::size_t woken = 0, awake = 0, blocks = 0;
  };
  // The check stops once more than a quarter of the blocks it is to look at are woken by the
  // motion, when that decides the frame whatever the rest hold: stale, every flag then set
  // awake (`wake_all` below), as on the deforming scenes, where the first frames after a refresh
  // paid the whole sample (armadillo: 0.5 ms, on one thread at any thread count). That is so for
  // the whole check, and for a sample of at least 64 blocks (a smaller sample decides at half).
  const auto check = [&](std::size_t stride) {
    std::mutex mutex;
    Count count;
    for (const OrphanBlocks* set : {&vf_blocks_, &ee_blocks_}) count.blocks += (set->size() + stride - 1) / stride;
    const bool can_stop = stride == 1 || count.blocks >= 64;
    const std::size_t deciding = count.blocks / 4 + 1;  // woken blocks that make 4 woken > blocks
    std::atomic<std::size_t> woken_so_far{0};
    const auto decided = [&] { return can_stop && woken_so_far.load(std::memory_order_relaxed) >= deciding; };
    for (OrphanBlocks* set : {&vf_blocks_, &ee_blocks_}) {
      OrphanBlocks& bl = *set;
      const std::size_t looked = (bl.size() + stride - 1) / stride;
      if (decided()) break;
      parallel_for_chunks(looked, threads, stride == 1 ? 256 : 32, [&](std::size_t begin, std::size_t end) {
        std::size_t local = 0, local_awake = 0, published = 0;
        for (std::size_t b = begin * stride; b < std::min(end * stride, bl.size()); b += stride) {
          if (b % (16 * stride) == 0) {  // every 16 blocks: publish the woken, stop if decided
            woken_so_far.fetch_add(local - published, std::memory_order_relaxed);
            published = local;
            if (decided()) break;
          }
          // Translated so that the block's first vertex stays put (distances do not change),
          // every vertex has moved by at most `moved`, so every point of its features too, and
          // no distance has dropped by more than twice that. Rounding: the differences are
          // local (the block's extent), their error a few ulps of it.
          const Index* v = bl.verts.data() + bl.begin[b];
          const Index* v_end = bl.verts.data() + bl.begin[b + 1];
          const Vec3 c = x[static_cast<std::size_t>(*v)], c_ref = orphan_ref_[static_cast<std::size_t>(*v)];
          // The loop stops at the first vertex that moved by more than half the block's margin
          // over pad, `reach`: the block is awake (on a frame where everything moves, the first
          // few vertices decide), and at once for a block that holds a pair within pad, awake
          // whatever the motion. A NaN coordinate, now or then, stops it too, awake (a maximum
          // by `<` would skip a NaN, and with the first vertex NaN every difference is NaN: the
          // block counted unmoved while its finite vertices may have closed in).
          const Scalar reach = (bl.bound[b] - pad) / 2;
          const Scalar reach2 = reach > 0 ? reach * reach : -1;
          Scalar moved2 = 0, extent2 = 0;
          for (; v != v_end; ++v) {
            const Vec3 now = x[static_cast<std::size_t>(*v)] - c;
            const Vec3 then = orphan_ref_[static_cast<std::size_t>(*v)] - c_ref;
            const Scalar d2 = (now - then).squaredNorm();
            if (!(d2 <= reach2)) {  // NaN too
              moved2 = std::numeric_limits<Scalar>::infinity();
              break;
            }
            moved2 = std::max(moved2, d2);
            extent2 = std::max({extent2, now.squaredNorm(), then.squaredNorm()});
          }
          const Scalar moved = std::sqrt(moved2) * (1 + 1e-12) + 1e-12 * std::sqrt(extent2);
          // Awake unless provably beyond pad (NaN: awake).
          const bool awake = !(bl.bound[b] - 2 * moved > pad);
          bl.awake[b] = awake ? 1 : 0;
          local += awake & (bl.bound[b] > pad);
          local_awake += awake ? 1u : 0u;
        }
        woken_so_far.fetch_add(local - published, std::memory_order_relaxed);
        const std::lock_guard lock(mutex);
        count.woken += local;
        count.awake += local_awake;
      });
    }
    return count;
  };
  // A sample first, every 16th block or about 256 blocks if that is fewer (on cloth-ball, its
  // 940 blocks cost 0.9 ms of cache misses, one thread): when most of those are woken by the
  // motion, the frame is stale without looking at the others. So it is, from a sample of at
  // least 64 blocks, when more than a quarter of them are (the threshold below); and when nearly
  // all of such a sample are awake, for whatever reason, every block is tested: looking at the
  // others would cost about what their sleep saves (on cloth-ball and rod-twist, whose blocks
  // are all tested).
  const std::size_t stride = std::max<std::size_t>(16, (vf_blocks_.size() + ee_blocks_.size()) / 256);
  Count count = check(stride);
  const bool sampled = count.blocks >= 64;
  const bool partial = 2 * count.woken > count.blocks ||
                       (sampled && (4 * count.woken > count.blocks || 8 * count.awake > 7 * count.blocks));
  if (!partial) count = check(1);
  stats_.set("orphan_sampled", partial ? 1 : 0);
  const std::size_t woken = count.woken, blocks = count.blocks;
  // Blocks that hold a pair within pad are awake whatever the motion; when the motion wakes more
  // than a quarter of the others, the bounds are stale: refresh, unless the previous frame was
  // a refresh already (the motion per frame is then too large for the bounds to pay): wait 1,
  // 2, 4, ... 64 frames, testing every block, before trying again.
  const bool stale = 4 * woken > blocks;
  if (!stale) {
    if (partial) wake_all();  // only the sample's flags are this frame's
    if (orphan_refreshed_) orphan_backoff_ = 0;
    orphan_refreshed_ = false;
    return false;
  }
  wake_all();
  if (orphan_refreshed_) {
    orphan_backoff_ = std::min(64, std::max(1, 2 * orphan_backoff_));
    orphan_wait_ = orphan_backoff_;
    orphan_refreshed_ = false;
    return false;
  }
  orphan_refreshed_ = true;
  return true;
}

void ExactDetector::narrow_phase(PositionsView x, Scalar pad, Scalar magnitude, const CandidateBuffer& candidates,
                                 ContactSet& out) {
  const Topology& topo = topology();
  const int threads = options().threads;
  const Scalar h = options().thickness;
  const Scalar h2 = h * h;
  const ContactKinds kinds = options().kinds;
  const std::size_t nf = static_cast<std::size_t>(topo.num_faces());
  const Scalar half = pad / 2;
  const auto narrow_start = std::chrono::steady_clock::now();

  const bool proximity = kinds.vf || kinds.ee;
  // The corners rounded to float, for the box rejections in float lanes (`detect`).
  CRUMPLE_ASSERT(!proximity || coarse_x_.size() == x.size());
  const auto coarse_point = [&](Index v) { return load4(coarse_x_[static_cast<std::size_t>(v)]); };
  // Corner k of face t, at x.
  const auto corner = [&](const PackedFace& t, std::size_t k) -> const Vec3& { return narrow::at(x, t.v[k]); };
  if (kinds.tt) {
    face_corners_.resize(nf);
    parallel_for_chunks(nf, threads, balanced_grain(nf, threads, 512, 4096), [&](std::size_t begin, std::size_t end) {
      for (std::size_t f = begin; f < end; ++f) {
        for (std::size_t k = 0; k < 3; ++k) face_corners_[f][k] = corner(packed_[f], k);
      }
    });
  }
  // The box rejections of the candidates (`coarse_masks`) and of the orphans, in float lanes,
  // unless the coordinates or the pad are too large for floats (or NaN): then infinite pads,
  // no box rejects, and the plane and line tests and the kernels decide alone.
  const bool coarse = magnitude <= 1e30 && pad <= 1e30;
  constexpr float kNoPad = std::numeric_limits<float>::infinity();
  const float coarse_half = coarse ? coarse_pad(half, magnitude) : kNoPad;
  const float coarse_full = coarse ? coarse_pad(pad, magnitude) : kNoPad;

  std::mutex mutex;
  std::size_t vf_tests = 0, ee_tests = 0, tt_tests = 0;
  std::vector<KeyedContacts> parts;  // each chunk's contacts, gathered in order at the end
  // A contact's key: its place in canonical order (`detail::gather_sorted`). Edge-edge contacts
  // are ordered by their first edge's vertices, then the second's: by the edges' ranks in that
  // order.
  const auto pair_key = [](Index first, Index second) {
    return static_cast<std::uint64_t>(first) << 32 | static_cast<std::uint32_t>(second);
  };
  const auto rank = [&](Index edge) { return edge_rank_[static_cast<std::size_t>(edge)]; };
  // Lists the keys of a chunk's contacts, so that the gather reads 8 bytes a contact before the
  // copy instead of the whole record (a frame's contacts are tens of MB, and the gather is
  // bound by memory traffic). (Listed block by block while the records were in this thread's
  // cache instead: no faster.)
  const auto list_keys = [&](KeyedContacts& part) {
    const auto list = [](const auto& records, std::vector<std::uint64_t>& keys, const auto& key) {
      keys.resize(records.size());
      for (std::size_t i = 0; i < records.size(); ++i) keys[i] = key(records[i]);
    };
    list(part.set.vf, part.vf_keys, [&](const VertexFaceContact& c) { return pair_key(c.vertex, c.face); });
    list(part.set.ee, part.ee_keys, [&](const EdgeEdgeContact& c) { return pair_key(rank(c.edge0), rank(c.edge1)); });
    list(part.set.tt, part.tt_keys, [&](const TriangleTriangleContact& c) { return pair_key(c.face0, c.face1); });
  };
  const auto merge = [&](LocalContacts& local) {
    local.vf_batch.flush(h2, local.set.vf);
    local.ee_batch.flush(h2, local.set.ee);
    local.tt_batch.flush(local.set.tt);
    list_keys(local.keyed);
    const std::lock_guard lock(mutex);
    if (!local.set.empty()) {
      parts.push_back(std::move(local.keyed));
    } else {
      spare_sets_.give(std::move(local.keyed));
    }
    vf_tests += local.vf_tests;
    ee_tests += local.ee_tests;
    tt_tests += local.tt_tests;
  };
  // Vertex v at p against face g, past the cheap rejections: the shared kernel, queued four at
  // a time (the contacts reach local.set.vf at the latest in `merge`), unless the squared
  // distance is wanted.
  const auto vf_kernel = [&](const Vec3& p, Index v, const Vec3& a, const Vec3& b, const Vec3& c, Index g,
                             LocalContacts& local, Scalar* sqr_distance = nullptr) {
    ++local.vf_tests;
    if (sqr_distance == nullptr) {
      local.vf_batch.push(v, p, g, a, b, c, h2, local.set.vf);
    } else if (auto contact = narrow::vertex_face(v, p, g, a, b, c, h2, sqr_distance)) {
      local.set.vf.push_back(*contact);
    }
  };
  // The box of face t padded by pad holds p (branch-free; NaN: it does not), in two steps that
  // the orphans' sift takes apart to bound a face once for several points.
  using Bounds = std::array<Vec3, 2>;  // lo, hi
  const auto padded_face_box = [&](const PackedFace& t) {
    const Vec3 &a = corner(t, 0), &b = corner(t, 1), &c = corner(t, 2);
    Bounds box;
    for (int i = 0; i < 3; ++i) {
      box[0][i] = std::min({a[i], b[i], c[i]}) - pad;
      box[1][i] = std::max({a[i], b[i], c[i]}) + pad;
    }
    return box;
  };
  const auto inside = [](const Vec3& p, const Bounds& box) {
    bool outside = false;
    for (int i = 0; i < 3; ++i) outside |= !(box[0][i] <= p[i]) | !(p[i] <= box[1][i]);
    return !outside;
  };
  const auto in_box = [&](const Vec3& p, const PackedFace& t) { return inside(p, padded_face_box(t)); };
  // The gap between p and the box of face t (negative inside; in_box: not beyond pad), as a
  // lower bound of their distance (rounded down by 1e-12 of itself).
  const auto vertex_box_gap = [&](const Vec3& p, const PackedFace& t) {
    const Vec3 &c0 = corner(t, 0), &c1 = corner(t, 1), &c2 = corner(t, 2);
    Scalar gap = -std::numeric_limits<Scalar>::infinity();
    for (int a = 0; a < 3; ++a) {
      gap = std::max({gap, std::min({c0[a], c1[a], c2[a]}) - p[a], p[a] - std::max({c0[a], c1[a], c2[a]})});
    }
    return gap * (1 - 1e-12);
  };
  // Edge e0 = (p0, p1) of vertices (u0, u1) and edge e1 = (q0, q1) of vertices (w0, w1), each
  // in any order, past the cheap rejections: the shared kernel, which sees the edges as the mesh
  // stores them (lower id first, each from its lower vertex), as for every other detector: the
  // same bits. Queued four at a time (the contacts reach local.set.ee at the latest in `merge`),
  // unless the squared distance is wanted.
  const auto ee_kernel = [&](const Vec3& p0, const Vec3& p1, Index u0, Index u1, Index e0, const Vec3& q0,
                             const Vec3& q1, Index w0, Index w1, Index e1, LocalContacts& local,
                             Scalar* sqr_distance = nullptr) {
    ++local.ee_tests;
    if (sqr_distance == nullptr) {
      local.ee_batch.push(e0, u0, u1, p0, p1, e1, w0, w1, q0, q1, h2, local.set.ee);
    } else if (auto c = narrow::EdgePair::ordered(e0, u0, u1, p0, p1, e1, w0, w1, q0, q1).test(h2, sqr_distance)) {
      local.set.ee.push_back(*c);
    }
  };
  // The gap between the boxes of edges (p0, p1) and (q0, q1) (negative if they overlap: not
  // beyond pad), as a lower bound of their distance.
  const auto edge_box_gap = [](const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1) {
    Scalar gap = -std::numeric_limits<Scalar>::infinity();
    for (int a = 0; a < 3; ++a) {
      const auto [lo0, hi0] = std::minmax(p0[a], p1[a]);
      const auto [lo1, hi1] = std::minmax(q0[a], q1[a]);
      gap = std::max({gap, lo1 - hi0, lo0 - hi1});
    }
    return gap * (1 - 1e-12);
  };
  // Keeps, in order, the codes of list[0, n) for which keep(code) holds; returns their number.
  // Branch-free: which sub-pairs pass a rejection test is unpredictable.
  const auto sift = [](std::uint16_t* list, std::size_t n, const auto& keep) {
    std::size_t kept = 0;
    for (std::size_t s = 0; s < n; ++s) {
      const std::uint16_t code = list[s];
      list[kept] = code;
      kept += keep(code) ? 1u : 0u;
    }
    return kept;
  };
  // Sifts list[0, n) by the plane (kLine false) or line (kLine true) test of points(code)
  // (`geometry::SeparationPoints`): four codes at a time in AVX2 lanes where the CPU has them
  // (the same verdicts; cloth-ball's narrow phase 9-10% faster, one thread).
#if CRUMPLE_SEPARATION_LANES
  const bool lanes = geometry::has_avx2();
#endif
  const auto sift_separated = [&]<bool kLine>(std::bool_constant<kLine>, std::uint16_t* list, std::size_t n,
                                              const auto& points) {
#if CRUMPLE_SEPARATION_LANES
    if (lanes) return sift_separated_x4<kLine>(list, n, pad, points);
#endif
    return sift(list, n, [&](std::uint16_t code) {
      const geometry::SeparationPoints q = points(code);
      return !geometry::beyond(kLine ? geometry::line_separation(*q[0], *q[1], *q[2], *q[3])
                                     : geometry::plane_separation(*q[0], *q[1], *q[2], *q[3]),
                               pad);
    });
  };
  // The cheap rejections of a list of vertex-face sub-pairs, in order, leaving those the kernel
  // must test: point(code) gives the vertex's position and face(code) the face.
  const auto sift_vertex_face = [&](std::uint16_t* list, std::size_t n, const auto& point, const auto& face) {
    n = sift(list, n, [&](std::uint16_t code) { return in_box(point(code), face(code)); });
    return sift_separated(std::false_type{}, list, n, [&](std::uint16_t code) {
      const PackedFace& t = face(code);
      return geometry::SeparationPoints{&point(code), &corner(t, 0), &corner(t, 1), &corner(t, 2)};
    });
  };
  // Sub-pairs are taken in blocks: the block's sub-pairs are listed, then the rejections sift
  // the list, and the exact kernels run over what is left.
  constexpr std::size_t kBlock = 64;
  // Lists the codes 0 .. n-1 (a sub-pair's place in its block).
  const auto iota = [](std::array<std::uint16_t, kBlock>& list, std::size_t n) {
    for (std::size_t k = 0; k < n; ++k) list[k] = static_cast<std::uint16_t>(k);
  };

  // 1. Broad-phase candidates (faces sharing no vertex).
  const auto& chunks = candidates.chunks();
  std::vector<std::size_t> offsets(chunks.size() + 1, 0);
  for (std::size_t i = 0; i < chunks.size(); ++i) offsets[i + 1] = offsets[i] + chunks[i].size();
  const std::size_t total = offsets.back();
  // The owned sub-pairs of a block of candidates whose boxes meet (`coarse_masks`, all of a
  // pair's box tests in a few float-lane operations: 9% of cloth-ball's frame against those
  // tests in double, sub-pair by sub-pair) are listed from a table without a branch, then the
  // plane and line tests sift the list. Code: the candidate's place in the block << 4 | the
  // table's code.
  static constexpr std::array<std::size_t, 3> kNext{1, 2, 0};
  // Chunks of 2,048 candidates, or fewer so that each thread has at least 16 (`balanced_grain`):
  // on the funnel a 2,048-candidate chunk was a tenth of the loop (one thread then waited 0.2
  // ms of the loop's 1.8 on two; 0.03 with 512-candidate chunks). Not fewer on the large
  // scenes, where a chunk is a small part of the loop anyway and each chunk's contacts are one
  // more part for the gather (cloth-ball with 512 was no faster).
  const std::size_t grain = balanced_grain(total, threads, 256, 2048);
  parallel_for_chunks(total, threads, grain, [&](std::size_t begin, std::size_t end) {
    LocalContacts local{spare_sets_.take()};
    // A block's candidates: the two faces, and where their corners are in x (looked up once).
    struct Candidate {
      std::array<const PackedFace*, 2> face;
      std::array<std::array<const Vec3*, 3>, 2> at;
    };
    std::array<Candidate, kBlock> block;
    // Room for a full table row written past the last candidate's codes.
    std::array<std::uint16_t, kBlock * 6 + 8> vf_subs;
    std::array<std::uint16_t, kBlock * 9 + 16> ee_subs;
    std::size_t c = static_cast<std::size_t>(
        std::upper_bound(offsets.begin(), offsets.end(), begin) - offsets.begin() - 1);
    for (std::size_t i = begin; i < end;) {
      std::size_t n = 0, nvf = 0, nee = 0;
      for (; i < end && n < kBlock; ++i, ++n) {
        while (i >= offsets[c + 1]) ++c;
        const FacePair& pair = chunks[c][i - offsets[c]];
        if (const std::size_t ahead = i + kBlock - offsets[c]; ahead < chunks[c].size()) {
          // The records of the next block's candidates, read while this block is processed.
          for (const Index f : chunks[c][ahead]) {
            __builtin_prefetch(&packed_[static_cast<std::size_t>(f)]);
            if (kinds.tt) {
              const auto* r = reinterpret_cast<const char*>(&face_corners_[static_cast<std::size_t>(f)]);
              __builtin_prefetch(r);
              __builtin_prefetch(r + sizeof(face_corners_[0]) - 1);
            }
          }
        }
        const PackedFace& a = packed_[static_cast<std::size_t>(pair[0])];
        const PackedFace& b = packed_[static_cast<std::size_t>(pair[1])];
        block[n].face = {&a, &b};
        block[n].at = {{{&corner(a, 0), &corner(a, 1), &corner(a, 2)}, {&corner(b, 0), &corner(b, 1), &corner(b, 2)}}};
        const auto base = static_cast<std::uint16_t>(n << 4);
        // The owned sub-pairs whose boxes meet.
        const auto axes = [&](const PackedFace& t) {
          return coarse_axes(coarse_point(t.v[0]), coarse_point(t.v[1]), coarse_point(t.v[2]));
        };
        const CoarseMasks box = proximity ? coarse_masks(axes(a), axes(b), coarse_half, coarse_full) : CoarseMasks{};
        if (kinds.vf) {
          const unsigned vkey = (a.vertex_mask | static_cast<unsigned>(b.vertex_mask) << 3) & box.vf;
          for (std::size_t k = 0; k < 8; ++k) vf_subs[nvf + k] = static_cast<std::uint16_t>(base | kVertexFace.codes[vkey][k]);
          nvf += kVertexFace.count[vkey];
        }
        if (kinds.ee) {
          // Bit 3i + j: side i of a and side j of b are both owned (b's mask, repeated at bits
          // 0, 3 and 6 where a owns side 0, 1, 2).
          const unsigned spread = (a.edge_mask & 1u) | (a.edge_mask & 2u) << 2 | (a.edge_mask & 4u) << 4;
          const unsigned ekey = (spread * b.edge_mask) & box.ee;
          for (std::size_t k = 0; k < 16; ++k) ee_subs[nee + k] = static_cast<std::uint16_t>(base | kEdgeEdge.codes[ekey][k]);
          nee += kEdgeEdge.count[ekey];
        }
      }
      if (kinds.vf) {
        // Corner (code & 3) of one face of the pair (the first, or with bit 2 the second), against
        // the other face.
        nvf = sift_separated(std::false_type{}, vf_subs.data(), nvf, [&](std::uint16_t code) {
          const Candidate& m = block[code >> 4];
          const std::size_t from = code >> 2 & 1u;
          const auto& t = m.at[from ^ 1u];
          return geometry::SeparationPoints{m.at[from][code & 3u], t[0], t[1], t[2]};
        });
        for (std::size_t s = 0; s < nvf; ++s) {
          const Candidate& m = block[vf_subs[s] >> 4];
          const std::size_t from = vf_subs[s] >> 2 & 1u, k = vf_subs[s] & 3u;
          const PackedFace* t = m.face[from ^ 1u];
          const auto& at = m.at[from ^ 1u];
          vf_kernel(*m.at[from][k], m.face[from]->v[k], *at[0], *at[1], *at[2], static_cast<Index>(t - packed_.data()),
                    local);
        }
      }
      if (kinds.ee) {
        // Side i of the first face and side j of the second: their ends, as corners of each face.
        const auto ends = [](std::uint16_t code) {
          const std::size_t i2 = code >> 2 & 3u, j = code & 3u;
          return std::array<std::size_t, 4>{i2, kNext[i2], j, kNext[j]};
        };
        nee = sift_separated(std::true_type{}, ee_subs.data(), nee, [&](std::uint16_t code) {
          const auto& at = block[code >> 4].at;
          const auto k = ends(code);
          return geometry::SeparationPoints{at[0][k[0]], at[0][k[1]], at[1][k[2]], at[1][k[3]]};
        });
        for (std::size_t s = 0; s < nee; ++s) {
          const Candidate& m = block[ee_subs[s] >> 4];
          const PackedFace &a = *m.face[0], &b = *m.face[1];
          const auto k = ends(ee_subs[s]);
          ee_kernel(*m.at[0][k[0]], *m.at[0][k[1]], a.v[k[0]], a.v[k[1]], a.e[k[0]], *m.at[1][k[2]], *m.at[1][k[3]],
                    b.v[k[2]], b.v[k[3]], b.e[k[2]], local);
        }
      }
      if (kinds.tt) {
        for (std::size_t m = 0; m < n; ++m) {
          const PackedFace& a = *block[m].face[0];
          const PackedFace& b = *block[m].face[1];
          const auto f = static_cast<Index>(&a - packed_.data()), g = static_cast<Index>(&b - packed_.data());
          // No box test first: every broad phase's candidates have boxes that overlap once padded
          // (measured: a test of the boxes padded by pad kept all 432,600 of cloth-ball's, and
          // all of the funnel's for kdop, hash and sap alike).
          ++local.tt_tests;
          const std::array<Vec3, 3>& pa = face_corners_[static_cast<std::size_t>(f)];
          const std::array<Vec3, 3>& pb = face_corners_[static_cast<std::size_t>(g)];
          if (f < g) {
            local.tt_batch.push(f, pa, g, pb, local.set.tt);
          } else {
            local.tt_batch.push(g, pb, f, pa, local.set.tt);
          }
        }
      }
    }
    merge(local);
  });

  // 2. Orphan sub-pairs of faces that share a vertex, by blocks: those woken by the motion since
  // the last refresh, or all of them on a refresh, which then also bounds each block's distances
  // from below with what its tests compute anyway (no extra kernel call): the box gap of the
  // sub-pairs the box rejects, the plane (line) distance of those that the plane (line)
  // rejects, and the kernel's distance, less the pad's rounding margin (pad - h, which covers
  // the kernel's rounding at either frame), of the others.
  const auto orphans_start = std::chrono::steady_clock::now();
  const bool refresh = proximity && wake_orphan_blocks(x, pad, threads);
  stats_.set("orphan_wake_ms", ms_since(orphans_start));
  const Scalar kernel_margin = pad - h;
  constexpr Scalar kInf = std::numeric_limits<Scalar>::infinity();
  // NaN-sticky minimum: a NaN bound keeps its block awake.
  const auto least = [](Scalar& bound, Scalar value) {
    if (!(value >= bound)) bound = value;
  };
  // Sifts list[0, n) by value(code) <= pad (a NaN is kept), lowering `bound` to the values of the
  // codes dropped; returns the number kept.
  const auto sift_bounded = [&](std::uint16_t* list, std::size_t n, const auto& value, Scalar& bound) {
    std::size_t kept = 0;
    for (std::size_t s = 0; s < n; ++s) {
      const std::uint16_t code = list[s];
      const Scalar v = value(code);
      const bool keep = !(v > pad);
      list[kept] = code;
      kept += keep ? 1u : 0u;
      bound = std::min(bound, keep ? kInf : v);
    }
    return kept;
  };
  // The kernel's distance, as a bound.
  const auto kernel_bound = [&](Scalar sqr_distance) { return std::sqrt(sqr_distance) * (1 - 1e-12) - kernel_margin; };
  // On a refresh, the sub-pairs [i, i + n) of a block: sifted by their box gap gap(k), then by
  // their plane or line distance separation(k) (k: the place in the block), then test(i + k,
  // local, &sqr_distance) on those left; returns the least of the values, the block's bound.
  const auto refresh_block = [&](std::size_t i, std::size_t n, LocalContacts& local, const auto& gap,
                                 const auto& separation, const auto& test) {
    std::array<std::uint16_t, kBlock> list;
    iota(list, n);
    Scalar bound = kInf;
    n = sift_bounded(list.data(), n, gap, bound);
    n = sift_bounded(list.data(), n, separation, bound);
    for (std::size_t s = 0; s < n; ++s) {
      Scalar sqr_distance = 0;
      test(i + list[s], local, &sqr_distance);
      least(bound, kernel_bound(sqr_distance));
    }
    return bound;
  };
  std::size_t tested_blocks = 0;
  // Runs test(i, n, local) on the sub-pairs [i, i + n) of each awake block of `blocks` (cut from a
  // list of `items`); on a refresh, refresh_test(i, n, local) instead, which returns the block's
  // bound.
  const auto orphan_pass = [&](OrphanBlocks& blocks, std::size_t items, const auto& test, const auto& refresh_test) {
    parallel_for_chunks(blocks.size(), threads, 64, [&](std::size_t begin, std::size_t end) {
      LocalContacts local{spare_sets_.take()};
      std::size_t tested = 0;
      for (std::size_t b = begin; b < end; ++b) {
        if (!blocks.awake[b]) continue;
        ++tested;
        const std::size_t i = b * kOrphanBlock, n = std::min(kOrphanBlock, items - i);
        if (refresh) {
          blocks.bound[b] = refresh_test(i, n, local);
        } else {
          test(i, n, local);
        }
      }
      merge(local);
      const std::lock_guard lock(mutex);
      tested_blocks += tested;
    });
  };
  if (kinds.vf) {
    const auto point = [&](std::size_t k) -> const Vec3& { return narrow::at(x, orphan_vf_[k][0]); };
    const auto face = [&](std::size_t k) -> const PackedFace& {
      return packed_[static_cast<std::size_t>(orphan_vf_[k][1])];
    };
    const auto vf_test = [&](std::size_t k, LocalContacts& local, Scalar* sqr_distance = nullptr) {
      const auto [v, g] = orphan_vf_[k];
      const PackedFace& t = face(k);
      vf_kernel(point(k), v, corner(t, 0), corner(t, 1), corner(t, 2), g, local, sqr_distance);
    };
    orphan_pass(
        vf_blocks_, orphan_vf_.size(),
        [&](std::size_t i, std::size_t n, LocalContacts& local) {
          // The box sift run by run, in float lanes as the candidates' (`coarse_masks`): a run's
          // face box is bounded once.
          std::array<std::uint16_t, kBlock> list;
          const std::size_t b = i / kOrphanBlock;
          std::size_t kept = 0, k = 0;
          for (std::size_t r = vf_blocks_.run_begin[b]; r < vf_blocks_.run_begin[b + 1]; ++r) {
            const Face& t = face(i + k).v;
            const F4 c0 = coarse_point(t[0]), c1 = coarse_point(t[1]), c2 = coarse_point(t[2]);
            const F4 lo = min4(min4(c0, c1), c2) - coarse_full, hi = max4(max4(c0, c1), c2) + coarse_full;
            for (const std::size_t run_end = k + vf_blocks_.runs[r]; k < run_end; ++k) {
              const F4 p = coarse_point(orphan_vf_[i + k][0]);
              list[kept] = static_cast<std::uint16_t>(k);
              kept += all_lanes((lo <= p) & (p <= hi));  // lane 3: 0 in [-pad, pad]
            }
          }
          n = sift_separated(std::false_type{}, list.data(), kept, [&](std::uint16_t code) {
            const PackedFace& t = face(i + code);
            return geometry::SeparationPoints{&point(i + code), &corner(t, 0), &corner(t, 1), &corner(t, 2)};
          });
          for (std::size_t s = 0; s < n; ++s) vf_test(i + list[s], local);
        },
        [&](std::size_t i, std::size_t n, LocalContacts& local) {
          return refresh_block(
              i, n, local,
              [&](std::uint16_t k) { return vertex_box_gap(point(i + k), face(i + k)); },
              [&](std::uint16_t k) {
                const PackedFace& t = face(i + k);
                return geometry::separation_bound(
                    geometry::plane_separation(point(i + k), corner(t, 0), corner(t, 1), corner(t, 2)));
              },
              vf_test);
        });
    // 3. Isolated vertices against every face.
    parallel_for_chunks(isolated_.size(), threads, 1, [&](std::size_t begin, std::size_t end) {
      LocalContacts local{spare_sets_.take()};
      std::array<std::uint16_t, kBlock> list;
      for (std::size_t i = begin; i < end; ++i) {
        const Index v = isolated_[i];
        const Vec3& p = narrow::at(x, v);
        for (std::size_t g0 = 0; g0 < nf; g0 += kBlock) {
          std::size_t n = std::min(kBlock, nf - g0);
          iota(list, n);
          n = sift_vertex_face(
              list.data(), n, [&](std::uint16_t) -> const Vec3& { return p; },
              [&](std::uint16_t k) -> const PackedFace& { return packed_[g0 + k]; });
          for (std::size_t s = 0; s < n; ++s) {
            const std::size_t g = g0 + list[s];
            const PackedFace& t = packed_[g];
            vf_kernel(p, v, corner(t, 0), corner(t, 1), corner(t, 2), static_cast<Index>(g), local);
          }
        }
      }
      merge(local);
    });
  }
  if (kinds.ee) {
    // The four ends of orphan edge pair k.
    const auto ends = [&](std::size_t k) {
      const OrphanEdges& o = orphan_ee_[k];
      return std::array<const Vec3*, 4>{&narrow::at(x, o.a[0]), &narrow::at(x, o.a[1]), &narrow::at(x, o.b[0]),
                                        &narrow::at(x, o.b[1])};
    };
    // The pairs are in the kernel's order already (first edge < second, each edge as the mesh
    // stores it): queued as they are, unless the squared distance is wanted.
    const auto ee_test = [&](std::size_t k, LocalContacts& local, Scalar* sqr_distance = nullptr) {
      const OrphanEdges& o = orphan_ee_[k];
      const auto p = ends(k);
      if (sqr_distance == nullptr) {
        ++local.ee_tests;
        local.ee_batch.push_in_order(o.e[0], o.a, *p[0], *p[1], o.e[1], o.b, *p[2], *p[3], h2, local.set.ee);
      } else {
        ee_kernel(*p[0], *p[1], o.a[0], o.a[1], o.e[0], *p[2], *p[3], o.b[0], o.b[1], o.e[1], local, sqr_distance);
      }
    };
    orphan_pass(
        ee_blocks_, orphan_ee_.size(),
        [&](std::size_t i, std::size_t n, LocalContacts& local) {
          // The box sift run by run, in float lanes: the first edge's box, bounded once for its
          // run and padded by the whole pad, meets the second edge's (as the vertex-face sift's
          // face box holds the point: the same rounding margin, `coarse_pad`).
          std::array<std::uint16_t, kBlock> list;
          const std::size_t b = i / kOrphanBlock;
          std::size_t kept = 0, k = 0;
          for (std::size_t r = ee_blocks_.run_begin[b]; r < ee_blocks_.run_begin[b + 1]; ++r) {
            const OrphanEdges& first = orphan_ee_[i + k];
            const F4 a0 = coarse_point(first.a[0]), a1 = coarse_point(first.a[1]);
            const F4 alo = min4(a0, a1) - coarse_full, ahi = max4(a0, a1) + coarse_full;
            for (const std::size_t run_end = k + ee_blocks_.runs[r]; k < run_end; ++k) {
              const OrphanEdges& o = orphan_ee_[i + k];
              const F4 b0 = coarse_point(o.b[0]), b1 = coarse_point(o.b[1]);
              list[kept] = static_cast<std::uint16_t>(k);
              kept += all_lanes((alo <= max4(b0, b1)) & (min4(b0, b1) <= ahi));  // lane 3: 0 in [-pad, pad]
            }
          }
          n = sift_separated(std::true_type{}, list.data(), kept, [&](std::uint16_t code) { return ends(i + code); });
          for (std::size_t s = 0; s < n; ++s) ee_test(i + list[s], local);
        },
        [&](std::size_t i, std::size_t n, LocalContacts& local) {
          return refresh_block(
              i, n, local,
              [&](std::uint16_t k) {
                const auto p = ends(i + k);
                return edge_box_gap(*p[0], *p[1], *p[2], *p[3]);
              },
              [&](std::uint16_t k) {
                const auto p = ends(i + k);
                return geometry::separation_bound(geometry::line_separation(*p[0], *p[1], *p[2], *p[3]));
              },
              ee_test);
        });
  }
  if (refresh) orphan_ref_.assign(x.begin(), x.end());
  stats_.set("orphan_ms", ms_since(orphans_start));
  stats_.set("orphan_blocks", static_cast<double>(vf_blocks_.size() + ee_blocks_.size()));
  stats_.set("orphan_blocks_tested", static_cast<double>(tested_blocks));
  stats_.set("orphan_refresh", refresh ? 1 : 0);
  stats_.set("narrow_ms", ms_since(narrow_start));

  // The frame's set in canonical order (`sorted_output`: the base class does not sort it again).
  const auto gather_start = std::chrono::steady_clock::now();
  std::vector<detail::KeyedList<VertexFaceContact>> vf_parts;
  std::vector<detail::KeyedList<EdgeEdgeContact>> ee_parts;
  std::vector<detail::KeyedList<TriangleTriangleContact>> tt_parts;
  for (const KeyedContacts& p : parts) {
    vf_parts.push_back({&p.set.vf, &p.vf_keys});
    ee_parts.push_back({&p.set.ee, &p.ee_keys});
    tt_parts.push_back({&p.set.tt, &p.tt_keys});
  }
  const auto count = [](const auto& lists) {
    std::size_t n = 0;
    for (const auto& list : lists) n += list.records->size();
    return n;
  };
  if (resolve_threads(threads) > 1 && detail::gather_places_serially(count(vf_parts)) &&
      detail::gather_places_serially(count(ee_parts)) && detail::gather_places_serially(count(tt_parts))) {
    // Few contacts: each kind's places are found on one thread, so the kinds are placed side by
    // side, the vertex-face and triangle contacts copied there too, then the edge-edge ones
    // (most of them) by every thread. (One after the other, the second thread waited 0.24 ms of
    // armadillo's 3.9 ms frame while the first placed them.)
    parallel_for_chunks(2, threads, 1, [&](std::size_t begin, std::size_t end) {
      for (std::size_t task = begin; task < end; ++task) {
        if (task == 0) {
          detail::gather_place(out.ee, ee_parts, topo.num_edges(), threads, gather_);
        } else {
          detail::gather_sorted(out.vf, vf_parts, topo.num_vertices(), threads, gather_other_);
          detail::gather_sorted(out.tt, tt_parts, static_cast<Index>(nf), threads, gather_other_);
        }
      }
    });
    detail::gather_copy(out.ee, threads, gather_);
  } else {
    detail::gather_sorted(out.vf, vf_parts, topo.num_vertices(), threads, gather_);
    detail::gather_sorted(out.ee, ee_parts, topo.num_edges(), threads, gather_);
    detail::gather_sorted(out.tt, tt_parts, static_cast<Index>(nf), threads, gather_);
  }
  for (KeyedContacts& p : parts) spare_sets_.give(std::move(p));
  stats_.set("sort_ms", ms_since(gather_start));
  stats_.set("orphan_vf", static_cast<double>(orphan_vf_.size()));
  stats_.set("orphan_ee", static_cast<double>(orphan_ee_.size()));
  stats_.set("isolated_vertices", static_cast<double>(isolated_.size()));
  stats_.set("vf_tests", static_cast<double>(vf_tests));
  stats_.set("ee_tests", static_cast<double>(ee_tests));
  if (kinds.tt) stats_.set("tt_tests", static_cast<double>(tt_tests));
}

}  // namespace crumple

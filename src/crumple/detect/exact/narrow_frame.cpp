#include <crumple/detect/exact/narrow_frame.hpp>

namespace crumple::exact {

NarrowFrame::NarrowFrame(const Topology& topo_, PositionsView x_, ContactKinds kinds_, int threads_,
                         Scalar thickness_, Scalar pad_, Scalar magnitude, const std::vector<PackedFace>& packed_,
                         const std::vector<std::array<Vec3, 3>>& face_corners_,
                         const std::vector<std::array<float, 4>>& coarse_x_, const std::vector<Index>& edge_rank_,
                         Spares<KeyedContacts>& spares_)
    : topo(topo_),
      x(x_),
      kinds(kinds_),
      proximity(kinds_.vf || kinds_.ee),
      threads(threads_),
      thickness(thickness_),
      sqr_thickness(thickness_ * thickness_),
      pad(pad_),
      packed(packed_),
      face_corners(face_corners_),
      coarse_x(coarse_x_),
      edge_rank(edge_rank_),
      spares(spares_) {
  // The box rejections in float lanes, unless the coordinates or the pad are too large for
  // floats (or NaN): then infinite pads, no box rejects, and the separation tests and the
  // kernels decide alone.
  const bool coarse = magnitude <= 1e30 && pad <= 1e30;
  constexpr float kNoPad = std::numeric_limits<float>::infinity();
  float_half_pad = coarse ? coarse_pad(pad / 2, magnitude) : kNoPad;
  float_pad = coarse ? coarse_pad(pad, magnitude) : kNoPad;
#if CRUMPLE_SEPARATION_LANES
  avx2 = geometry::has_avx2();
#endif
  CRUMPLE_ASSERT(!proximity || coarse_x.size() == x.size());
}

void NarrowFrame::collect(LocalContacts& local) {
  local.vf_batch.flush(sqr_thickness, local.set.vf);
  local.ee_batch.flush(sqr_thickness, local.set.ee);
  local.tt_batch.flush(local.set.tt);
  // A contact's key: its place in canonical order (`detail::gather_sorted`), listed here so that
  // the gather reads 8 bytes a contact before the copy instead of the whole record. Edge-edge
  // contacts are ordered by their first edge's vertices, then the second's: by the edges'
  // ranks in that order.
  const auto pair_key = [](Index first, Index second) {
    return static_cast<std::uint64_t>(first) << 32 | static_cast<std::uint32_t>(second);
  };
  const auto rank = [&](Index edge) { return edge_rank[static_cast<std::size_t>(edge)]; };
  const auto list = [](const auto& records, std::vector<std::uint64_t>& keys, const auto& key) {
    keys.resize(records.size());
    for (std::size_t i = 0; i < records.size(); ++i) keys[i] = key(records[i]);
  };
  KeyedContacts& part = local.keyed;
  list(part.set.vf, part.vf_keys, [&](const VertexFaceContact& c) { return pair_key(c.vertex, c.face); });
  list(part.set.ee, part.ee_keys, [&](const EdgeEdgeContact& c) { return pair_key(rank(c.edge0), rank(c.edge1)); });
  list(part.set.tt, part.tt_keys, [&](const TriangleTriangleContact& c) { return pair_key(c.face0, c.face1); });
  const std::lock_guard lock(mutex);
  if (!part.set.empty()) {
    parts.push_back(std::move(part));
  } else {
    spares.give(std::move(part));
  }
  vf_tests += local.vf_tests;
  ee_tests += local.ee_tests;
  tt_tests += local.tt_tests;
}

}  // namespace crumple::exact

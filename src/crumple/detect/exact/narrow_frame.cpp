#include <crumple/detect/exact/narrow_frame.hpp>

#include <algorithm>

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
      sqr_thickness(narrow::sqr_thickness(thickness_)),
      pad(pad_),
      packed(packed_),
      face_corners(face_corners_),
      coarse_x(coarse_x_),
      edge_rank(edge_rank_),
      spares(spares_),
      keep_budget(static_cast<std::size_t>(topo_.num_faces()) * kKeepBytesPerFace) {
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

void NarrowFrame::list_keys(LocalContacts& local) const {
  // A contact's key: its place in canonical order (`detail::gather_sorted`). Edge-edge contacts
  // are ordered by their first edge's vertices, then the second's: by the edges' ranks in that
  // order.
  const auto pair_key = [](Index first, Index second) {
    return static_cast<std::uint64_t>(first) << 32 | static_cast<std::uint32_t>(second);
  };
  const auto rank = [&](Index edge) { return edge_rank[static_cast<std::size_t>(edge)]; };
  // The records go to `kept` (with their keys) while the budget allows, else only their keys
  // to `only`.
  const auto list = [&](auto& records, auto& kept_records, std::vector<std::uint64_t>& keys,
                        std::vector<std::uint64_t>& only, const auto& key) {
    if (records.empty()) return;
    // The budget counts the storage the kept records take, growth included.
    const std::size_t size = kept_records.size() + records.size();
    const std::size_t capacity = size <= kept_records.capacity() ? kept_records.capacity()
                                                                 : std::max(size, 2 * kept_records.capacity());
    const std::size_t bytes = (capacity - kept_records.capacity()) * sizeof(records[0]);
    if (bytes == 0 || kept.fetch_add(bytes) + bytes <= keep_budget) {
      kept_records.reserve(capacity);
      for (const auto& c : records) keys.push_back(key(c));
      kept_records.insert(kept_records.end(), records.begin(), records.end());
    } else {
      kept.fetch_sub(bytes);
      for (const auto& c : records) only.push_back(key(c));
    }
    records.clear();
  };
  KeyedContacts& part = local.keyed;
  list(local.set.vf, part.set.vf, part.vf_keys, part.vf_only,
       [&](const VertexFaceContact& c) { return pair_key(c.vertex, c.face); });
  list(local.set.ee, part.set.ee, part.ee_keys, part.ee_only,
       [&](const EdgeEdgeContact& c) { return pair_key(rank(c.edge0), rank(c.edge1)); });
  // A triangle contact is its key (the gather makes it from the key): keys only, no record
  // kept beside one as large.
  for (const TriangleTriangleContact& c : local.set.tt) part.tt_only.push_back(pair_key(c.face0, c.face1));
  local.set.tt.clear();
}

void NarrowFrame::collect(LocalContacts& local) {
  local.vf_batch.flush(sqr_thickness, local.set.vf);
  local.ee_batch.flush(sqr_thickness, local.set.ee);
  local.tt_batch.flush(local.set.tt);
  list_keys(local);
  KeyedContacts& part = local.keyed;
  // A triangle contact's key is as large as its record: the keys held until the gather are
  // sized exactly (not up to twice by their growth), so that they and the gather's places stay
  // within 1.5 x the records (gather_contacts.cpp).
  part.tt_only.shrink_to_fit();
  const std::lock_guard lock(mutex);
  if (!part.empty()) {
    parts.push_back(std::move(part));
  } else {
    spares.give(std::move(part));
  }
  vf_tests += local.vf_tests;
  ee_tests += local.ee_tests;
  tt_tests += local.tt_tests;
}

}  // namespace crumple::exact

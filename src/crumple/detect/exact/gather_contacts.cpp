#include <crumple/core/parallel.hpp>
#include <crumple/detect/exact/narrow_frame.hpp>
#include <crumple/detect/exact/sort_by_major.hpp>

#include <numeric>

namespace crumple::exact {

void gather_contacts(std::vector<KeyedContacts>& parts, const Topology& topo, int threads, GatherBuffers& buffers,
                     Spares<KeyedContacts>& spares, ContactSet& out) {
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
  const Index nf = topo.num_faces();
  if (resolve_threads(threads) > 1 && detail::gather_places_serially(count(vf_parts)) &&
      detail::gather_places_serially(count(ee_parts)) && detail::gather_places_serially(count(tt_parts))) {
    // Few contacts: each kind's places are found on one thread, so the kinds are placed side by
    // side (the vertex-face and triangle contacts copied there too) rather than one after the
    // other, then the edge-edge ones (most of them) are copied by every thread.
    parallel_for_chunks(2, threads, 1, [&](std::size_t begin, std::size_t end) {
      for (std::size_t task = begin; task < end; ++task) {
        if (task == 0) {
          detail::gather_place(out.ee, ee_parts, topo.num_edges(), threads, buffers.main);
        } else {
          detail::gather_sorted(out.vf, vf_parts, topo.num_vertices(), threads, buffers.other);
          detail::gather_sorted(out.tt, tt_parts, nf, threads, buffers.other);
        }
      }
    });
    detail::gather_copy(out.ee, threads, buffers.main);
  } else {
    detail::gather_sorted(out.vf, vf_parts, topo.num_vertices(), threads, buffers.main);
    detail::gather_sorted(out.ee, ee_parts, topo.num_edges(), threads, buffers.main);
    detail::gather_sorted(out.tt, tt_parts, nf, threads, buffers.main);
  }
  for (KeyedContacts& p : parts) spares.give(std::move(p));
  parts.clear();
}

std::vector<Index> edge_ranks(const Topology& topo) {
  std::vector<Index> rank(static_cast<std::size_t>(topo.num_edges()));
  std::vector<Index> by_vertices(rank.size());
  std::iota(by_vertices.begin(), by_vertices.end(), 0);
  sort_by_major(
      by_vertices, static_cast<std::size_t>(topo.num_vertices()), [&](Index e) { return topo.edge(e)[0]; },
      [&](Index a, Index b) { return topo.edge(a)[1] < topo.edge(b)[1]; });
  for (std::size_t r = 0; r < by_vertices.size(); ++r) rank[static_cast<std::size_t>(by_vertices[r])] = static_cast<Index>(r);
  return rank;
}

}  // namespace crumple::exact

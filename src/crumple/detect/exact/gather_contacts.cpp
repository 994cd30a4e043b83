#include <crumple/core/parallel.hpp>
#include <crumple/detect/exact/narrow_frame.hpp>
#include <crumple/detect/exact/sort_by_major.hpp>

#include <algorithm>
#include <cstdint>
#include <numeric>

namespace crumple::exact {

void gather_contacts(NarrowFrame& frame, const std::vector<Index>& edge_by_rank, GatherBuffers& buffers,
                     ContactSet& out) {
  const Topology& topo = frame.topo;
  const PositionsView x = frame.x;
  const Scalar sqr_thickness = frame.sqr_thickness;
  const int threads = frame.threads;
  std::vector<KeyedContacts>& parts = frame.parts;
  std::vector<detail::KeyedList<VertexFaceContact>> vf_parts;
  std::vector<detail::KeyedList<EdgeEdgeContact>> ee_parts;
  std::vector<detail::KeyedList<TriangleTriangleContact>> tt_parts;
  for (const KeyedContacts& p : parts) {
    vf_parts.push_back({&p.set.vf, &p.vf_keys});
    vf_parts.push_back({nullptr, &p.vf_only});
    ee_parts.push_back({&p.set.ee, &p.ee_keys});
    ee_parts.push_back({nullptr, &p.ee_only});
    tt_parts.push_back({&p.set.tt, &p.tt_keys});
    tt_parts.push_back({nullptr, &p.tt_only});
  }
  // The records not kept, made again by the kernels that found them, four at a time, on the
  // same positions in the same order of arguments (`vertex_face` with the face's corners in
  // order, an edge pair as `EdgePair::ordered` puts it): the same bits.
  const auto first_of = [](std::uint64_t key) { return static_cast<Index>(key >> 32); };
  const auto second_of = [](std::uint64_t key) { return static_cast<Index>(key & 0x7FFFFFFFu); };
  const auto make_vf = [&](const std::uint64_t* keys, std::size_t n, std::vector<VertexFaceContact>& made) {
    narrow::VertexFaceBatch batch;
    for (std::size_t i = 0; i < n; ++i) {
      const Index v = first_of(keys[i]), f = second_of(keys[i]);
      const Face& t = topo.face(f);
      batch.push(v, narrow::at(x, v), f, narrow::at(x, t[0]), narrow::at(x, t[1]), narrow::at(x, t[2]), sqr_thickness,
                 made);
    }
    batch.flush(sqr_thickness, made);
  };
  const auto make_ee = [&](const std::uint64_t* keys, std::size_t n, std::vector<EdgeEdgeContact>& made) {
    narrow::EdgeEdgeBatch batch;
    for (std::size_t i = 0; i < n; ++i) {
      const Index e = edge_by_rank[static_cast<std::size_t>(first_of(keys[i]))];
      const Index f = edge_by_rank[static_cast<std::size_t>(second_of(keys[i]))];
      const Edge &a = topo.edge(e), &b = topo.edge(f);
      batch.push(e, a[0], a[1], narrow::at(x, a[0]), narrow::at(x, a[1]), f, b[0], b[1], narrow::at(x, b[0]),
                 narrow::at(x, b[1]), sqr_thickness, made);
    }
    batch.flush(sqr_thickness, made);
  };
  const auto make_tt = [&](const std::uint64_t* keys, std::size_t n, std::vector<TriangleTriangleContact>& made) {
    for (std::size_t i = 0; i < n; ++i) made.push_back({first_of(keys[i]), second_of(keys[i])});
  };
  // A kind's keys, once its places are found: given back before its records are sized.
  const auto free_keys = [&](auto keys, auto only) {
    for (KeyedContacts& p : parts) {
      std::vector<std::uint64_t>().swap(p.*keys);
      std::vector<std::uint64_t>().swap(p.*only);
    }
  };
  const auto count = [](const auto& lists) {
    std::size_t n = 0;
    for (const auto& list : lists) n += list.keys->size();
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
          detail::gather_place(ee_parts, topo.num_edges(), threads, buffers.main);
        } else {
          detail::gather_sorted(out.vf, vf_parts, topo.num_vertices(), threads, buffers.other, make_vf);
          detail::gather_sorted(out.tt, tt_parts, nf, threads, buffers.other, make_tt);
        }
      }
    });
    free_keys(&KeyedContacts::vf_keys, &KeyedContacts::vf_only);
    free_keys(&KeyedContacts::tt_keys, &KeyedContacts::tt_only);
    free_keys(&KeyedContacts::ee_keys, &KeyedContacts::ee_only);
    detail::gather_copy(out.ee, threads, buffers.main, make_ee);
  } else {
    detail::gather_place(vf_parts, topo.num_vertices(), threads, buffers.main);
    free_keys(&KeyedContacts::vf_keys, &KeyedContacts::vf_only);
    detail::gather_copy(out.vf, threads, buffers.main, make_vf);
    detail::gather_place(ee_parts, topo.num_edges(), threads, buffers.main);
    free_keys(&KeyedContacts::ee_keys, &KeyedContacts::ee_only);
    detail::gather_copy(out.ee, threads, buffers.main, make_ee);
    detail::gather_place(tt_parts, nf, threads, buffers.main);
    free_keys(&KeyedContacts::tt_keys, &KeyedContacts::tt_only);
    detail::gather_copy(out.tt, threads, buffers.main, make_tt);
  }
  // The parts' storage, kept records' included, for the next frame's chunks (fresh storage
  // costs page faults): at most `keep_budget` bytes of records, which the next frame's budget
  // does not count again.
  for (KeyedContacts& p : parts) frame.spares.give(std::move(p));
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

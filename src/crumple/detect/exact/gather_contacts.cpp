#include <crumple/core/parallel.hpp>
#include <crumple/detect/exact/narrow_frame.hpp>
#include <crumple/detect/exact/sort_by_major.hpp>

#include <algorithm>
#include <cstdint>
#include <numeric>

namespace crumple::exact {

namespace {

/// The triangle contacts of `parts` into `out` in canonical order (by first face, then second).
/// A triangle contact is its key (face0 << 32 | face1, 8 bytes as the record), so its record
/// is made from the key, kept or not, and the keys are placed without `gather_place`'s
/// address per contact: counted per first face, their second faces scattered to their places
/// (4 bytes each, beside the keys), the keys freed, then `out` sized and filled group by group,
/// each group's second faces sorted. The peak is 12 bytes a contact (1.5 x the records) plus
/// two counts per face.
void gather_triangles(std::vector<KeyedContacts>& parts, Index nf, int threads,
                      std::vector<TriangleTriangleContact>& out) {
  const auto faces = static_cast<std::size_t>(nf);
  std::size_t total = 0;
  for (const KeyedContacts& p : parts) total += p.tt_keys.size() + p.tt_only.size();
  if (total > out.capacity()) std::vector<TriangleTriangleContact>().swap(out);  // not held beside the keys
  out.clear();
  if (total == 0) return;
  std::vector<std::size_t> start(faces + 1, 0);  // start[f]: the place of face f's first contact
  for (const KeyedContacts& p : parts) {
    for (const auto* keys : {&p.tt_keys, &p.tt_only}) {
      for (const std::uint64_t key : *keys) ++start[(key >> 32) + 1];
    }
  }
  for (std::size_t f = 0; f < faces; ++f) start[f + 1] += start[f];
  std::vector<std::int32_t> second(total);
  {
    std::vector<std::size_t> next(start.begin(), start.end() - 1);
    for (KeyedContacts& p : parts) {
      for (auto* keys : {&p.tt_keys, &p.tt_only}) {
        for (const std::uint64_t key : *keys) {
          second[next[key >> 32]++] = static_cast<std::int32_t>(key & 0x7FFFFFFFu);
        }
        std::vector<std::uint64_t>().swap(*keys);
      }
    }
  }
  out.resize(total);
  parallel_for_chunks(faces, threads, 4096, [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) {
      std::int32_t* const first = second.data() + start[f];
      std::int32_t* const last = second.data() + start[f + 1];
      std::sort(first, last);
      for (std::int32_t* g = first; g < last; ++g) {
        out[static_cast<std::size_t>(g - second.data())] = {static_cast<Index>(f), static_cast<Index>(*g)};
      }
    }
  });
}

}  // namespace

void gather_contacts(NarrowFrame& frame, const std::vector<Index>& edge_by_rank, GatherBuffers& buffers,
                     ContactSet& out) {
  const Topology& topo = frame.topo;
  const PositionsView x = frame.x;
  const Scalar sqr_thickness = frame.sqr_thickness;
  const int threads = frame.threads;
  std::vector<KeyedContacts>& parts = frame.parts;
  std::vector<detail::KeyedList<VertexFaceContact>> vf_parts;
  std::vector<detail::KeyedList<EdgeEdgeContact>> ee_parts;
  for (const KeyedContacts& p : parts) {
    vf_parts.push_back({&p.set.vf, &p.vf_keys});
    vf_parts.push_back({nullptr, &p.vf_only});
    ee_parts.push_back({&p.set.ee, &p.ee_keys});
    ee_parts.push_back({nullptr, &p.ee_only});
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
  // The triangle contacts first (their keys are freed before the other kinds' places are found).
  gather_triangles(parts, nf, threads, out.tt);
  if (resolve_threads(threads) > 1 && detail::gather_places_serially(count(vf_parts)) &&
      detail::gather_places_serially(count(ee_parts))) {
    // Few contacts: each kind's places are found on one thread, so the kinds are placed side by
    // side (the vertex-face contacts copied there too) rather than one after the other, then
    // the edge-edge ones (most of them) are copied by every thread.
    parallel_for_chunks(2, threads, 1, [&](std::size_t begin, std::size_t end) {
      for (std::size_t task = begin; task < end; ++task) {
        if (task == 0) {
          detail::gather_place(ee_parts, topo.num_edges(), threads, buffers.main);
        } else {
          detail::gather_sorted(out.vf, vf_parts, topo.num_vertices(), threads, buffers.other, make_vf);
        }
      }
    });
    free_keys(&KeyedContacts::vf_keys, &KeyedContacts::vf_only);
    free_keys(&KeyedContacts::ee_keys, &KeyedContacts::ee_only);
    detail::gather_copy(out.ee, threads, buffers.main, make_ee);
  } else {
    detail::gather_place(vf_parts, topo.num_vertices(), threads, buffers.main);
    free_keys(&KeyedContacts::vf_keys, &KeyedContacts::vf_only);
    detail::gather_copy(out.vf, threads, buffers.main, make_vf);
    detail::gather_place(ee_parts, topo.num_edges(), threads, buffers.main);
    free_keys(&KeyedContacts::ee_keys, &KeyedContacts::ee_only);
    detail::gather_copy(out.ee, threads, buffers.main, make_ee);
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

#include <crumple/core/parallel.hpp>
#include <crumple/detect/exact/narrow_frame.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace crumple::exact {

namespace {

constexpr Scalar kInf = std::numeric_limits<Scalar>::infinity();

/// NaN-sticky minimum: a NaN bound keeps its block awake.
void least(Scalar& bound, Scalar value) {
  if (!(value >= bound)) bound = value;
}

/// Sifts list[0, n) by value(code) <= pad (a NaN is kept), lowering `bound` to the values of
/// the codes dropped; returns the number kept.
template <class Value>
std::size_t sift_bounded(std::uint16_t* list, std::size_t n, const Value& value, Scalar pad, Scalar& bound) {
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
}

/// On a refresh, the sub-pairs [i, i + n) of a block: sifted by their box gap gap(k), then by
/// their plane or line distance separation(k) (k: the place in the block), then test(i + k,
/// local, &sqr_distance) on those left. Returns the block's bound, the least of: the gaps and
/// separations of the sub-pairs they drop, and the kernel's distances of the others less the
/// pad's rounding margin (pad - h, which covers the kernel's rounding at either frame).
template <class Gap, class Separation, class Test>
Scalar refresh_block(const NarrowFrame& frame, std::size_t i, std::size_t n, LocalContacts& local, const Gap& gap,
                     const Separation& separation, const Test& test) {
  const Scalar kernel_margin = frame.pad - frame.thickness;
  CodeList list;
  iota(list, n);
  Scalar bound = kInf;
  n = sift_bounded(list.data(), n, gap, frame.pad, bound);
  n = sift_bounded(list.data(), n, separation, frame.pad, bound);
  for (std::size_t s = 0; s < n; ++s) {
    Scalar sqr_distance = 0;
    test(i + list[s], local, &sqr_distance);
    least(bound, std::sqrt(sqr_distance) * (1 - 1e-12) - kernel_margin);
  }
  return bound;
}

/// Runs test(i, n, local) on the sub-pairs [i, i + n) of each awake block of `blocks` (cut
/// from a list of `items`); on a refresh, refresh_test(i, n, local) instead, which returns the
/// block's bound. Returns the number of blocks tested.
template <class Test, class RefreshTest>
std::size_t orphan_pass(NarrowFrame& frame, OrphanBlocks& blocks, std::size_t items, bool refresh, const Test& test,
                        const RefreshTest& refresh_test) {
  std::size_t tested_blocks = 0;
  parallel_for_chunks(blocks.size(), frame.threads, 64, [&](std::size_t begin, std::size_t end) {
    LocalContacts local{frame.spares.take()};
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
    frame.collect(local);
    const std::lock_guard lock(frame.mutex);
    tested_blocks += tested;
  });
  return tested_blocks;
}

/// The vertex-face orphans: (vertex, face) sub-pairs of adjacent faces.
std::size_t orphans_vertex_face(NarrowFrame& frame, Orphans& orphans, bool refresh) {
  const auto& list_vf = orphans.vf;
  const OrphanBlocks& blocks = orphans.vf_blocks;
  const float float_pad = frame.float_pad;
  const auto point = [&](std::size_t k) -> const Vec3& { return narrow::at(frame.x, list_vf[k][0]); };
  const auto face = [&](std::size_t k) -> const PackedFace& {
    return frame.packed[static_cast<std::size_t>(list_vf[k][1])];
  };
  const auto corner = [&](const PackedFace& t, std::size_t k) -> const Vec3& { return frame.corner(t, k); };
  const auto vf_test = [&](std::size_t k, LocalContacts& local, Scalar* sqr_distance = nullptr) {
    const auto [v, g] = list_vf[k];
    const PackedFace& t = face(k);
    frame.vf_kernel(point(k), v, corner(t, 0), corner(t, 1), corner(t, 2), g, local, sqr_distance);
  };
  return orphan_pass(
      frame, orphans.vf_blocks, list_vf.size(), refresh,
      [&](std::size_t i, std::size_t, LocalContacts& local) {
        // The box sift run by run, in float lanes as the candidates' (`coarse_masks`): a run's
        // face box is bounded once.
        CodeList list;
        const std::size_t b = i / kOrphanBlock;
        std::size_t kept = 0, k = 0;
        for (std::size_t r = blocks.run_begin[b]; r < blocks.run_begin[b + 1]; ++r) {
          const Face& t = face(i + k).v;
          const F4 c0 = frame.coarse_point(t[0]), c1 = frame.coarse_point(t[1]), c2 = frame.coarse_point(t[2]);
          const F4 lo = min4(min4(c0, c1), c2) - float_pad, hi = max4(max4(c0, c1), c2) + float_pad;
          for (const std::size_t run_end = k + blocks.runs[r]; k < run_end; ++k) {
            const F4 p = frame.coarse_point(list_vf[i + k][0]);
            list[kept] = static_cast<std::uint16_t>(k);
            kept += all_lanes((lo <= p) & (p <= hi));  // lane 3: 0 in [-pad, pad]
          }
        }
        const std::size_t n = frame.sift_separated<false>(list.data(), kept, [&](std::uint16_t code) {
          const PackedFace& t = face(i + code);
          return geometry::SeparationPoints{&point(i + code), &corner(t, 0), &corner(t, 1), &corner(t, 2)};
        });
        for (std::size_t s = 0; s < n; ++s) vf_test(i + list[s], local);
      },
      [&](std::size_t i, std::size_t n, LocalContacts& local) {
        return refresh_block(
            frame, i, n, local, [&](std::uint16_t k) { return frame.vertex_box_gap(point(i + k), face(i + k)); },
            [&](std::uint16_t k) {
              const PackedFace& t = face(i + k);
              return geometry::separation_bound(
                  geometry::plane_separation(point(i + k), corner(t, 0), corner(t, 1), corner(t, 2)));
            },
            vf_test);
      });
}

/// The edge-edge orphans: pairs of edges of adjacent faces that share no vertex.
std::size_t orphans_edge_edge(NarrowFrame& frame, Orphans& orphans, bool refresh) {
  const auto& list_ee = orphans.ee;
  const OrphanBlocks& blocks = orphans.ee_blocks;
  const float float_pad = frame.float_pad;
  const Scalar sqr_thickness = frame.sqr_thickness;
  // The four ends of orphan edge pair k.
  const auto ends = [&](std::size_t k) {
    const OrphanEdges& o = list_ee[k];
    const PositionsView x = frame.x;
    return std::array<const Vec3*, 4>{&narrow::at(x, o.a[0]), &narrow::at(x, o.a[1]), &narrow::at(x, o.b[0]),
                                      &narrow::at(x, o.b[1])};
  };
  // The pairs are in the kernel's order already (first edge < second, each edge as the mesh
  // stores it): queued as they are, unless the squared distance is wanted.
  const auto ee_test = [&](std::size_t k, LocalContacts& local, Scalar* sqr_distance = nullptr) {
    const OrphanEdges& o = list_ee[k];
    const auto p = ends(k);
    if (sqr_distance == nullptr) {
      ++local.ee_tests;
      local.ee_batch.push_in_order(o.e[0], o.a, *p[0], *p[1], o.e[1], o.b, *p[2], *p[3], sqr_thickness, local.set.ee);
      frame.spill(local);
    } else {
      frame.ee_kernel(*p[0], *p[1], o.a[0], o.a[1], o.e[0], *p[2], *p[3], o.b[0], o.b[1], o.e[1], local, sqr_distance);
    }
  };
  return orphan_pass(
      frame, orphans.ee_blocks, list_ee.size(), refresh,
      [&](std::size_t i, std::size_t, LocalContacts& local) {
        // The box sift run by run, in float lanes: the first edge's box, bounded once for its
        // run and padded by the whole pad, meets the second edge's (as the vertex-face sift's
        // face box holds the point: the same rounding margin, `coarse_pad`).
        CodeList list;
        const std::size_t b = i / kOrphanBlock;
        std::size_t kept = 0, k = 0;
        for (std::size_t r = blocks.run_begin[b]; r < blocks.run_begin[b + 1]; ++r) {
          const OrphanEdges& first = list_ee[i + k];
          const F4 a0 = frame.coarse_point(first.a[0]), a1 = frame.coarse_point(first.a[1]);
          const F4 alo = min4(a0, a1) - float_pad, ahi = max4(a0, a1) + float_pad;
          for (const std::size_t run_end = k + blocks.runs[r]; k < run_end; ++k) {
            const OrphanEdges& o = list_ee[i + k];
            const F4 b0 = frame.coarse_point(o.b[0]), b1 = frame.coarse_point(o.b[1]);
            list[kept] = static_cast<std::uint16_t>(k);
            kept += all_lanes((alo <= max4(b0, b1)) & (min4(b0, b1) <= ahi));  // lane 3: 0 in [-pad, pad]
          }
        }
        const std::size_t n =
            frame.sift_separated<true>(list.data(), kept, [&](std::uint16_t code) { return ends(i + code); });
        for (std::size_t s = 0; s < n; ++s) ee_test(i + list[s], local);
      },
      [&](std::size_t i, std::size_t n, LocalContacts& local) {
        return refresh_block(
            frame, i, n, local,
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

}  // namespace

std::size_t narrow_orphans(NarrowFrame& frame, Orphans& orphans, bool refresh) {
  std::size_t tested = 0;
  if (frame.kinds.vf) tested += orphans_vertex_face(frame, orphans, refresh);
  if (frame.kinds.ee) tested += orphans_edge_edge(frame, orphans, refresh);
  return tested;
}

}  // namespace crumple::exact

#include <crumple/core/parallel.hpp>
#include <crumple/detect/exact/orphans.hpp>
#include <crumple/detect/exact/sort_by_major.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <utility>

namespace crumple::exact {

namespace {

/// Cuts a list of `items` sub-pairs into blocks: the vertices each block uses (verts_of(i):
/// sub-pair i's), and its runs of sub-pairs with the same key(i). A vertex is listed once per
/// block by marking it with the block's number (`listed_in`, one entry per vertex).
template <class VertsOf, class Key>
void cut_blocks(OrphanBlocks& blocks, std::size_t items, std::vector<std::size_t>& listed_in, const VertsOf& verts_of,
                const Key& key) {
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
}

}  // namespace

Orphans list_orphans(const Topology& topo, const FeatureOwnership& own) {
  const Index nf = topo.num_faces();
  const Index nv = topo.num_vertices();
  Orphans out;
  // Orphan sub-pairs: owned features of face pairs that share a vertex, not excluded. Each pair
  // is visited from the faces around its smallest shared vertex (not through `face_faces`, whose
  // memory is quadratic in a valence even where the pairs have no orphan, as repeated faces);
  // around a star, not here but each frame (`narrow_stars`).
  const Adjacency& vertex_faces = topo.vertex_faces();
  for (Index v = 0; v < nv; ++v) {
    const auto around = vertex_faces[v];
    if (around.size() > kStarValence) {
      out.stars.push_back(v);
      continue;
    }
    for (std::size_t p = 0; p < around.size(); ++p) {
      for (std::size_t q = p + 1; q < around.size(); ++q) {
        const Index f = std::min(around[p], around[q]), g = std::max(around[p], around[q]);
        if (f == g || smallest_shared_vertex(topo, f, g) != v) continue;
        for_each_orphan(
            topo, own, f, g, [&](Index u, Index face) { out.vf.push_back({u, face}); },
            [&](Index e0, Index e1) { out.ee.push_back({{e0, e1}, topo.edge(e0), topo.edge(e1)}); });
      }
    }
  }
  // By (face, vertex) and by (first edge, second edge); no two the same (a feature has one
  // owner, so a sub-pair comes from one pair of faces).
  sort_by_major(
      out.vf, static_cast<std::size_t>(nf), [](const auto& o) { return o[1]; },
      [](const auto& a, const auto& b) { return a[0] < b[0]; });
  sort_by_major(
      out.ee, static_cast<std::size_t>(topo.num_edges()), [](const OrphanEdges& o) { return o.e[0]; },
      [](const OrphanEdges& a, const OrphanEdges& b) { return a.e[1] < b.e[1]; });
  std::vector<std::size_t> listed_in(static_cast<std::size_t>(nv));
  cut_blocks(
      out.vf_blocks, out.vf.size(), listed_in,
      [&](std::size_t i) {
        const auto [v, g] = out.vf[i];
        const Face& t = topo.face(g);
        return std::array<Index, 4>{v, t[0], t[1], t[2]};
      },
      [&](std::size_t i) { return out.vf[i][1]; });
  cut_blocks(
      out.ee_blocks, out.ee.size(), listed_in,
      [&](std::size_t i) {
        const OrphanEdges& o = out.ee[i];
        return std::array<Index, 4>{o.a[0], o.a[1], o.b[0], o.b[1]};
      },
      [&](std::size_t i) { return out.ee[i].e[0]; });
  return out;
}

bool wake_orphan_blocks(Orphans& orphans, OrphanSleep& sleep, PositionsView x, Scalar pad, int threads,
                        DetectorStats& stats) {
  OrphanBlocks& vf_blocks = orphans.vf_blocks;
  OrphanBlocks& ee_blocks = orphans.ee_blocks;
  const auto wake_all = [&] {
    for (OrphanBlocks* set : {&vf_blocks, &ee_blocks}) set->awake.assign(set->size(), 1);
  };
  if (sleep.ref.size() != x.size()) {  // first frame (or new topology): refresh
    wake_all();
    sleep.refreshed = true;
    sleep.backoff = sleep.wait = 0;
    return true;
  }
  if (sleep.wait > 0) {  // backing off: every block, no bounds
    --sleep.wait;
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
  // awake (`wake_all` below), so a deforming scene does not pay for the whole sample. That is
  // so for the whole check, and for a sample of at least 64 blocks (a smaller sample decides
  // at half).
  const auto check = [&](std::size_t stride) {
    std::mutex mutex;
    Count count;
    for (const OrphanBlocks* set : {&vf_blocks, &ee_blocks}) count.blocks += (set->size() + stride - 1) / stride;
    const bool can_stop = stride == 1 || count.blocks >= 64;
    const std::size_t deciding = count.blocks / 4 + 1;  // woken blocks that make 4 woken > blocks
    std::atomic<std::size_t> woken_so_far{0};
    const auto decided = [&] { return can_stop && woken_so_far.load(std::memory_order_relaxed) >= deciding; };
    for (OrphanBlocks* set : {&vf_blocks, &ee_blocks}) {
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
          const Vec3 c = x[static_cast<std::size_t>(*v)], c_ref = sleep.ref[static_cast<std::size_t>(*v)];
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
            const Vec3 then = sleep.ref[static_cast<std::size_t>(*v)] - c_ref;
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
  // A sample first, every 16th block or about 256 blocks if that is fewer (looking at a block
  // is a cache miss or more): when most of those are woken by the motion, the frame is stale
  // without looking at the others. So it is, from a sample of at least 64 blocks, when more
  // than a quarter of them are (the threshold below); and when nearly all of such a sample are
  // awake, for whatever reason, every block is tested: looking at the others would cost about
  // what their sleep saves.
  const std::size_t stride = std::max<std::size_t>(16, (vf_blocks.size() + ee_blocks.size()) / 256);
  Count count = check(stride);
  const bool sampled = count.blocks >= 64;
  const bool partial = 2 * count.woken > count.blocks ||
                       (sampled && (4 * count.woken > count.blocks || 8 * count.awake > 7 * count.blocks));
  if (!partial) count = check(1);
  stats.set("orphan_sampled", partial ? 1 : 0);
  const std::size_t woken = count.woken, blocks = count.blocks;
  // Blocks that hold a pair within pad are awake whatever the motion; when the motion wakes more
  // than a quarter of the others, the bounds are stale: refresh, unless the previous frame was
  // a refresh already (the motion per frame is then too large for the bounds to pay): wait 1,
  // 2, 4, ... 64 frames, testing every block, before trying again.
  const bool stale = 4 * woken > blocks;
  if (!stale) {
    if (partial) wake_all();  // only the sample's flags are this frame's
    if (sleep.refreshed) sleep.backoff = 0;
    sleep.refreshed = false;
    return false;
  }
  wake_all();
  if (sleep.refreshed) {
    sleep.backoff = std::min(64, std::max(1, 2 * sleep.backoff));
    sleep.wait = sleep.backoff;
    sleep.refreshed = false;
    return false;
  }
  sleep.refreshed = true;
  return true;
}

}  // namespace crumple::exact

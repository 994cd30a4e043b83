// The hybrid detector's examination of the zones (hybrid_detail.hpp): in schedule order until
// the quota, the cap or the time budget stops it, each zone searched exactly (every owned pair
// behind a box pre-test) or stochastically (the thesis' Algorithm 3 restricted to the zone).

#include <crumple/detect/hybrid_detail.hpp>

#include <algorithm>
#include <cmath>
#include <span>
#include <vector>

namespace crumple {

using hybrid_detail::due;
using hybrid_detail::EETraits;
using hybrid_detail::EFTraits;
using hybrid_detail::EngineConfig;
using hybrid_detail::kEE;
using hybrid_detail::kEF;
using hybrid_detail::kVF;
using hybrid_detail::uniform_index;
using hybrid_detail::VFTraits;

void HybridDetector::Impl::examine_zones(ZoneSearchFrame& s, const std::vector<std::size_t>& order,
                                         const EngineConfig& base, const HybridParams& params) {
  const int every = params.every;
  const Scalar h = s.h;
  const std::size_t quota = (zones.size() + static_cast<std::size_t>(every) - 1) / static_cast<std::size_t>(every);
  const std::size_t cap = params.zones > 0 ? static_cast<std::size_t>(params.zones) : zones.size();
  const auto rows_size = [](std::span<const Index> row) { return static_cast<Index>(row.size()); };
  for (const std::size_t zi : order) {
    Zone& z = zones[zi];
    const bool wanted = every == 1 || due(z, every) || z.contacts > 0 || s.examined < quota;
    if (!wanted || s.examined >= cap || s.out_of_time()) {
      s.carried.insert(s.carried.end(), s.old_kept.begin() + static_cast<std::ptrdiff_t>(z.kept_begin),
                       s.old_kept.begin() + static_cast<std::ptrdiff_t>(z.kept_end));
      continue;
    }
    ++s.examined;
    z.examined = true;
    const auto la = static_cast<std::size_t>(z.a), lb = static_cast<std::size_t>(z.b);
    const Scalar nz = 0.5 * (near_factor[la] + near_factor[lb]) * h;
    s.ctx.near = nz;
    s.ctx.near2 = nz * nz;
    const Index particles = rows_size(owned_verts[z.a]) + (z.a == z.b ? 0 : rows_size(owned_verts[z.b]));
    const double share = particles > 0 ? static_cast<double>(z.contacts) / particles : 0;
    // A leaf's particles are shared among the zones it is in, so that the draws of a frame
    // follow the rule over the whole mesh, not once per zone.
    const double zone_particles =
        static_cast<double>(rows_size(owned_verts[z.a])) / leaf_zones[la] +
        (z.a == z.b ? 0.0 : static_cast<double>(rows_size(owned_verts[z.b])) / leaf_zones[lb]);
    EngineConfig config = base;
    config.propagation = params.auto_propagation ? (share > 0.5 ? Propagation::None : Propagation::Linear)
                                                 : params.propagation;
    ee.set_config(config);
    vf.set_config(config);
    ef.set_config(config);
    if (params.search == ZoneSearch::Exact) {
      search_exact(s, z);
      continue;
    }
    // Draws: the thesis' rule of thumb per zone (10% of its particles below 30% in collision,
    // one per particle above 50%, linear between), or a fixed count.
    int n_draw = params.draw;
    if (n_draw == 0) {
      const double rate = share < 0.3 ? 0.1 : share > 0.5 ? 1.0 : 0.1 + (share - 0.3) / 0.2 * 0.9;
      n_draw = std::max(1, static_cast<int>(std::ceil(rate * zone_particles)));
    }
    search_stochastic(s, z, n_draw);
  }
}

void HybridDetector::Impl::search_exact(ZoneSearchFrame& s, Zone& z) {
  const Topology& topo = s.topo;
  const PositionsView x = s.x;
  const Scalar h = s.h;
  const auto out_of_time = [&] { return s.out_of_time(); };
  // Every pair of owned elements, behind a box pre-test (the box of one side grown by h).
  const auto vf_side = [&](Index owner, Index other) {
    for (const Index v : owned_verts[owner]) {
      if (out_of_time()) return;
      const Vec3& p = x[static_cast<std::size_t>(v)];
      for (const Index f : leaf_faces[other]) {
        Box b = fbox(topo, x, f);
        b.inflate(h);
        if (!b.contains(p) || topo.face_has_vertex(f, v)) continue;
        ++s.exact_pairs;
        sink.add_vf(v, f);
      }
    }
  };
  if (s.run_vf) {
    vf_side(z.a, z.b);
    if (z.a != z.b) vf_side(z.b, z.a);
  }
  if (s.run_ee) {
    const auto ea = owned_edges[z.a];
    const auto eb = owned_edges[z.b];
    for (std::size_t i = 0; i < ea.size() && !out_of_time(); ++i) {
      Box b = ebox(topo, x, ea[i]);
      b.inflate(h);
      for (std::size_t j = z.a == z.b ? i + 1 : 0; j < eb.size(); ++j) {
        if (!b.overlaps(ebox(topo, x, eb[j])) || topo.edges_adjacent(ea[i], eb[j])) continue;
        ++s.exact_pairs;
        sink.add_ee(ea[i], eb[j]);
      }
    }
  }
  if (s.run_ef) {
    const auto fa = leaf_faces[z.a];
    const auto fb = leaf_faces[z.b];
    for (std::size_t i = 0; i < fa.size() && !out_of_time(); ++i) {
      const Box& b = fbox(topo, x, fa[i]);
      for (std::size_t j = z.a == z.b ? i + 1 : 0; j < fb.size(); ++j) {
        if (!b.overlaps(fbox(topo, x, fb[j])) || topo.faces_adjacent(fa[i], fb[j])) continue;
        ++s.exact_pairs;
        sink.add_tt(fa[i], fb[j]);
      }
    }
  }
  if (out_of_time()) s.unfinish(z);
}

void HybridDetector::Impl::search_stochastic(ZoneSearchFrame& s, Zone& z, int n_draw) {
  const Topology& topo = s.topo;
  const auto out_of_time = [&] { return s.out_of_time(); };
  const std::size_t c_ee = ee.colliding_pairs().size();
  const std::size_t c_vf = vf.colliding_pairs().size();
  const std::size_t c_ef = ef.colliding_pairs().size();
  for (std::size_t k = z.kept_begin; k < z.kept_end; ++k) {
    if (out_of_time()) {  // the rest wait, as they are, for the next frame
      s.carried.insert(s.carried.end(), s.old_kept.begin() + static_cast<std::ptrdiff_t>(k),
                       s.old_kept.begin() + static_cast<std::ptrdiff_t>(z.kept_end));
      break;
    }
    const Kept& kp = s.old_kept[k];
    if (kp.type == kEE && s.run_ee) ee.process_pair(s.ctx, kp.pair);
    if (kp.type == kVF && s.run_vf) vf.process_pair(s.ctx, kp.pair);
    if (kp.type == kEF && s.run_ef) ef.process_pair(s.ctx, kp.pair);
  }
  // Draws.
  const auto pick = [&](std::span<const Index> row) {
    return row[static_cast<std::size_t>(uniform_index(rng, static_cast<Index>(row.size())))];
  };
  for (int d = 0; d < n_draw && !out_of_time(); ++d) {
    const bool swap = z.a != z.b && (rng() & 1) != 0;
    const Index p = swap ? z.b : z.a, q = swap ? z.a : z.b;
    if (s.run_ee && !owned_edges[p].empty() && !owned_edges[q].empty()) {
      const Index e0 = pick(owned_edges[p]), e1 = pick(owned_edges[q]);
      ++s.drawn;
      if (!EETraits::excluded(topo, e0, e1)) ee.process_pair(s.ctx, {e0, e1});
    }
    if (s.run_vf && !owned_verts[p].empty()) {
      const Index v = pick(owned_verts[p]), f = pick(leaf_faces[q]);
      ++s.drawn;
      if (!VFTraits::excluded(topo, v, f)) vf.process_pair(s.ctx, {v, f});
    }
    if (s.run_ef && !owned_edges[p].empty()) {
      const Index e = pick(owned_edges[p]), f = pick(leaf_faces[q]);
      ++s.drawn;
      if (!EFTraits::excluded(topo, e, f)) ef.process_pair(s.ctx, {e, f});
    }
  }
  if (s.run_ee) ee.propagate_from(s.ctx, c_ee);
  if (s.run_vf) vf.propagate_from(s.ctx, c_vf);
  if (s.run_ef) ef.propagate_from(s.ctx, c_ef);
  if (out_of_time()) s.unfinish(z);
}

}  // namespace crumple

// The k-DOP hierarchy's frame-to-frame cache (kdop_tree_detail.hpp, "Temporal coherence"):
// which frames record the coherence units' candidates, which reuse them, and when a stale cache
// waits before recording again.
#include <crumple/detect/broad_phase/kdop_tree_detail.hpp>

#include <algorithm>
#include <cstdint>
#include <vector>

namespace crumple::detail {

/// Decides this frame's mode and the radius of its refit (larger on a refresh frame).
template <int K>
void DopTree<K>::choose_coherence(const FrameInput& in) {
  refit_radius_ = in.radius;
  mode_ = Mode::off;
  if (!params_.coherence || in.intersection_only || in.continuous || (params_.sweep && !in.previous.empty())) {
    cache_valid_ = false;
    return;
  }
  // Displacement boxes take no NaN: a frame with a non-finite coordinate is traversed, and
  // the next finite one records.
  const auto finite = [&] {
    return std::all_of(in.positions.begin(), in.positions.end(), [](const Vec3& p) { return p.allFinite(); });
  };
  if (!cache_valid_ || cache_ref_.size() != in.positions.size()) {
    if (finite()) {
      start_record(in);
    } else {
      cache_valid_ = false;
    }
    return;
  }
  if (cache_wait_ > 0) {  // backing off: traversed, nothing recorded
    --cache_wait_;
    return;
  }
  slack_ = 2 * (cache_radius_ - in.radius);
  if (slack_ > 0 && cache_fresh(in.positions)) {
    if (!finite()) {
      cache_valid_ = false;
      return;
    }
    if (cache_refreshed_) cache_backoff_ = 0;
    cache_refreshed_ = false;
    mode_ = Mode::reuse;
    return;
  }
  // Stale. Right after a refresh the motion per frame is too large for the cache to pay:
  // wait 1, 2, 4, ... 64 frames before recording again.
  if (cache_refreshed_) {
    cache_backoff_ = std::min(64, std::max(1, 2 * cache_backoff_));
    cache_wait_ = cache_backoff_;
    cache_refreshed_ = false;
    return;
  }
  if (finite()) {
    start_record(in);
  } else {
    cache_valid_ = false;
  }
}

/// A refresh frame: the k-DOPs are inflated by the slack more, and every unit's candidates
/// are recorded with the positions.
template <int K>
void DopTree<K>::start_record(const FrameInput& in) {
  mode_ = Mode::record;
  cache_radius_ = refit_radius_ = in.radius * (1 + kSlack);
  cache_ref_.assign(in.positions.begin(), in.positions.end());
  units_.clear();
  unit_pairs_.clear();
  cache_valid_ = false;  // until the traversal has recorded every unit
  cache_refreshed_ = true;
}

/// Of every 16th leaf, at most a quarter have vertices whose displacements since the refresh
/// frame differ by more than the slack (else most units would be traversed anyway). Stops as
/// soon as more than a quarter have (deforming cloth: a quarter of the sample, scattered reads).
template <int K>
inline bool DopTree<K>::cache_fresh(PositionsView x) const {
  const std::size_t samples = (leaf_ids_.size() + 15) / 16;
  std::size_t moved = 0;
  for (std::size_t i = 0; i < leaf_ids_.size(); i += 16) {
    const auto n = static_cast<std::size_t>(leaf_ids_[i]);
    Box m = Box::empty();
    for (std::size_t k = leaf_verts_[n]; k < leaf_verts_[n + 1]; ++k) {
      const auto v = static_cast<std::size_t>(verts_[k]);
      m.grow(x[v] - cache_ref_[v]);
    }
    moved += spread(m, m) <= slack_ ? 0 : 1;
    if (4 * moved > samples) return false;
  }
  return true;
}

#define CRUMPLE_KDOP_INSTANTIATE(K)                            \
  template void DopTree<K>::choose_coherence(const FrameInput&); \
  template void DopTree<K>::start_record(const FrameInput&);
CRUMPLE_KDOP_FOR_EACH_K(CRUMPLE_KDOP_INSTANTIATE)
#undef CRUMPLE_KDOP_INSTANTIATE

}  // namespace crumple::detail

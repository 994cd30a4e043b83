#include <crumple/core/error.hpp>
// The k-DOP hierarchy as a broad phase (kdop_tree.hpp): its parameters, the `KdopTree` facade
// over one `detail::DopTree<K>` per k, and a frame's order of steps (kdop_tree_detail.hpp lists
// the units that define the rest).
#include <crumple/core/timing.hpp>
#include <crumple/detect/broad_phase/kdop_tree_detail.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <limits>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace crumple {

KdopParams KdopParams::from_spec(const MethodSpec& spec) {
  // Keys left out keep the struct's defaults (one place says what they are).
  KdopParams p;
  static constexpr std::array<std::string_view, 4> kK{"6", "14", "18", "26"};
  static constexpr std::array<std::string_view, 3> kArity{"2", "4", "8"};
  p.k = std::stoi(spec.get_choice("k", std::to_string(p.k), kK));
  p.arity = std::stoi(spec.get_choice("arity", std::to_string(p.arity), kArity));
  const long long leaf = spec.get_int("leaf", p.leaf);
  // Saturated to int (a value past it is out of range all the same): `validate` reports it.
  p.leaf = static_cast<int>(
      std::clamp<long long>(leaf, std::numeric_limits<int>::min(), std::numeric_limits<int>::max()));
  p.rebuild = spec.get_double("rebuild", p.rebuild);
  p.sweep = spec.get_bool("sweep", p.sweep);
  p.cones = spec.get_bool("cones", p.cones);
  p.coherence = spec.get_bool("coherence", p.coherence);
  p.validate("method " + spec.to_string());
  return p;
}

void KdopParams::validate(const std::string& who) const {
  if (k != 6 && k != 14 && k != 18 && k != 26) {
    throw InputError(who + ": k must be 6, 14, 18 or 26, got " + std::to_string(k));
  }
  if (arity != 2 && arity != 4 && arity != 8) {
    throw InputError(who + ": arity must be 2, 4 or 8, got " + std::to_string(arity));
  }
  if (leaf < 1 || leaf > 64) throw InputError(who + ": leaf must be in 1..64, got " + std::to_string(leaf));
  if (!(rebuild >= 1)) throw InputError(who + ": rebuild must be >= 1");
}

namespace detail {

template <int K>
void DopTree<K>::update(const Topology& topo, const FrameInput& in, DetectorStats& stats) {
  threads_ = in.threads;
  if (topo.num_faces() == 0) return;
  const auto t0 = std::chrono::steady_clock::now();
  if (nodes_.empty()) build(topo, in.positions, in.owns, stats);
  const auto tc = std::chrono::steady_clock::now();
  choose_coherence(in);
  stats.set("coherence_ms", ms_since(tc));
  refit(in);
  double q = quality();
  if (q > params_.rebuild * built_quality_) {
    build(topo, in.positions, in.owns, stats);  // the node ids change: the cache is dropped
    if (mode_ == Mode::reuse) start_record(in);
    refit(in);
    q = quality();
  }
  stats.set("refit_ms", ms_since(t0));
  stats.set("quality", q / built_quality_);
  stats.set("nodes", static_cast<double>(nodes_.size()));

  culling_ = params_.cones && in.intersection_only;
  if (culling_) {
    const auto tc = std::chrono::steady_clock::now();
    if (!contours_valid_) build_contours();
    normal_masks(in.positions);
    positions_ = in.positions;
    stats.set("cones_ms", ms_since(tc));
  }
}

template <int K>
void DopTree<K>::self_pairs(CandidateBuffer& out, DetectorStats& stats) {
  if (nodes_.empty()) return;
  culled_ = 0;
  const auto t1 = std::chrono::steady_clock::now();
  traverse(threads_, out, stats);
  stats.set("traversal_ms", ms_since(t1));
  stats.set("coherence", mode_ == Mode::off ? 0 : mode_ == Mode::record ? 1 : 2);
  if (culling_) stats.set("culled_nodes", static_cast<double>(culled_.load()));
}

template <int K>
std::vector<Bounds> DopTree<K>::boxes(int depth) const {
  std::vector<Bounds> out;
  if (depth < 0 || depth >= levels() || dops_.size() != nodes_.size()) return out;
  const auto [begin, end] = levels_[static_cast<std::size_t>(depth)];
  for (Index n = begin; n < end; ++n) {
    const Dop& d = dops_[static_cast<std::size_t>(n)];
    out.push_back({Vec3(d.min(0), d.min(1), d.min(2)), Vec3(d.max(0), d.max(1), d.max(2))});
  }
  return out;
}

template <int K>
std::vector<std::vector<Index>> DopTree<K>::leaf_faces() const {
  std::vector<std::vector<Index>> out;
  for (const Node& node : nodes_) {
    if (!node.leaf) continue;
    const auto first = order_.begin() + node.first;
    out.emplace_back(first, first + node.count);
  }
  return out;
}

}  // namespace detail

KdopTree::KdopTree(KdopParams params) : params_(params) {
  params_.validate("kdop");  // also for parameters built in code, not through a spec
}

KdopTree::~KdopTree() = default;

void KdopTree::build(const Topology& topology) {
  topo_ = &topology;
  switch (params_.k) {
    case 6:
      tree_ = std::make_unique<detail::DopTree<6>>(params_);
      break;
    case 14:
      tree_ = std::make_unique<detail::DopTree<14>>(params_);
      break;
    case 18:
      tree_ = std::make_unique<detail::DopTree<18>>(params_);
      break;
    default:
      tree_ = std::make_unique<detail::DopTree<26>>(params_);
      break;
  }
}

int KdopTree::levels() const { return tree_ ? tree_->levels() : 0; }

std::vector<Bounds> KdopTree::node_boxes(int depth) const {
  return tree_ ? tree_->boxes(depth) : std::vector<Bounds>{};
}

std::vector<std::vector<Index>> KdopTree::leaf_faces() const {
  return tree_ ? tree_->leaf_faces() : std::vector<std::vector<Index>>{};
}

void KdopTree::update(const FrameInput& in, DetectorStats& stats) {
  CRUMPLE_CHECK(tree_ != nullptr, "kdop: update before build");
  tree_->update(*topo_, in, stats);
}

void KdopTree::self_pairs(CandidateBuffer& out, DetectorStats& stats) { tree_->self_pairs(out, stats); }

}  // namespace crumple

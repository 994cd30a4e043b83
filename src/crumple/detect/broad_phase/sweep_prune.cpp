#include <crumple/core/error.hpp>
#include <crumple/core/parallel.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/broad_phase/sweep_prune.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <numeric>
#include <string>

namespace crumple {

SapParams SapParams::from_spec(const MethodSpec& spec) {
  SapParams p;
  static constexpr std::array<std::string_view, 4> kAxis{"auto", "x", "y", "z"};
  const std::string axis = spec.get_choice("axis", "auto", kAxis);
  p.axis = axis == "auto" ? -1 : axis[0] - 'x';
  return p;
}

SweepPrune::SweepPrune(SapParams params) : params_(params) {}

void SweepPrune::build(const Topology& topology) {
  topo_ = &topology;
  axis_ = -1;
  order_.clear();
  keys_.clear();
  sorted_boxes_.clear();
  sorted_faces_.clear();
}

void SweepPrune::update(const FrameInput& in, DetectorStats& stats) {
  CRUMPLE_CHECK(topo_ != nullptr, "sap: update before build");
  const Topology& topo = *topo_;
  threads_ = in.threads;
  const std::size_t nf = static_cast<std::size_t>(topo.num_faces());
  if (nf == 0) return;
  const auto t0 = std::chrono::steady_clock::now();
  face_boxes(topo, in, in.continuous, boxes_);
  if (axis_ < 0) {
    axis_ = params_.axis;
    if (axis_ < 0) {  // axis of largest variance of the box centres
      Vec3 mean = Vec3::Zero(), sq = Vec3::Zero();
      for (const Box& b : boxes_) {
        const Vec3 c((b.lo[0] + b.hi[0]) / 2, (b.lo[1] + b.hi[1]) / 2, (b.lo[2] + b.hi[2]) / 2);
        mean += c;
        sq += c.cwiseProduct(c);
      }
      mean /= static_cast<Scalar>(nf);
      const Vec3 var = sq / static_cast<Scalar>(nf) - mean.cwiseProduct(mean);
      var.maxCoeff(&axis_);
    }
  }
  const int ax = axis_;
  const auto key_less = [&](Scalar ka, Index a, Scalar kb, Index b) { return ka < kb || (ka == kb && a < b); };
  std::size_t swaps = 0;
  bool full_sort = order_.size() != nf;
  if (!full_sort) {
    keys_.resize(nf);
    for (std::size_t i = 0; i < nf; ++i) keys_[i] = boxes_[static_cast<std::size_t>(order_[i])].lo[static_cast<std::size_t>(ax)];
    // Insertion sort of the previous frame's order (nearly sorted under coherence).
    const std::size_t limit = 32 * nf;
    for (std::size_t i = 1; i < nf && !full_sort; ++i) {
      const Scalar k = keys_[i];
      const Index id = order_[i];
      std::size_t j = i;
      while (j > 0 && key_less(k, id, keys_[j - 1], order_[j - 1])) {
        keys_[j] = keys_[j - 1];
        order_[j] = order_[j - 1];
        --j;
      }
      keys_[j] = k;
      order_[j] = id;
      swaps += i - j;
      if (swaps > limit) full_sort = true;
    }
  }
  if (full_sort) {
    order_.resize(nf);
    std::iota(order_.begin(), order_.end(), 0);
    std::sort(order_.begin(), order_.end(), [&](Index a, Index b) {
      return key_less(boxes_[static_cast<std::size_t>(a)].lo[static_cast<std::size_t>(ax)], a,
                      boxes_[static_cast<std::size_t>(b)].lo[static_cast<std::size_t>(ax)], b);
    });
    keys_.resize(nf);
    for (std::size_t i = 0; i < nf; ++i) keys_[i] = boxes_[static_cast<std::size_t>(order_[i])].lo[static_cast<std::size_t>(ax)];
  }
  sorted_boxes_.resize(nf);
  sorted_faces_.resize(nf);
  parallel_for_chunks(nf, in.threads, 4096, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      sorted_boxes_[i] = boxes_[static_cast<std::size_t>(order_[i])];
      sorted_faces_[i] = topo.face(order_[i]);
    }
  });
  stats.set("refit_ms", ms_since(t0));
  stats.set("swaps", static_cast<double>(swaps));
  stats.set("full_sort", full_sort ? 1 : 0);
  stats.set("axis", ax);
}

void SweepPrune::self_pairs(CandidateBuffer& out, DetectorStats& stats) {
  const std::size_t nf = sorted_boxes_.size();
  if (nf == 0) return;
  const int ax = axis_;
  const auto t1 = std::chrono::steady_clock::now();
  const std::size_t a1 = static_cast<std::size_t>((ax + 1) % 3), a2 = static_cast<std::size_t>((ax + 2) % 3);
  parallel_for_chunks(nf, threads_, 1024, [&](std::size_t begin, std::size_t end) {
    std::vector<FacePair> local = out.take();
    for (std::size_t i = begin; i < end; ++i) {
      const Box& bi = sorted_boxes_[i];
      const Scalar hi = bi.hi[static_cast<std::size_t>(ax)];
      for (std::size_t j = i + 1; j < nf && keys_[j] <= hi; ++j) {
        const Box& bj = sorted_boxes_[j];
        // Branch-free on purpose: the four comparisons as ints, ORed bitwise.
        if (int(bi.lo[a1] > bj.hi[a1]) | int(bj.lo[a1] > bi.hi[a1]) | int(bi.lo[a2] > bj.hi[a2]) |
            int(bj.lo[a2] > bi.hi[a2]))
          continue;
        if (faces_share_vertex(sorted_faces_[i], sorted_faces_[j])) continue;
        const Index f = order_[i], g = order_[j];
        local.push_back({std::min(f, g), std::max(f, g)});
      }
      out.flush_if_full(local);
    }
    out.add(std::move(local));
  });
  stats.set("traversal_ms", ms_since(t1));
}

}  // namespace crumple

#pragma once
/// \file
/// Internal: a binary tree of axis-aligned boxes, built in O(n log n) and queried for the boxes
/// that overlap a given one. Used where a per-topology list or an all-pairs test would be
/// quadratic (the faces around a star, vertices used by no face, the hash grid's oversized
/// faces): built per frame, it keeps those stages near-linear in their input whenever the boxes
/// are not themselves crowded.

#include <crumple/detect/broad_phase/broad_phase.hpp>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

namespace crumple::detail {

class BoxTree {
 public:
  /// Builds over `boxes` (kept by reference until the next build). A box with a NaN side or
  /// empty (lo > hi) is left out: it overlaps nothing.
  void build(std::span<const Box> boxes) {
    boxes_ = boxes;
    items_.clear();
    for (std::size_t i = 0; i < boxes.size(); ++i) {
      const Box& b = boxes[i];
      if (b.lo[0] <= b.hi[0] && b.lo[1] <= b.hi[1] && b.lo[2] <= b.hi[2]) items_.push_back(static_cast<std::uint32_t>(i));
    }
    nodes_.clear();
    if (!items_.empty()) split(0, items_.size());
  }

  /// Calls hit(i) for every box i that overlaps `query` (closed intervals); returns the number
  /// of node boxes compared (the work, for counters).
  template <class Hit>
  std::size_t query(const Box& query, const Hit& hit) const {
    if (nodes_.empty()) return 0;
    std::size_t compared = 0;
    std::uint32_t stack[64];  // depth <= log2(n) + 1 (median splits)
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
      const Node& node = nodes_[stack[--top]];
      ++compared;
      if (!node.box.overlaps(query)) continue;
      if (node.right == 0) {
        for (std::uint32_t k = node.begin; k < node.end; ++k) {
          if (boxes_[items_[k]].overlaps(query)) hit(items_[k]);
        }
        compared += node.end - node.begin;
      } else {
        stack[top++] = node.right;
        stack[top++] = node.begin_child;
      }
    }
    return compared;
  }

 private:
  static constexpr std::size_t kLeaf = 4;
  struct Node {
    Box box;
    std::uint32_t begin = 0, end = 0;  ///< items [begin, end)
    std::uint32_t begin_child = 0;     ///< left child's node (inner nodes)
    std::uint32_t right = 0;           ///< right child's node; 0: a leaf
  };

  /// A box's centre along axis a, finite even for infinite sides (a strict weak order for the
  /// split, never NaN: the box's NaN-free by `build`).
  Scalar centre(std::uint32_t i, std::size_t a) const {
    constexpr Scalar kMax = std::numeric_limits<Scalar>::max();
    return std::clamp(boxes_[i].lo[a], -kMax, kMax) / 2 + std::clamp(boxes_[i].hi[a], -kMax, kMax) / 2;
  }

  /// Adds the node of items [begin, end) and its subtree; returns its place. Median split of
  /// the box centres along the longest side of their extent.
  std::uint32_t split(std::size_t begin, std::size_t end) {
    const auto at = static_cast<std::uint32_t>(nodes_.size());
    nodes_.push_back({});
    Box box = Box::empty(), centres = Box::empty();
    for (std::size_t k = begin; k < end; ++k) {
      const Box& b = boxes_[items_[k]];
      box.merge(b);
      centres.grow(Vec3(centre(items_[k], 0), centre(items_[k], 1), centre(items_[k], 2)));
    }
    nodes_[at].box = box;
    nodes_[at].begin = static_cast<std::uint32_t>(begin);
    nodes_[at].end = static_cast<std::uint32_t>(end);
    if (end - begin <= kLeaf) return at;
    std::size_t axis = 0;
    for (std::size_t a = 1; a < 3; ++a) {
      if (centres.hi[a] - centres.lo[a] > centres.hi[axis] - centres.lo[axis]) axis = a;
    }
    const std::size_t mid = begin + (end - begin) / 2;
    std::nth_element(items_.begin() + static_cast<std::ptrdiff_t>(begin), items_.begin() + static_cast<std::ptrdiff_t>(mid),
                     items_.begin() + static_cast<std::ptrdiff_t>(end), [&](std::uint32_t i, std::uint32_t j) {
                       return centre(i, axis) < centre(j, axis);
                     });
    const std::uint32_t left = split(begin, mid);
    const std::uint32_t right = split(mid, end);
    nodes_[at].begin_child = left;
    nodes_[at].right = right;
    return at;
  }

  std::span<const Box> boxes_;
  std::vector<std::uint32_t> items_;
  std::vector<Node> nodes_;
};

}  // namespace crumple::detail

#pragma once
/// \file
/// Internal: the face-level slab test and the impacts' merge of the mesh-level continuous
/// query (continuous.cpp), exposed for their tests.

#include <crumple/core/types.hpp>

#include <algorithm>
#include <array>
#include <cstddef>
#include <span>
#include <utility>
#include <vector>

namespace crumple::detail {

/// A face's box at t = 0 and at t = 1, each bound rounded outwards to float, indexed
/// [3 τ + axis]: the lows, then the highs. (16-byte aligned: the kernels' two-float loads at
/// lo[4] and hi[4] are then 8-byte aligned.)
struct alignas(16) FaceBoxes {
  std::array<float, 6> lo, hi;
};

/// Whether on some axis, at t = 0 and at t = 1 alike, one face's low minus the other's high,
/// converted to double and subtracted there (one rounding), exceeds `bound`:
/// `geometry::ccd_slabs_apart`'s test on the float boxes. `avx2` (only where
/// `geometry::detail::ccd_has_avx2()`) picks the kernel of three four-wide differences, else
/// the one of six two-wide (SSE2) differences; both give the same answer.
bool face_boxes_apart(const FaceBoxes& a, const FaceBoxes& b, Scalar bound, bool avx2);

/// Sorts `items` made of consecutive runs each sorted by `less` (run r ends at `ends[r]`; the
/// ends increase and the last is items.size(); empty runs are allowed): a k-way merge on a
/// binary heap of the runs' heads (the top replaced and sifted down as its run advances), each
/// item moved once. With unique keys, the order of `std::sort`.
template <class T, class Less>
void merge_sorted_runs(std::vector<T>& items, std::span<const std::size_t> ends, Less less) {
  struct Head {
    T* at;
    T* end;
  };
  std::vector<Head> heap;
  heap.reserve(ends.size());
  std::size_t begin = 0;
  for (const std::size_t end : ends) {
    if (end > begin) heap.push_back({items.data() + begin, items.data() + end});
    begin = end;
  }
  if (heap.size() <= 1) return;
  // Restores the heap order (the smallest head on top) below position i.
  const auto sift_down = [&](std::size_t i) {
    const std::size_t n = heap.size();
    const Head h = heap[i];
    for (;;) {
      std::size_t c = 2 * i + 1;
      if (c >= n) break;
      if (c + 1 < n && less(*heap[c + 1].at, *heap[c].at)) ++c;
      if (!less(*heap[c].at, *h.at)) break;
      heap[i] = heap[c];
      i = c;
    }
    heap[i] = h;
  };
  for (std::size_t i = heap.size() / 2; i-- > 0;) sift_down(i);
  std::vector<T> out;
  out.reserve(items.size());
  while (!heap.empty()) {
    Head& top = heap.front();
    out.push_back(std::move(*top.at));
    if (++top.at == top.end) {
      top = heap.back();
      heap.pop_back();
      if (heap.empty()) break;
    }
    sift_down(0);
  }
  items = std::move(out);
}

}  // namespace crumple::detail

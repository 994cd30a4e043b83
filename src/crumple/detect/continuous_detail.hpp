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
/// ends increase and the last is items.size(); empty runs are allowed): a k-way merge on a heap
/// of the runs' heads, each item moved once. With unique keys, the order of `std::sort`.
template <class T, class Less>
void merge_sorted_runs(std::vector<T>& items, std::span<const std::size_t> ends, Less less) {
  struct Head {
    std::size_t at, end;
  };
  std::vector<Head> heap;
  heap.reserve(ends.size());
  std::size_t begin = 0;
  for (const std::size_t end : ends) {
    if (end > begin) heap.push_back({begin, end});
    begin = end;
  }
  if (heap.size() <= 1) return;
  // A max-heap on "later": its top is the run whose head comes first.
  const auto later = [&](const Head& x, const Head& y) { return less(items[y.at], items[x.at]); };
  std::make_heap(heap.begin(), heap.end(), later);
  std::vector<T> out;
  out.reserve(items.size());
  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), later);
    Head& h = heap.back();
    out.push_back(std::move(items[h.at++]));
    if (h.at == h.end) {
      heap.pop_back();
    } else {
      std::push_heap(heap.begin(), heap.end(), later);
    }
  }
  items = std::move(out);
}

}  // namespace crumple::detail

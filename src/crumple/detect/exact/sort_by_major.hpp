#pragma once
/// \file
/// Internal to the exact detector: a counting sort for the per-topology lists.

#include <algorithm>
#include <cstddef>
#include <vector>

namespace crumple::exact {

/// Sorts `items` by major(item) in [0, majors), then `minor_less` within a major: a counting
/// sort on the major, then a sort of each major's few items (the set-up's lists hold hundreds
/// of thousands of items keyed by a vertex, a face or an edge, each key with few). With no two
/// items equal under (major, minor_less), the order is the one `std::sort` gives.
template <class T, class Major, class MinorLess>
void sort_by_major(std::vector<T>& items, std::size_t majors, const Major& major, const MinorLess& minor_less) {
  std::vector<std::size_t> start(majors + 1, 0);
  for (const T& t : items) ++start[static_cast<std::size_t>(major(t)) + 1];
  for (std::size_t k = 0; k < majors; ++k) start[k + 1] += start[k];
  std::vector<T> out(items.size());
  std::vector<std::size_t> next(start.begin(), start.end() - 1);
  for (const T& t : items) out[next[static_cast<std::size_t>(major(t))]++] = t;
  for (std::size_t k = 0; k < majors; ++k) {
    std::sort(out.begin() + static_cast<std::ptrdiff_t>(start[k]), out.begin() + static_cast<std::ptrdiff_t>(start[k + 1]),
              minor_less);
  }
  items.swap(out);
}

}  // namespace crumple::exact

#pragma once
/// Union–find over vertex ids, shared by the fail-safe's impact zones and the untangler's
/// contours (internal).

#include <crumple/core/types.hpp>

#include <cstddef>
#include <vector>

namespace crumple::response::detail {

/// The root of `i`'s set in the forest `parent` (a root is its own parent), halving the path.
inline Index root(std::vector<Index>& parent, Index i) {
  const auto at = [](Index k) { return static_cast<std::size_t>(k); };
  while (parent[at(i)] != i) {
    parent[at(i)] = parent[at(parent[at(i)])];
    i = parent[at(i)];
  }
  return i;
}

}  // namespace crumple::response::detail

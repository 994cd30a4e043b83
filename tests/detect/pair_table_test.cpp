// The stochastic engine's per-frame pair table (stochastic_engine.hpp): a set of pair keys with
// a value and flags, cleared in O(1) per frame, checked against std::map through growth and
// many generations.

#include <crumple/detect/stochastic_engine.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <map>
#include <random>

namespace {

using crumple::stochastic_detail::pair_key;
using crumple::stochastic_detail::PairTable;

TEST(PairTable, MatchesAMapThroughGrowthAndClears) {
  PairTable table;
  std::mt19937_64 rng(5);
  for (int frame = 0; frame < 6; ++frame) {
    table.clear();
    EXPECT_EQ(table.size(), 0U);
    std::map<std::uint64_t, std::pair<std::uint32_t, double>> model;
    // Keys from a small range so that lookups hit stored keys, and pairs that differ in one
    // element only (what a walk asks for).
    const int n = frame % 2 == 0 ? 3000 : 40;
    for (int i = 0; i < 20 * n; ++i) {
      const auto a = static_cast<crumple::Index>(rng() % static_cast<std::uint64_t>(n));
      const auto b = static_cast<crumple::Index>(rng() % 64);
      const std::uint64_t k = pair_key(a, b);
      const auto it = model.find(k);
      if (rng() % 3 == 0) {
        const double* v = table.find(k);
        ASSERT_EQ(v != nullptr, it != model.end());
        if (v != nullptr) {
          EXPECT_EQ(*v, it->second.second);
        }
        continue;
      }
      PairTable::Entry& e = table.entry(k);
      if (it == model.end()) {
        // A new entry starts empty, whatever the slot held in an earlier frame.
        ASSERT_EQ(e.flags, 0U);
        ASSERT_EQ(e.value, 0.0);
        e.flags = static_cast<std::uint32_t>(i) | 1U;
        e.value = 0.5 * i;
        model[k] = {e.flags, e.value};
      } else {
        ASSERT_EQ(e.flags, it->second.first);
        ASSERT_EQ(e.value, it->second.second);
      }
    }
    EXPECT_EQ(table.size(), model.size());
    for (const auto& [k, fv] : model) {
      const PairTable::Entry& e = table.entry(k);
      EXPECT_EQ(e.flags, fv.first);
      EXPECT_EQ(e.value, fv.second);
    }
    EXPECT_EQ(table.size(), model.size());
  }
  // `insert` keeps the first value.
  table.clear();
  EXPECT_TRUE(table.insert(pair_key(1, 2), 3.0).second);
  const auto again = table.insert(pair_key(1, 2), 4.0);
  EXPECT_FALSE(again.second);
  EXPECT_EQ(*again.first, 3.0);
  EXPECT_TRUE(table.contains(pair_key(1, 2)));
  EXPECT_FALSE(table.contains(pair_key(2, 1)));
}

}  // namespace

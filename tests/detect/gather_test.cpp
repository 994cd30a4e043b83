// detail::gather_sorted, the exact detectors' last step, against a plain sort (the detector
// tests see its order too: the exact detectors' output is not sorted again).

#include <crumple/detect/gather.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <set>
#include <vector>

namespace crumple {
namespace {

// A record as the detectors' contacts are: ids and a payload that must travel with them (or be
// made again from the ids).
struct Record {
  Index first = 0, second = 0;
  double payload = 0;
  std::uint64_t key() const {
    return static_cast<std::uint64_t>(first) << 32 | static_cast<std::uint32_t>(second);
  }
};

// `count` records with distinct (first, second), first in [0, keys) drawn so that a few first
// criteria hold many records (up to hundreds: buckets sorted in place), split into `parts` lists
// of random lengths (some empty).
std::vector<std::vector<Record>> make_parts(std::mt19937& rng, Index keys, std::size_t count, std::size_t parts) {
  std::set<std::pair<Index, Index>> seen;
  std::vector<Record> all;
  std::uniform_int_distribution<Index> any(0, keys - 1), hot(0, std::min<Index>(keys - 1, 3));
  std::uniform_int_distribution<Index> second(0, 1 << 20);
  while (all.size() < count) {
    const Index f = (rng() % 8 == 0) ? hot(rng) : any(rng);
    const Index s = second(rng);
    if (seen.insert({f, s}).second) all.push_back({f, s, static_cast<double>(all.size())});
  }
  std::vector<std::vector<Record>> out(parts);
  for (const Record& r : all) out[rng() % parts].push_back(r);
  return out;
}

// The record that `expect_gathered` hands in by its key alone: its payload is made from the key.
Record made_of(std::uint64_t key) {
  const auto first = static_cast<Index>(key >> 32), second = static_cast<Index>(key & 0xFFFFFFFFu);
  return {first, second, -static_cast<double>(key)};
}
void made(const std::uint64_t* keys, std::size_t n, std::vector<Record>& out) {
  for (std::size_t i = 0; i < n; ++i) out.push_back(made_of(keys[i]));
}

// `shared`: a scratch kept from earlier calls (else a fresh one). Every third list is handed in
// as keys alone, its records made by `made`.
void expect_gathered(const std::vector<std::vector<Record>>& lists, Index keys, int threads,
                     detail::GatherScratch* shared = nullptr) {
  std::vector<std::vector<std::uint64_t>> keys_of(lists.size());
  std::vector<detail::KeyedList<Record>> parts;
  std::vector<Record> want;
  for (std::size_t i = 0; i < lists.size(); ++i) {
    for (const Record& r : lists[i]) {
      keys_of[i].push_back(r.key());
      want.push_back(i % 3 == 2 ? made_of(r.key()) : r);
    }
    parts.push_back({i % 3 == 2 ? nullptr : &lists[i], &keys_of[i]});
  }
  std::sort(want.begin(), want.end(), [](const Record& a, const Record& b) { return a.key() < b.key(); });
  detail::GatherScratch fresh;
  detail::GatherScratch& scratch = shared != nullptr ? *shared : fresh;
  std::vector<Record> got{{7, 7, 7}};  // stale content is replaced
  for (int round = 0; round < 2; ++round) {  // the scratch is reused
    detail::gather_sorted(got, parts, keys, threads, scratch, made);
    ASSERT_EQ(got.size(), want.size());
    for (std::size_t i = 0; i < want.size(); ++i) {
      ASSERT_EQ(got[i].key(), want[i].key()) << "place " << i << " of " << want.size();
      ASSERT_EQ(got[i].payload, want[i].payload) << "place " << i;
    }
  }
}

TEST(Gather, CountedPathMatchesASort) {
  std::mt19937 rng(5101);
  for (int threads : {1, 2, 3}) {
    for (std::size_t parts : {1u, 7u, 300u}) {
      expect_gathered(make_parts(rng, 1000, 20000, parts), 1000, threads);
    }
  }
}

TEST(Gather, CountedPathInSlicesMatchesASort) {
  // 65,536 items and more are counted and scattered by slices, one per thread (up to four).
  std::mt19937 rng(5103);
  for (int threads : {2, 3, 5}) expect_gathered(make_parts(rng, 20000, 70000, 11), 20000, threads);
}

TEST(Gather, SortedPathMatchesASort) {
  // Fewer records than keys / 8: sorted by key rather than counted.
  std::mt19937 rng(5102);
  for (int threads : {1, 2}) expect_gathered(make_parts(rng, 1 << 20, 5000, 9), 1 << 20, threads);
}

TEST(Gather, GroupsOfEverySizeAndSecondCriteriaOverTheirWholeRange) {
  // Groups of up to 140 records under one first criterion (ranked four at a time, with every
  // remainder of four, and sorted past 128), in scrambled order, second criteria up to
  // 2^31 - 1; more records than keys / 8, so that they are counted.
  std::mt19937 rng(5104);
  std::vector<Record> all;
  const Index keys = 150;
  std::uniform_int_distribution<Index> any(0, 0x7FFFFFFF);
  std::size_t drawn = 0;
  for (Index f = 0; f < keys - 10; ++f) {
    // Group f: max(f + 1, 2) criteria (0 and 2^31 - 1 among them), a seventh then left out.
    std::set<Index> seconds{0, 0x7FFFFFFF};
    while (static_cast<Index>(seconds.size()) < f + 1) {
      seconds.insert(f % 2 == 0 ? any(rng) : 0x7FFFFFFF - any(rng) % 300);
    }
    for (Index s : seconds) {
      if (drawn++ % 7 != 3 || f < 2) all.push_back({f, s, static_cast<double>(all.size())});
    }
  }
  ASSERT_GT(all.size(), 8000u);
  std::shuffle(all.begin(), all.end(), rng);
  std::vector<std::vector<Record>> lists(5);
  for (const Record& r : all) lists[rng() % lists.size()].push_back(r);
  for (int threads : {1, 2}) expect_gathered(lists, keys, threads);
}

TEST(Gather, EmptyAndSingle) {
  expect_gathered({}, 10, 2);
  expect_gathered({{}, {}}, 10, 2);
  expect_gathered({{{3, 4, 1.5}}}, 10, 2);
  // Every record under one first criterion, found in reverse order.
  std::vector<Record> one;
  for (Index s = 500; s > 0; --s) one.push_back({2, s, static_cast<double>(s)});
  expect_gathered({one}, 4, 2);
}

TEST(Gather, OneScratchAcrossDifferentFrames) {
  // The counts are put back to 0 only for the first criteria that had records: a scratch kept
  // across calls whose records fall under other criteria, with other key counts, other slice
  // counts, and the sorted path in between, must still place every record.
  std::mt19937 rng(5105);
  for (int threads : {1, 2, 3}) {
    detail::GatherScratch scratch;
    expect_gathered(make_parts(rng, 1000, 20000, 7), 1000, threads, &scratch);
    expect_gathered(make_parts(rng, 1000, 9000, 3), 1000, threads, &scratch);
    expect_gathered(make_parts(rng, 20000, 70000, 11), 20000, threads, &scratch);
    expect_gathered(make_parts(rng, 1 << 20, 5000, 9), 1 << 20, threads, &scratch);
    expect_gathered(make_parts(rng, 20000, 30000, 5), 20000, threads, &scratch);
    expect_gathered(make_parts(rng, 1000, 20000, 2), 1000, threads, &scratch);
  }
}

}  // namespace
}  // namespace crumple

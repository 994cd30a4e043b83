#pragma once
/// \file
/// The exact detectors' last step: the contacts that the narrow phase's chunks found, in
/// whatever order they were found, put into one list in canonical order. A chunk may hand in
/// keys without their records (memory: see exact/gather_contacts.cpp): those records are made
/// from the keys as they are placed.

#include <crumple/core/error.hpp>
#include <crumple/core/parallel.hpp>
#include <crumple/core/types.hpp>

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace crumple::detail {

/// Buffers of `gather_sorted`, kept across frames (fresh buffers of MBs cost page faults every
/// frame).
struct GatherScratch {
  /// A record being gathered: its place in canonical order, and where it is.
  struct Item {
    std::uint64_t key;
    const void* record;
  };
  std::vector<Item> items;  ///< few records: listed, then sorted
  /// Many records: their addresses and second criteria, grouped by first criterion.
  std::vector<const void*> records;
  std::vector<std::int32_t> seconds;
  /// Per slice of the items, bit k: first criterion k has items in it.
  std::vector<std::uint64_t> held;
  std::vector<std::size_t> firsts;  ///< the first criteria that have items, in order
  /// Per slice of the items and first criterion: how many items, then the next free place; all
  /// 0 between calls when `clean`.
  std::vector<std::size_t> cursor;
  bool clean = false;
  // What `gather_place` leaves for `gather_copy`:
  bool listed = false;              ///< the records are `items`, sorted (else counted)
  std::vector<std::size_t> starts;  ///< where the items of each of `firsts` start, then the total
  std::vector<std::size_t> bound;   ///< ranges of `firsts` that the copy's threads claim
  std::size_t total = 0;            ///< the records placed
};

/// True when `gather_place` places `total` records on the calling thread alone, whatever the
/// thread count: counting them in slices costs more than it saves.
inline bool gather_places_serially(std::size_t total) { return total < (std::size_t{1} << 16); }

/// One list of records to gather and their keys (keys[i]: records[i]'s place in the order, as
/// `gather_sorted` says), listed by whoever wrote the records. `records` null: keys alone,
/// whose records `gather_copy` makes.
template <class T>
struct KeyedList {
  const std::vector<T>* records;
  const std::vector<std::uint64_t>* keys;
};

/// `gather_sorted` (below) gathers the records of every list in `parts` into `dest` in the
/// order of their keys, in two steps that a caller may also run apart: `gather_place` finds
/// each record's place, `gather_copy` sizes dest and copies the records there (they must still
/// be where they were; the keys need not be: they may be freed between the steps, so that they
/// and dest are never held together). A key
/// is a record's place in that order as one integer, first criterion << 32 | second, the first
/// in [0, keys), the second in [0, 2^31) (an `Index`); no two records may have the same key.
///
/// The records are not moved until their place is known: the keys are counted per first
/// criterion and the records' addresses and second criteria scattered to their first
/// criterion's places (each thread counting then scattering its own slice of the keys), then
/// `threads` threads, claiming ranges of first criteria that hold about the same number of
/// records (four ranges per thread), copy each record to its place, once, reading them ahead.
/// Among a criterion's items (a dense mesh may have hundreds for one edge), an item's place is
/// the number of them with smaller second criteria, counted four items at a time in vector
/// lanes over the group's 32-bit criteria, which lie side by side; groups over 128 are sorted.
///
/// The gather is bound by memory traffic (a frame's contacts can be tens of MB): the keys come
/// with the records, so that the records are read once here, by the copy, and the counting
/// reads the keys where they are instead of a list of (key, address) items made first. Fewer
/// records than keys / 8 are sorted by key instead of counted: counting would cost more, over
/// every key.
template <class T>
void gather_place(const std::vector<KeyedList<T>>& parts, Index keys, int threads, GatherScratch& scratch) {
  using Item = GatherScratch::Item;
  auto& items = scratch.items;
  auto& records = scratch.records;
  auto& seconds = scratch.seconds;
  auto& held = scratch.held;
  auto& firsts = scratch.firsts;
  auto& next = scratch.cursor;
  auto& starts = scratch.starts;
  auto& bound = scratch.bound;
  scratch.listed = false;
  std::vector<std::size_t> offset(parts.size() + 1, 0);
  for (std::size_t i = 0; i < parts.size(); ++i) {
    CRUMPLE_ASSERT(parts[i].records == nullptr || parts[i].keys->size() == parts[i].records->size());
    offset[i + 1] = offset[i] + parts[i].keys->size();
  }
  const std::size_t total = offset.back();
  scratch.total = total;
  if (total == 0) return;
  // Calls f(key, record) on the items [from, to) of the parts put end to end, in order.
  const auto each_item = [&](std::size_t from, std::size_t to, const auto& f) {
    auto i = static_cast<std::size_t>(std::upper_bound(offset.begin(), offset.end(), from) - offset.begin() - 1);
    for (std::size_t j = from; j < to; ++i) {
      const std::size_t stop = std::min(to, offset[i + 1]);
      const std::uint64_t* key = parts[i].keys->data() + (j - offset[i]);
      if (parts[i].records == nullptr) {
        for (; j < stop; ++j) f(*key++, static_cast<const T*>(nullptr));
        continue;
      }
      const T* record = parts[i].records->data() + (j - offset[i]);
      for (; j < stop; ++j) f(*key++, record++);
    }
  };
  const auto by_key = [](const Item& a, const Item& b) { return a.key < b.key; };
  if (total < static_cast<std::size_t>(keys) / 8) {
    items.resize(total);
    Item* to = items.data();
    each_item(0, total, [&to](std::uint64_t key, const T* record) { *to++ = {key, record}; });
    std::sort(items.begin(), items.end(), by_key);
    scratch.listed = true;
    return;
  }
  // Each slice of the items is counted, then scattered, by one thread; slice s's items of first
  // criterion k go to [cursor, ...) of row s, after those of the slices before.
  const auto workers = static_cast<std::size_t>(resolve_threads(threads));
  // (A few tens of thousands of items: one slice, counted and scattered without starting
  // threads, which costs more than it saves there.)
  const std::size_t slices = gather_places_serially(total) ? 1 : std::min<std::size_t>(workers, 4);
  const auto nk = static_cast<std::size_t>(keys);
  const std::size_t words = (nk + 63) / 64;
  const auto slice = [&](std::size_t s) { return std::pair{total * s / slices, total * (s + 1) / slices}; };
  // The counts start at 0 and only the first criteria that had items are put back to 0 after
  // the scatter, rather than every row cleared before the count: most criteria may have no
  // items (most edges are the first edge of no edge-edge contact). Their bits in `held` list
  // them, and the places are summed over those only.
  if (!scratch.clean || next.size() != slices * nk) next.assign(slices * nk, 0);
  scratch.clean = false;  // until the counts are back to 0
  held.assign(slices * words, 0);
  parallel_for_chunks(slices, threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t s = begin; s < end; ++s) {
      std::size_t* row = next.data() + s * nk;
      std::uint64_t* bits = held.data() + s * words;
      const auto [from, to] = slice(s);
      each_item(from, to, [row, bits](std::uint64_t key, const T*) {
        const std::size_t k = key >> 32;
        ++row[k];
        bits[k / 64] |= std::uint64_t{1} << (k % 64);
      });
    }
  });
  firsts.clear();
  starts.clear();
  std::size_t place = 0;
  for (std::size_t w = 0; w < words; ++w) {
    std::uint64_t bits = held[w];
    for (std::size_t s = 1; s < slices; ++s) bits |= held[s * words + w];
    for (; bits != 0; bits &= bits - 1) {
      const std::size_t k = w * 64 + static_cast<std::size_t>(std::countr_zero(bits));
      firsts.push_back(k);
      starts.push_back(place);
      for (std::size_t s = 0; s < slices; ++s) place += std::exchange(next[s * nk + k], place);
    }
  }
  starts.push_back(place);
  records.resize(total);
  seconds.resize(total + 3);  // read past the last group (`group` below)
  parallel_for_chunks(slices, threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t s = begin; s < end; ++s) {
      std::size_t* row = next.data() + s * nk;
      const auto [from, to] = slice(s);
      each_item(from, to, [&, row](std::uint64_t key, const T* record) {
        CRUMPLE_ASSERT((key & 0xFFFFFFFFu) <= 0x7FFFFFFFu);
        const std::size_t place = row[key >> 32]++;
        records[place] = record;
        seconds[place] = static_cast<std::int32_t>(key & 0x7FFFFFFFu);
      });
    }
  });
  for (const std::size_t k : firsts) {
    for (std::size_t s = 0; s < slices; ++s) next[s * nk + k] = 0;
  }
  scratch.clean = true;
  // Ranges of first criteria holding about total / ranges records each, four per thread: the
  // threads claim them as they go, so that one whose records come slower (from the other core's
  // cache) does fewer instead of leaving the others waiting.
  const std::size_t ranges = workers == 1 ? 1 : 4 * workers;
  bound.assign(1, 0);
  for (std::size_t r = 1; r < ranges; ++r) {
    const auto it = std::lower_bound(starts.begin(), starts.end() - 1, total * r / ranges);
    bound.push_back(std::max(bound.back(), static_cast<std::size_t>(it - starts.begin())));
  }
  bound.push_back(firsts.size());
}

/// Records of keys handed in alone, made `kMadeAtOnce` at a time where they go: make(keys, n,
/// made) appends the records of keys[0, n) to `made`.
template <class T, class Make>
class MadeRecords {
 public:
  static constexpr std::size_t kMadeAtOnce = 256;
  MadeRecords(std::vector<T>& dest, const Make& make) : dest_(dest), make_(make) {
    at_.reserve(kMadeAtOnce);
    keys_.reserve(kMadeAtOnce);
    made_.reserve(kMadeAtOnce + 4);
  }
  /// dest[place] = the record of key, at the latest at the next `flush`.
  void put(std::size_t place, std::uint64_t key) {
    at_.push_back(place);
    keys_.push_back(key);
    if (keys_.size() == kMadeAtOnce) flush();
  }
  void flush() {
    if (keys_.empty()) return;
    made_.clear();
    make_(keys_.data(), keys_.size(), made_);
    CRUMPLE_ASSERT(made_.size() == keys_.size());
    for (std::size_t i = 0; i < at_.size(); ++i) dest_[at_[i]] = made_[i];
    at_.clear();
    keys_.clear();
  }

 private:
  std::vector<T>& dest_;
  const Make& make_;
  std::vector<std::size_t> at_;
  std::vector<std::uint64_t> keys_;
  std::vector<T> made_;
};

/// Second step of `gather_sorted`: sizes dest (its storage given back first when it must grow,
/// so that the old and the new are never held together) and copies the records placed by
/// `gather_place` into it; make(keys, n, made) appends the records of n keys handed in alone
/// to `made` (`MadeRecords`).
template <class T, class Make>
void gather_copy(std::vector<T>& dest, int threads, GatherScratch& scratch, const Make& make) {
  using Item = GatherScratch::Item;
  const std::size_t total = scratch.total;
  if (total > dest.capacity()) std::vector<T>().swap(dest);
  dest.resize(total);
  if (total == 0) return;
  if (scratch.listed) {
    const Item* from = scratch.items.data();
    parallel_for_chunks(total, threads, 4096, [&](std::size_t begin, std::size_t end) {
      MadeRecords<T, Make> made(dest, make);
      for (std::size_t j = begin; j < end; ++j) {
        if (j + 48 < end && from[j + 48].record != nullptr) {  // the records are scattered: fetch ahead
          const auto* ahead = static_cast<const char*>(from[j + 48].record);
          __builtin_prefetch(ahead);
          __builtin_prefetch(ahead + sizeof(T) - 1);
        }
        if (from[j].record != nullptr) {
          dest[j] = *static_cast<const T*>(from[j].record);
        } else {
          made.put(j, from[j].key);
        }
      }
      made.flush();
    });
    return;
  }
  const auto& records = scratch.records;
  const auto& seconds = scratch.seconds;
  const auto& starts = scratch.starts;
  const auto& bound = scratch.bound;
  const std::size_t ranges = bound.size() - 1;
  constexpr std::size_t kRanked = 128;  // more items under one first criterion: sorted, then copied
  parallel_for_chunks(ranges, threads, 1, [&](std::size_t begin, std::size_t end) {
    std::vector<std::uint64_t> order;  // a large group's (second criterion, item), sorted
    MadeRecords<T, Make> made(dest, make);
    for (std::size_t r = begin; r < end; ++r) {
      for (std::size_t g = bound[r]; g < std::max(bound[r], bound[r + 1]); ++g) {
        const std::size_t first = starts[g];
        const std::size_t n = starts[g + 1] - first;
        // The records are scattered: fetch ahead.
        for (std::size_t j = first + 48; j < std::min(first + n + 48, total); ++j) {
          const auto* ahead = static_cast<const char*>(records[j]);
          if (ahead == nullptr) continue;
          __builtin_prefetch(ahead);
          __builtin_prefetch(ahead + sizeof(T) - 1);
        }
        const std::uint64_t high = static_cast<std::uint64_t>(scratch.firsts[g]) << 32;
        const auto put = [&](std::size_t rank, std::size_t item) {
          const void* record = records[first + item];
          if (record != nullptr) {
            dest[first + rank] = *static_cast<const T*>(record);
          } else {
            made.put(first + rank, high | static_cast<std::uint32_t>(seconds[first + item]));
          }
        };
        if (n > kRanked) {
          order.resize(n);
          for (std::size_t i = 0; i < n; ++i) {
            order[i] = static_cast<std::uint64_t>(seconds[first + i]) << 32 | i;
          }
          std::sort(order.begin(), order.end());
          for (std::size_t i = 0; i < n; ++i) put(i, order[i] & 0xFFFFFFFFu);
          continue;
        }
        // An item's place: how many of the group's second criteria are smaller than its own,
        // counted for four items at a time (a loop the compiler runs in vector lanes; the
        // criteria are padded by three, and items past the group are not placed).
        const std::int32_t* group = seconds.data() + first;
        for (std::size_t i = 0; i < n; i += 4) {
          const std::int32_t x0 = group[i], x1 = group[i + 1], x2 = group[i + 2], x3 = group[i + 3];
          std::uint32_t r0 = 0, r1 = 0, r2 = 0, r3 = 0;
          for (std::size_t j = 0; j < n; ++j) {
            const std::int32_t y = group[j];
            r0 += y < x0 ? 1u : 0u;
            r1 += y < x1 ? 1u : 0u;
            r2 += y < x2 ? 1u : 0u;
            r3 += y < x3 ? 1u : 0u;
          }
          put(r0, i);
          if (i + 1 < n) put(r1, i + 1);
          if (i + 2 < n) put(r2, i + 2);
          if (i + 3 < n) put(r3, i + 3);
        }
      }
    }
    made.flush();
  });
}

/// Both steps (see `gather_place`).
template <class T, class Make>
void gather_sorted(std::vector<T>& dest, const std::vector<KeyedList<T>>& parts, Index keys, int threads,
                   GatherScratch& scratch, const Make& make) {
  gather_place(parts, keys, threads, scratch);
  gather_copy(dest, threads, scratch, make);
}

}  // namespace crumple::detail

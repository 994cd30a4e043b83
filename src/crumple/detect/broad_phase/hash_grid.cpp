#include <crumple/core/error.hpp>
#include <crumple/core/parallel.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/broad_phase/box_tree_detail.hpp>
#include <crumple/detect/broad_phase/hash_grid.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <string>

namespace crumple {

namespace {

std::uint64_t next_prime(std::uint64_t n) {
  if (n <= 2) return 2;
  for (std::uint64_t p = n | 1u;; p += 2) {
    bool prime = true;
    for (std::uint64_t d = 3; d * d <= p; d += 2) {
      if (p % d == 0) {
        prime = false;
        break;
      }
    }
    if (prime) return p;
  }
}

/// Teschner et al.'s hash of cell (i, j, k), unsigned 64-bit wraparound then mod n.
inline std::uint32_t hash_cell(std::int32_t i, std::int32_t j, std::int32_t k, std::uint64_t n) {
  const std::uint64_t h = (static_cast<std::uint64_t>(static_cast<std::int64_t>(i)) * 73856093ull) ^
                          (static_cast<std::uint64_t>(static_cast<std::int64_t>(j)) * 19349663ull) ^
                          (static_cast<std::uint64_t>(static_cast<std::int64_t>(k)) * 83492791ull);
  return static_cast<std::uint32_t>(h % n);
}

}  // namespace

HashParams HashParams::from_spec(const MethodSpec& spec) {
  HashParams p;
  p.cell = spec.get_double("cell", p.cell);
  if (!(std::isfinite(p.cell) && p.cell >= 0)) {
    throw InputError("method " + spec.to_string() + ": cell must be a number >= 0");
  }
  const long long table = spec.get_int("table", static_cast<long long>(p.table));
  if (table < 0 || table > (1ll << 31)) {
    throw InputError("method " + spec.to_string() + ": table must be in 0..2^31");
  }
  p.table = static_cast<std::uint64_t>(table);
  return p;
}

HashGrid::HashGrid(HashParams params) : params_(params) {}

void HashGrid::build(const Topology& topology) {
  topo_ = &topology;
  cell_size_ = 0;
  table_size_ = 0;
  bucket_start_.assign(1, 0);
  sorted_.clear();
}

void HashGrid::update(const FrameInput& in, DetectorStats& stats) {
  CRUMPLE_CHECK(topo_ != nullptr, "hash: update before build");
  const Topology& topo = *topo_;
  threads_ = in.threads;
  const std::size_t nf = static_cast<std::size_t>(topo.num_faces());
  if (nf == 0) return;
  const auto t0 = std::chrono::steady_clock::now();
  face_boxes(topo, in, in.continuous, boxes_);
  if (cell_size_ == 0) {
    // Of the finite edges: one NaN vertex made the mean NaN, and the cells size 1 whatever the
    // mesh's scale.
    const Scalar mean = edge_length_stats(topo, in.positions).mean;
    cell_size_ = params_.cell > 0 ? params_.cell * mean : std::max(mean, 4 * in.radius);
    if (!(cell_size_ > 0)) cell_size_ = 1;
  }
  const Scalar inv = 1 / cell_size_;
  ranges_.resize(nf);
  entry_offset_.resize(nf + 1);
  oversized_flag_.assign(nf, 0);
  std::atomic<bool> too_fine{false};
  parallel_for_chunks(nf, in.threads, 4096, [&](std::size_t begin, std::size_t end) {
    bool bad = false;
    for (std::size_t f = begin; f < end; ++f) {
      std::array<std::int32_t, 6> r{0, 0, 0, -1, -1, -1};  // no cell
      double span = 1;  // cells of the box, in floating point (no overflow)
      bool out_of_range = false;
      // An empty box (every corner NaN) is in no cell.
      for (int a = 0; a < 3 && boxes_[f].lo[0] <= boxes_[f].hi[0]; ++a) {
        const Scalar lo = std::floor(boxes_[f].lo[a] * inv);
        const Scalar hi = std::floor(boxes_[f].hi[a] * inv);
        out_of_range |= !(std::fabs(lo) < 1e9 && std::fabs(hi) < 1e9);
        span *= hi - lo + 1;
        r[static_cast<std::size_t>(a)] = static_cast<std::int32_t>(std::clamp(lo, -1e9, 1e9));
        r[static_cast<std::size_t>(a) + 3] = static_cast<std::int32_t>(std::clamp(hi, -1e9, 1e9));
      }
      if (boxes_[f].lo[0] <= boxes_[f].hi[0] && !(span <= kMaxCellsPerFace)) {
        // Oversized: in no cell, tested against every face by box (self_pairs).
        oversized_flag_[f] = 1;
        r = {0, 0, 0, -1, -1, -1};
      } else {
        bad |= out_of_range;
      }
      ranges_[f] = r;
      std::size_t cells = 1;
      for (std::size_t a = 0; a < 3; ++a) {
        cells *= static_cast<std::size_t>(std::max<std::int64_t>(0, std::int64_t{r[a + 3]} - r[a] + 1));
      }
      entry_offset_[f + 1] = bad ? 0 : cells;
    }
    if (bad) too_fine.store(true, std::memory_order_relaxed);
  });
  if (too_fine) {
    throw InputError("hash: cell size " + std::to_string(cell_size_) +
                     " is too small for the coordinates of this mesh");
  }
  oversized_.clear();
  for (std::size_t f = 0; f < nf; ++f) {
    if (oversized_flag_[f]) oversized_.push_back(static_cast<Index>(f));
  }
  entry_offset_[0] = 0;
  for (std::size_t f = 0; f < nf; ++f) entry_offset_[f + 1] += entry_offset_[f];
  const std::size_t entries = entry_offset_[nf];
  if (entries >= (std::size_t{1} << 32)) {
    throw InputError("hash: " + std::to_string(entries) + " cell entries (over 2^32): cell size too small");
  }
  if (table_size_ == 0) {
    table_size_ = params_.table > 0 ? params_.table : next_prime(2 * static_cast<std::uint64_t>(entries));
  }
  const std::uint64_t n = table_size_;
  entry_bucket_.resize(entries);
  parallel_for_chunks(nf, in.threads, 4096, [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) {
      const auto& r = ranges_[f];
      std::size_t e = entry_offset_[f];
      for (std::int32_t i = r[0]; i <= r[3]; ++i)
        for (std::int32_t j = r[1]; j <= r[4]; ++j)
          for (std::int32_t k = r[2]; k <= r[5]; ++k) entry_bucket_[e++] = hash_cell(i, j, k, n);
    }
  });
  // Counting sort of the entries by bucket.
  bucket_start_.assign(n + 1, 0);
  for (std::size_t e = 0; e < entries; ++e) ++bucket_start_[entry_bucket_[e] + 1];
  for (std::uint64_t b = 0; b < n; ++b) bucket_start_[b + 1] += bucket_start_[b];
  sorted_.resize(entries);
  {
    std::vector<std::uint32_t> cursor(bucket_start_.begin(), bucket_start_.end() - 1);
    for (std::size_t f = 0; f < nf; ++f) {
      const auto& r = ranges_[f];
      std::size_t e = entry_offset_[f];
      for (std::int32_t i = r[0]; i <= r[3]; ++i)
        for (std::int32_t j = r[1]; j <= r[4]; ++j)
          for (std::int32_t k = r[2]; k <= r[5]; ++k) {
            sorted_[cursor[entry_bucket_[e++]]++] = Entry{static_cast<Index>(f), {i, j, k}};
          }
    }
  }
  stats.set("refit_ms", ms_since(t0));
  stats.set("cell_size", cell_size_);
  stats.set("table_size", static_cast<double>(n));
  stats.set("entries", static_cast<double>(entries));
  stats.set("hash_cells", static_cast<double>(entries));
  stats.set("hash_oversized", static_cast<double>(oversized_.size()));
}

void HashGrid::self_pairs(CandidateBuffer& out, DetectorStats& stats) {
  const Topology& topo = *topo_;
  if (topo.num_faces() == 0) return;
  const std::uint64_t n = table_size_;
  const auto t1 = std::chrono::steady_clock::now();
  // Bucket-major: pairs of entries of one bucket that are the same cell (sequential access).
  parallel_for_chunks(n, threads_, 4096, [&](std::size_t begin, std::size_t end) {
    std::vector<FacePair> local = out.take();
    for (std::size_t b = begin; b < end; ++b) {
      const std::uint32_t s0 = bucket_start_[b], s1 = bucket_start_[b + 1];
      if (s1 - s0 < 2) continue;
      for (std::uint32_t s = s0; s < s1; ++s) {
        const Entry& ea = sorted_[s];
        const std::size_t f = static_cast<std::size_t>(ea.face);
        const auto& r = ranges_[f];
        for (std::uint32_t t = s + 1; t < s1; ++t) {
          const Entry& eb = sorted_[t];
          if (ea.cell[0] != eb.cell[0] || ea.cell[1] != eb.cell[1] || ea.cell[2] != eb.cell[2]) continue;
          const std::size_t g = static_cast<std::size_t>(eb.face);
          const auto& rg = ranges_[g];
          // Report from the cell of the lower corner of the boxes' intersection only.
          if (std::max(r[0], rg[0]) != ea.cell[0] || std::max(r[1], rg[1]) != ea.cell[1] ||
              std::max(r[2], rg[2]) != ea.cell[2])
            continue;
          if (!boxes_[f].overlaps(boxes_[g])) continue;
          if (faces_share_vertex(topo.face(ea.face), topo.face(eb.face))) continue;
          local.push_back({std::min(ea.face, eb.face), std::max(ea.face, eb.face)});
        }
      }
      out.flush_if_full(local);
    }
    out.add(std::move(local));
  });
  std::size_t oversized_tests = 0;
  if (!oversized_.empty()) {
    // Every face queries a box tree over the oversized faces' boxes, so the work is about
    // F log(oversized) plus the pairs found, not F x oversized. A pair of two oversized faces is
    // reported from the larger index only, so every pair is reported once.
    oversized_boxes_.resize(oversized_.size());
    for (std::size_t i = 0; i < oversized_.size(); ++i) {
      oversized_boxes_[i] = boxes_[static_cast<std::size_t>(oversized_[i])];
    }
    detail::BoxTree tree;
    tree.build(oversized_boxes_);
    std::atomic<std::size_t> tests{0};
    parallel_for_chunks(topo.num_faces(), threads_, 1024, [&](std::size_t begin, std::size_t end) {
      std::vector<FacePair> local = out.take();
      std::size_t chunk_tests = 0;
      for (std::size_t g = begin; g < end; ++g) {
        const Index gi = static_cast<Index>(g);
        chunk_tests += tree.query(boxes_[g], [&](std::uint32_t i) {
          const Index o = oversized_[i];
          if (o == gi || (oversized_flag_[g] && o > gi)) return;
          if (faces_share_vertex(topo.face(o), topo.face(gi))) return;
          local.push_back({std::min(o, gi), std::max(o, gi)});
        });
        out.flush_if_full(local);
      }
      tests.fetch_add(chunk_tests, std::memory_order_relaxed);
      out.add(std::move(local));
    });
    oversized_tests = tests.load();
  }
  stats.set("hash_oversized_tests", static_cast<double>(oversized_tests));
  stats.set("traversal_ms", ms_since(t1));
}

}  // namespace crumple

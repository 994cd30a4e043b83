#pragma once
/// \file
/// `hash`: optimised spatial hashing (Teschner, Heidelberger, Müller, Pomeranets & Gross,
/// VMV 2003) adapted to vertex–face and edge–edge proximity, a broad phase
/// (broad_phase.hpp) of the exact detector.
///
/// Every frame, each face's box (current positions — for a continuous query, both ends of the
/// step — inflated by half the padded thickness) is
/// entered into every grid cell it overlaps; cell (i, j, k) goes to bucket
/// ((i p1) xor (j p2) xor (k p3)) mod n with the paper's primes, in unsigned 64-bit arithmetic.
/// Buckets are filled by a counting sort, so no table clearing and no per-bucket allocation.
/// Then, bucket by bucket (sequential memory access, in parallel over buckets), two entries
/// give a candidate when they are the same cell c (hash collisions only cost time), c is the
/// cell of the lower corner of the two boxes' intersection (so every pair is reported from
/// exactly one cell), the boxes overlap and the faces share no vertex. A face whose box spans
/// more than `kMaxCellsPerFace` cells ("oversized") enters no cell, so the entries are at most
/// that many per face whatever the faces' sizes; every face then queries a box tree over the
/// oversized faces' boxes, which costs about log(oversized) box tests per face plus the pairs
/// found. The result never depends on the cell size or table size. Stats: `hash_cells`,
/// `hash_oversized` and `hash_oversized_tests` (the tree's box tests).
/// Spec: `hash:cell=C,table=N` — C is the cell size as a multiple of the mean edge length of
/// the first frame (0 = automatic: max(mean edge, 2 h)); N the bucket count (0 = the smallest
/// prime >= 2 x the entries of the first frame); plus `max_contacts`, `overflow`.

#include <crumple/detect/broad_phase/broad_phase.hpp>

#include <cstdint>
#include <vector>

namespace crumple {

struct HashParams {
  double cell = 0;         ///< cell size / mean edge length; 0 = automatic
  std::uint64_t table = 0;  ///< number of buckets; 0 = automatic
  static HashParams from_spec(const MethodSpec& spec);
  bool operator==(const HashParams&) const = default;
};

class HashGrid final : public BroadPhase {
 public:
  explicit HashGrid(HashParams params);
  Method method() const override { return Method::Hash; }
  void build(const Topology& topology) override;
  void update(const FrameInput& in, DetectorStats& stats) override;
  void self_pairs(CandidateBuffer& out, DetectorStats& stats) override;

 private:
  struct Entry {
    Index face;
    std::int32_t cell[3];
  };
  /// A face whose box spans more cells than this is "oversized": it enters no cell and is
  /// found by the other faces through a box tree instead, so the grid holds at most this many
  /// entries per face whatever the faces' sizes.
  static constexpr double kMaxCellsPerFace = 64;
  HashParams params_;
  const Topology* topo_ = nullptr;
  int threads_ = 0;       ///< of the last update
  Scalar cell_size_ = 0;  ///< fixed at the first frame
  std::uint64_t table_size_ = 0;
  std::vector<Box> boxes_;
  std::vector<std::array<std::int32_t, 6>> ranges_;  ///< cell range of each face box
  std::vector<std::size_t> entry_offset_;            ///< per face: first entry
  std::vector<std::uint32_t> entry_bucket_;          ///< per entry (face-major order)
  std::vector<std::uint32_t> bucket_start_;          ///< table_size_ + 1
  std::vector<Entry> sorted_;                        ///< entries grouped by bucket
  std::vector<std::uint8_t> oversized_flag_;         ///< per face: 1 when oversized
  std::vector<Index> oversized_;                     ///< the oversized faces, ascending
  std::vector<Box> oversized_boxes_;                 ///< their boxes, in the same order
};

}  // namespace crumple

#pragma once
// The triangular solves of a prefactored L D Lᵀ (projective dynamics' global step), with L stored
// as dense supernodal blocks in single precision: internal to sim (integrator.cpp), tested
// against a plain sweep over the same factor in tests/sim/supernodal_test.cpp.

#include <crumple/core/types.hpp>

#include <Eigen/SparseCore>

#include <array>
#include <cstddef>
#include <vector>

namespace crumple::sim::detail {

/// x ← (L D Lᵀ)⁻¹ x for three right-hand sides at once (the coordinates of `Vec3`), L unit lower
/// triangular, over L's entries rounded to single precision and summed in double.
///
/// Storage. A supernode is a run of consecutive columns c₀..c₁ in which each column's parent in
/// the elimination tree is the next one: the structure of column c then lies in c + 1..c₁ and
/// the structure of c₁ (struct(c) \ {parent} ⊆ struct(parent)), so the supernode is dense over
/// its local rows: its own columns, then R = struct(c₁) below them, zeros stored where a column
/// lacks a row (relaxed amalgamation: a column joins the run while at most `relax` of the slots
/// are such zeros). The columns go in blocks of four; a block stores its entries from its own
/// rows down, in chunks of 4 rows × 4 columns (each column's 4 rows contiguous), so one block is
/// one contiguous stream; local rows are padded to multiples of 4 with zeros. Each supernode
/// keeps its row list once and one copy serves both sweeps. Forward, block by block: the
/// block's 4 × 4 triangle, then u += P y over the rows below it (by coordinate), R's part
/// scattered at the end; backward, R's rows gathered once, then from the last block: Pᵀ g over
/// the rows below, the block's triangle, the solved values joining g. Each entry below a
/// block's triangle is read once per sweep for three multiply-adds (x, y, z), four rows at a
/// time (GCC vector extensions: one AVX register, or two SSE ones; no fused multiply-adds, so
/// the same bits on every x86-64 CPU).
///
/// Threads. The elimination tree is split into two disjoint forests and the rest (`top`, the
/// separators above them): the forward sweep runs each forest on its own thread, accumulating
/// its updates of top rows in its own buffer, then the top; the backward sweep the top, then the
/// forests. Row i of L refers only to i's descendants and column j only to j's ancestors, so the
/// forests never touch each other's rows. The split depends on the factor only, never on the
/// thread count: every sum runs in a fixed order, the same bits on 1 and 2 threads.
class SupernodalSolve {
 public:
  /// The most zeros a relaxed supernode may store, as a fraction of its slots.
  static constexpr double kRelax = 0.2;

  /// Sizes of the plan, for tests and benchmarks.
  struct Stats {
    std::size_t supernodes = 0;  ///< number of supernodes
    std::size_t nonzeros = 0;    ///< strictly lower entries of L
    std::size_t stored = 0;      ///< floats stored (entries, zeros and padding)
    std::size_t widest = 0;      ///< the most columns of one supernode
    std::size_t top = 0;         ///< columns outside the two forests (the serial part)
  };

  /// Plans the solves for the factor L D Lᵀ. `strict_lower`: L's entries below the diagonal,
  /// m × m, compressed by columns with each column's rows increasing (as Eigen's simplicial
  /// factors store them); `diagonal`: D's m entries, all nonzero. `relax`: the most zeros a
  /// supernode may store as a fraction of its slots (0: fundamental supernodes only).
  void plan(const Eigen::SparseMatrix<Scalar>& strict_lower, const Eigen::Matrix<Scalar, Eigen::Dynamic, 1>& diagonal,
            double relax = kRelax);

  /// x ← (L D Lᵀ)⁻¹ x, x of size m (L's rows in its order), the two forests on `threads`
  /// threads (at most two are used). Relative rounding about 1e-7 of x's scale from L's single
  /// precision.
  void solve(std::vector<Vec3>& x, int threads);

  Stats stats() const { return stats_; }

 private:
  struct Supernode {
    int first = 0;              // column c₀
    int width = 0;              // columns c₀..c₀ + width − 1
    int rows = 0;               // |R|
    int lead = 0;               // width rounded up to a multiple of 4: R's first local row
    int chunks = 0;             // local rows (lead + |R| rounded up to a multiple of 4) / 4
    std::size_t row_start = 0;  // R's rows in row_[row_start..), targets in target_[row_start..)
    std::size_t values = 0;     // its blocks in value_ (block b after the 16 (b chunks − b (b − 1) / 2) before)
  };
  /// Scratch of one thread: a supernode's updates of its local rows (forward) or its local
  /// rows' values (backward), by coordinate.
  struct Scratch {
    std::vector<Scalar> x, y, z;
  };

  void forward(std::size_t group, std::vector<Vec3>& x, Scratch& scratch, std::vector<Vec3>* partial) const;
  void backward(std::size_t group, std::vector<Vec3>& x, Scratch& scratch) const;

  std::array<std::vector<int>, 3> group_;  // supernodes of forest 0, forest 1 and the top, increasing
  std::vector<Supernode> node_;
  std::vector<int> row_;     // each supernode's rows R, increasing
  std::vector<int> target_;  // forward scatter of R's rows: a row of x, or ~slot in the forest's top buffer
  std::vector<float> value_;  // the supernodes' blocks
  std::vector<int> top_;      // top columns, increasing (slot t: top_[t])
  std::vector<Scalar> inverse_diagonal_;
  std::array<std::vector<Vec3>, 2> partial_;  // per forest: its updates of the top rows, by slot
  std::array<Scratch, 2> scratch_;
  Stats stats_;
};

}  // namespace crumple::sim::detail

#include <crumple/core/error.hpp>
#include <crumple/core/parallel.hpp>
#include <crumple/sim/supernodal_detail.hpp>

#include <algorithm>
#include <cstring>
#include <iterator>

namespace crumple::sim::detail {

namespace {

// Four doubles and four floats (GCC and Clang vector extensions: one AVX register, or two SSE
// ones in the clone without AVX).
using V4 = Scalar __attribute__((vector_size(32)));
using F4 = float __attribute__((vector_size(16)));

/// The sweeps are compiled twice, with AVX2 and without, and the CPU picks at load time (GCC's
/// function multiversioning). The library is built with -ffp-contract=off, so both round alike.
/// Under the sanitizers (and with Clang), one version.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(CRUMPLE_SANITIZED)
#define CRUMPLE_SWEEP_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define CRUMPLE_SWEEP_CLONES
#endif
#define CRUMPLE_SWEEP_INLINE inline __attribute__((always_inline))
// The helpers below are always inlined: no call passes a vector, so GCC's note on the AVX
// calling convention (-Wpsabi) does not apply.
#if defined(__GNUC__)
#pragma GCC diagnostic ignored "-Wpsabi"
#endif

CRUMPLE_SWEEP_INLINE V4 splat(Scalar s) { return V4{s, s, s, s}; }
/// Four floats widened to doubles (exact). Element by element, not `__builtin_convertvector`:
/// GCC 12 lowers that into two 2-wide conversions and an insert even in the AVX2 clone, where
/// this form becomes one `vcvtps2pd` from memory (3 of the forward sweep's 4 × 4 chunk's ~50
/// instructions per column block, measured in the disassembly).
CRUMPLE_SWEEP_INLINE V4 load(const float* p) {
  F4 f;
  std::memcpy(&f, p, sizeof f);
  return V4{f[0], f[1], f[2], f[3]};
}
CRUMPLE_SWEEP_INLINE V4 load(const Scalar* p) {
  V4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
CRUMPLE_SWEEP_INLINE void store(Scalar* p, V4 v) { std::memcpy(p, &v, sizeof v); }
/// (v₀ + v₁) + (v₂ + v₃): a lane sum in a fixed order.
CRUMPLE_SWEEP_INLINE Scalar lanes(V4 v) { return (v[0] + v[1]) + (v[2] + v[3]); }

/// u += Σ_j P_j y_j over the rows of a block's chunks (`chunks` chunks of 4 rows × Q columns,
/// each column's 4 rows contiguous), y the block's Q solved values, u by coordinate: per chunk,
/// t = P₀ y₀, t += P_j y_j in column order, u += t.
template <int Q>
CRUMPLE_SWEEP_INLINE void block_update(const float* p, std::size_t chunks, const Vec3* y, Scalar* ux, Scalar* uy,
                                       Scalar* uz) {
  V4 a[Q], b[Q], c[Q];
  for (int j = 0; j < Q; ++j) {
    a[j] = splat(y[j].x());
    b[j] = splat(y[j].y());
    c[j] = splat(y[j].z());
  }
  for (std::size_t k = 0; k < chunks; ++k, p += 4 * Q, ux += 4, uy += 4, uz += 4) {
    V4 v = load(p);
    V4 tx = v * a[0], ty = v * b[0], tz = v * c[0];
    for (int j = 1; j < Q; ++j) {
      v = load(p + 4 * j);
      tx += v * a[j];
      ty += v * b[j];
      tz += v * c[j];
    }
    store(ux, load(ux) + tx);
    store(uy, load(uy) + ty);
    store(uz, load(uz) + tz);
  }
}

/// s_j = Σ_r P_j[r] g_r over a block's chunks (as `block_update`), g by coordinate: each sum in
/// four lanes (rows ≡ 0, 1, 2, 3 mod 4) in chunk order, then the lanes (`lanes`).
template <int Q>
CRUMPLE_SWEEP_INLINE void block_dot(const float* p, std::size_t chunks, const Scalar* gx, const Scalar* gy,
                                    const Scalar* gz, Vec3* sum) {
  V4 sx[Q] = {}, sy[Q] = {}, sz[Q] = {};
  for (std::size_t k = 0; k < chunks; ++k, p += 4 * Q, gx += 4, gy += 4, gz += 4) {
    const V4 x = load(gx), y = load(gy), z = load(gz);
    for (int j = 0; j < Q; ++j) {
      const V4 v = load(p + 4 * j);
      sx[j] += v * x;
      sy[j] += v * y;
      sz[j] += v * z;
    }
  }
  for (int j = 0; j < Q; ++j) sum[j] = Vec3(lanes(sx[j]), lanes(sy[j]), lanes(sz[j]));
}

/// Floats before block b of a supernode whose rows span `chunks` chunks: the blocks before it
/// have four columns, block b' holds chunks b'..chunks − 1.
CRUMPLE_SWEEP_INLINE std::size_t block_offset(std::size_t b, std::size_t chunks) {
  return 16 * b * chunks - 8 * b * (b > 0 ? b - 1 : 0);
}

}  // namespace

void SupernodalSolve::plan(const Eigen::SparseMatrix<Scalar>& strict_lower,
                           const Eigen::Matrix<Scalar, Eigen::Dynamic, 1>& diagonal, double relax) {
  CRUMPLE_CHECK(strict_lower.rows() == strict_lower.cols() && diagonal.size() == strict_lower.cols(),
                "supernodal solve: L must be square, D of its size");
  CRUMPLE_CHECK(strict_lower.isCompressed(), "supernodal solve: L must be compressed");
  const auto m = static_cast<std::size_t>(strict_lower.cols());
  const int* outer = strict_lower.outerIndexPtr();
  const int* inner = strict_lower.innerIndexPtr();
  const Scalar* value = strict_lower.valuePtr();
  // Elimination tree: the parent of j is the first row below the diagonal in column j. Work of
  // a node: its row and its column; of a subtree, the sum over it (parents come after their
  // children).
  std::vector<int> parent(m, -1);
  std::vector<std::size_t> row_count(m, 0), work(m), subtree(m, 0);
  for (std::size_t j = 0; j < m; ++j) {
    for (int k = outer[j]; k < outer[j + 1]; ++k) {
      CRUMPLE_CHECK(static_cast<std::size_t>(inner[k]) > j && static_cast<std::size_t>(inner[k]) < m &&
                        (k == outer[j] || inner[k] > inner[k - 1]),
                    "supernodal solve: L's columns must hold increasing rows below the diagonal");
      ++row_count[static_cast<std::size_t>(inner[k])];
    }
  }
  for (std::size_t j = 0; j < m; ++j) {
    if (outer[j] < outer[j + 1]) parent[j] = inner[outer[j]];
    work[j] = 1 + static_cast<std::size_t>(outer[j + 1] - outer[j]) + row_count[j];
    subtree[j] += work[j];
    if (parent[j] >= 0) subtree[static_cast<std::size_t>(parent[j])] += subtree[j];
  }
  std::vector<int> child_start(m + 1, 0), children(m), roots;
  for (std::size_t j = 0; j < m; ++j) {
    if (parent[j] >= 0) ++child_start[static_cast<std::size_t>(parent[j]) + 1];
  }
  for (std::size_t j = 0; j < m; ++j) child_start[j + 1] += child_start[j];
  {
    std::vector<int> at(child_start.begin(), child_start.end() - 1);
    for (std::size_t j = 0; j < m; ++j) {
      if (parent[j] >= 0) {
        children[static_cast<std::size_t>(at[static_cast<std::size_t>(parent[j])]++)] = static_cast<int>(j);
      } else {
        roots.push_back(static_cast<int>(j));
      }
    }
  }
  std::size_t total = 0;
  for (const int r : roots) total += subtree[static_cast<std::size_t>(r)];
  // Greedy: pack the candidate subtrees into two bins (largest first, into the lighter one);
  // while that is unbalanced, move the heaviest candidate's root to the top and its children
  // into the candidates. Keep the packing of least cost (top + heavier bin).
  std::vector<int> candidates = roots, best_roots;
  std::vector<char> best_bin;
  std::size_t top_work = 0, best_cost = total;
  const auto heavier = [&](int x, int y) {
    return subtree[static_cast<std::size_t>(x)] > subtree[static_cast<std::size_t>(y)];
  };
  for (int expansion = 0; expansion < 4096 && !candidates.empty(); ++expansion) {
    std::sort(candidates.begin(), candidates.end(), heavier);
    std::array<std::size_t, 2> load{0, 0};
    std::vector<char> bin(candidates.size());
    for (std::size_t c = 0; c < candidates.size(); ++c) {
      const std::size_t into = load[0] <= load[1] ? 0 : 1;
      bin[c] = static_cast<char>(into);
      load[into] += subtree[static_cast<std::size_t>(candidates[c])];
    }
    if (const std::size_t cost = top_work + std::max(load[0], load[1]); cost < best_cost) {
      best_cost = cost;
      best_roots = candidates;
      best_bin = bin;
    }
    const std::size_t heaviest = subtree[static_cast<std::size_t>(candidates[0])];
    if (std::max(load[0], load[1]) - std::min(load[0], load[1]) < total / 64 || heaviest < total / 64) break;
    const auto r = static_cast<std::size_t>(candidates[0]);
    candidates.erase(candidates.begin());
    top_work += work[r];
    candidates.insert(candidates.end(), children.begin() + child_start[r], children.begin() + child_start[r + 1]);
  }
  // Forests only where they save a fifth of the work at least (else everything is top).
  std::vector<char> label(m, 2);
  if (5 * best_cost < 4 * total) {
    std::vector<int> stack;
    for (std::size_t c = 0; c < best_roots.size(); ++c) {
      stack.push_back(best_roots[c]);
      while (!stack.empty()) {
        const auto j = static_cast<std::size_t>(stack.back());
        stack.pop_back();
        label[j] = best_bin[c];
        stack.insert(stack.end(), children.begin() + child_start[j], children.begin() + child_start[j + 1]);
      }
    }
  }
  top_.clear();
  std::vector<int> top_slot(m, -1);
  for (std::size_t j = 0; j < m; ++j) {
    if (label[j] == 2) {
      top_slot[j] = static_cast<int>(top_.size());
      top_.push_back(static_cast<int>(j));
    }
  }
  // Supernodes: runs of columns of one part, each the parent of the one before, while the
  // stored zeros stay within `relax` of the slots.
  const auto count = [&](std::size_t j) { return static_cast<std::size_t>(outer[j + 1] - outer[j]); };
  node_.clear();
  row_.clear();
  target_.clear();
  value_.clear();
  for (auto& g : group_) g.clear();
  stats_ = Stats{};
  std::vector<int> where(m, -1);
  std::size_t most_rows = 0, most_width = 0;
  for (std::size_t j = 0; j < m;) {
    const std::size_t first = j;
    std::size_t nonzeros = count(j);
    for (++j; j < m && label[j] == label[first] && parent[j - 1] == static_cast<int>(j); ++j) {
      const std::size_t width = j - first + 1;
      const std::size_t slots = width * (width - 1) / 2 + width * count(j);
      if (static_cast<double>(slots - (nonzeros + count(j))) > relax * static_cast<double>(slots)) break;
      nonzeros += count(j);
    }
    const std::size_t last = j - 1, width = j - first;
    Supernode s;
    s.first = static_cast<int>(first);
    s.width = static_cast<int>(width);
    s.rows = static_cast<int>(count(last));
    s.lead = (s.width + 3) / 4 * 4;
    s.chunks = (s.lead + (s.rows + 3) / 4 * 4) / 4;
    s.row_start = row_.size();
    const auto part = static_cast<std::size_t>(label[first]);
    for (int k = outer[last]; k < outer[last + 1]; ++k) {
      const int i = inner[k];
      where[static_cast<std::size_t>(i)] = k - outer[last];
      row_.push_back(i);
      target_.push_back(part == 2 || label[static_cast<std::size_t>(i)] == label[first]
                            ? i
                            : ~top_slot[static_cast<std::size_t>(i)]);
    }
    // Local rows: the supernode's columns (padded to a multiple of 4), then R. Block b (columns
    // 4b..4b + 3, fewer in the last) holds the chunks of 4 local rows from chunk b on.
    const auto chunks = static_cast<std::size_t>(s.chunks), blocks = static_cast<std::size_t>(s.lead) / 4;
    s.values = value_.size();
    value_.resize(value_.size() + block_offset(blocks - 1, chunks) +
                      4 * (width - 4 * (blocks - 1)) * (chunks - (blocks - 1)),
                  0.0F);
    for (std::size_t k = 0; k < width; ++k) {
      const std::size_t c = first + k, b = k / 4, q = std::min<std::size_t>(4, width - 4 * b);
      for (int e = outer[c]; e < outer[c + 1]; ++e) {
        const auto i = static_cast<std::size_t>(inner[e]);
        CRUMPLE_ASSERT(i <= last || (where[i] >= 0 && row_[s.row_start + static_cast<std::size_t>(where[i])] == static_cast<int>(i)));
        const std::size_t local = i <= last ? i - first : static_cast<std::size_t>(s.lead + where[i]);
        value_[s.values + block_offset(b, chunks) + (local / 4 - b) * 4 * q + 4 * (k % 4) + local % 4] =
            static_cast<float>(value[e]);
      }
    }
    for (int k = outer[last]; k < outer[last + 1]; ++k) where[static_cast<std::size_t>(inner[k])] = -1;
    group_[part].push_back(static_cast<int>(node_.size()));
    node_.push_back(s);
    most_rows = std::max(most_rows, 4 * chunks);
    most_width = std::max(most_width, width);
  }
  for (std::size_t f = 0; f < 2; ++f) partial_[f].assign(top_.size(), Vec3::Zero());
  for (Scratch& s : scratch_) {
    s.x.assign(most_rows, 0);
    s.y.assign(most_rows, 0);
    s.z.assign(most_rows, 0);
  }
  inverse_diagonal_.resize(m);
  for (std::size_t j = 0; j < m; ++j) {
    CRUMPLE_CHECK(diagonal[static_cast<Eigen::Index>(j)] != 0, "supernodal solve: D must be nonzero");
    inverse_diagonal_[j] = 1 / diagonal[static_cast<Eigen::Index>(j)];
  }
  stats_.supernodes = node_.size();
  stats_.nonzeros = static_cast<std::size_t>(outer[m]);
  stats_.stored = value_.size();
  stats_.widest = most_width;
  stats_.top = top_.size();
}

/// L y = b over the supernodes of `group`, in place in x: block by block (four columns), the
/// block's own triangle, then its update of every local row below it (u, by coordinate); the
/// updates of R's rows scattered at the end (a forest's top rows into `partial`).
CRUMPLE_SWEEP_CLONES void SupernodalSolve::forward(std::size_t group, std::vector<Vec3>& x, Scratch& scratch,
                                                   std::vector<Vec3>* partial) const {
  if (partial) std::fill(partial->begin(), partial->end(), Vec3::Zero());
  Scalar* ux = scratch.x.data();
  Scalar* uy = scratch.y.data();
  Scalar* uz = scratch.z.data();
  for (const int id : group_[group]) {
    const Supernode& s = node_[static_cast<std::size_t>(id)];
    const auto chunks = static_cast<std::size_t>(s.chunks);
    std::fill_n(ux, 4 * chunks, 0.0);
    std::fill_n(uy, 4 * chunks, 0.0);
    std::fill_n(uz, 4 * chunks, 0.0);
    Vec3* column = x.data() + s.first;
    for (std::size_t b = 0; 4 * b < static_cast<std::size_t>(s.width); ++b) {
      const int q = std::min(4, s.width - 4 * static_cast<int>(b));
      const float* block = value_.data() + s.values + block_offset(b, chunks);
      std::array<Vec3, 4> y;
      for (int j = 0; j < q; ++j) {
        const std::size_t local = 4 * b + static_cast<std::size_t>(j);
        Vec3 v = column[local] - Vec3(ux[local], uy[local], uz[local]);
        for (int i = 0; i < j; ++i) v -= static_cast<Scalar>(block[4 * i + j]) * y[static_cast<std::size_t>(i)];
        y[static_cast<std::size_t>(j)] = v;
        column[local] = v;
      }
      const std::size_t below = chunks - b - 1, from = 4 * b + 4;
      const float* p = block + 4 * q;
      switch (q) {
        case 4: block_update<4>(p, below, y.data(), ux + from, uy + from, uz + from); break;
        case 3: block_update<3>(p, below, y.data(), ux + from, uy + from, uz + from); break;
        case 2: block_update<2>(p, below, y.data(), ux + from, uy + from, uz + from); break;
        default: block_update<1>(p, below, y.data(), ux + from, uy + from, uz + from); break;
      }
    }
    const int* target = target_.data() + s.row_start;
    const auto lead = static_cast<std::size_t>(s.lead);
    for (std::size_t r = 0; r < static_cast<std::size_t>(s.rows); ++r) {
      const Vec3 u(ux[lead + r], uy[lead + r], uz[lead + r]);
      if (target[r] >= 0) {
        x[static_cast<std::size_t>(target[r])] -= u;
      } else {
        (*partial)[static_cast<std::size_t>(~target[r])] += u;
      }
    }
  }
}

/// Lᵀ z = D⁻¹ y over the supernodes of `group` (last first), in place in x: R's rows gathered
/// (g, by coordinate), then block by block from the last, the block's sums over the local rows
/// below it, then its own triangle; each solved value joins g for the blocks before.
CRUMPLE_SWEEP_CLONES void SupernodalSolve::backward(std::size_t group, std::vector<Vec3>& x, Scratch& scratch) const {
  Scalar* gx = scratch.x.data();
  Scalar* gy = scratch.y.data();
  Scalar* gz = scratch.z.data();
  for (auto it = group_[group].rbegin(); it != group_[group].rend(); ++it) {
    const Supernode& s = node_[static_cast<std::size_t>(*it)];
    const auto chunks = static_cast<std::size_t>(s.chunks), lead = static_cast<std::size_t>(s.lead);
    const int* row = row_.data() + s.row_start;
    // The next supernode's row list, which this sweep reads in descending order too.
    if (std::next(it) != group_[group].rend()) {
      const Supernode& next = node_[static_cast<std::size_t>(*std::next(it))];
      for (std::size_t k = 0; k < static_cast<std::size_t>(next.rows); k += 16) __builtin_prefetch(row_.data() + next.row_start + k);
    }
    // R's rows, four at a time into whole vectors (a vector load of four scalar stores would
    // wait for them to leave the store buffer), zeros in the padding.
    const auto rows = static_cast<std::size_t>(s.rows);
    const Vec3 zero = Vec3::Zero();
    const auto at = [&](std::size_t k) -> const Vec3& { return k < rows ? x[static_cast<std::size_t>(row[k])] : zero; };
    for (std::size_t k = 0; k < rows; k += 4) {
      const Vec3 &a = at(k), &b = at(k + 1), &c = at(k + 2), &d = at(k + 3);
      store(gx + lead + k, V4{a.x(), b.x(), c.x(), d.x()});
      store(gy + lead + k, V4{a.y(), b.y(), c.y(), d.y()});
      store(gz + lead + k, V4{a.z(), b.z(), c.z(), d.z()});
    }
    Vec3* column = x.data() + s.first;
    for (std::size_t b = (static_cast<std::size_t>(s.width) + 3) / 4; b-- > 0;) {
      const int q = std::min(4, s.width - 4 * static_cast<int>(b));
      const float* block = value_.data() + s.values + block_offset(b, chunks);
      const std::size_t below = chunks - b - 1, from = 4 * b + 4;
      const float* p = block + 4 * q;
      // The next block this sweep reads lies just before this one in value_ (the block before
      // in this supernode, or the previous supernode's last): fetch as many bytes of it as this
      // block holds. Each block is read upwards but the blocks downwards, a pattern the
      // hardware's prefetch does not follow.
      const std::size_t at = s.values + block_offset(b, chunks);
      for (std::size_t f = at - std::min(at, 4 * static_cast<std::size_t>(q) * (below + 1) + 16); f < at; f += 16) {
        __builtin_prefetch(value_.data() + f);
      }
      std::array<Vec3, 4> sum;
      switch (q) {
        case 4: block_dot<4>(p, below, gx + from, gy + from, gz + from, sum.data()); break;
        case 3: block_dot<3>(p, below, gx + from, gy + from, gz + from, sum.data()); break;
        case 2: block_dot<2>(p, below, gx + from, gy + from, gz + from, sum.data()); break;
        default: block_dot<1>(p, below, gx + from, gy + from, gz + from, sum.data()); break;
      }
      std::array<Vec3, 4> z{zero, zero, zero, zero};
      for (int j = q - 1; j >= 0; --j) {
        const std::size_t local = 4 * b + static_cast<std::size_t>(j);
        Vec3 total = sum[static_cast<std::size_t>(j)];
        for (int i = j + 1; i < q; ++i) total += static_cast<Scalar>(block[4 * j + i]) * z[static_cast<std::size_t>(i)];
        z[static_cast<std::size_t>(j)] = inverse_diagonal_[static_cast<std::size_t>(s.first) + local] * column[local] - total;
        column[local] = z[static_cast<std::size_t>(j)];
      }
      store(gx + 4 * b, V4{z[0].x(), z[1].x(), z[2].x(), z[3].x()});
      store(gy + 4 * b, V4{z[0].y(), z[1].y(), z[2].y(), z[3].y()});
      store(gz + 4 * b, V4{z[0].z(), z[1].z(), z[2].z(), z[3].z()});
    }
  }
}

void SupernodalSolve::solve(std::vector<Vec3>& x, int threads) {
  CRUMPLE_CHECK(x.size() == inverse_diagonal_.size(), "supernodal solve: x must have L's size");
  parallel_for_chunks(2, threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) forward(f, x, scratch_[f], &partial_[f]);
  });
  for (std::size_t t = 0; t < top_.size(); ++t) x[static_cast<std::size_t>(top_[t])] -= partial_[0][t] + partial_[1][t];
  forward(2, x, scratch_[0], nullptr);
  backward(2, x, scratch_[0]);
  parallel_for_chunks(2, threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) backward(f, x, scratch_[f]);
  });
}

}  // namespace crumple::sim::detail

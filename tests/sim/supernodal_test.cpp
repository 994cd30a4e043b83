// The supernodal triangular solves of projective dynamics' factor against a plain sweep over the
// same factor and against Eigen's double-precision solve.
#include <crumple/sim/supernodal_detail.hpp>

#include <gtest/gtest.h>

#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cstdio>
#include <random>
#include <vector>

namespace crumple::sim {
namespace {

using Sparse = Eigen::SparseMatrix<Scalar>;

/// A cloth-like system on a g × g lattice, numbered as one nested-dissection step does: the
/// vertices left of the middle column, those right of it (each side column by column towards the
/// middle, so its fill stays in a band), then the column. Springs (stiffness in
/// [0.5, 1.5], seeded) to the 4 neighbours, one diagonal per cell and the neighbours two apart
/// (bending), a mass term 0.1 on the diagonal. With the natural ordering, its elimination tree has
/// two subtrees joined by the column's chain: both forests and the top carry work.
Sparse lattice_system(int g, unsigned seed) {
  const int middle = g / 2;
  std::vector<int> index(static_cast<std::size_t>(g * g));
  int next = 0;
  for (int x = 0; x < middle; ++x) {
    for (int y = 0; y < g; ++y) index[static_cast<std::size_t>(y * g + x)] = next++;
  }
  for (int x = g - 1; x > middle; --x) {
    for (int y = 0; y < g; ++y) index[static_cast<std::size_t>(y * g + x)] = next++;
  }
  for (int y = 0; y < g; ++y) index[static_cast<std::size_t>(y * g + middle)] = next++;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<Scalar> stiffness(0.5, 1.5);
  std::vector<Eigen::Triplet<Scalar>> t;
  const auto spring = [&](int x0, int y0, int x1, int y1) {
    if (x1 < 0 || x1 >= g || y1 < 0 || y1 >= g) return;
    const int a = index[static_cast<std::size_t>(y0 * g + x0)], b = index[static_cast<std::size_t>(y1 * g + x1)];
    const Scalar k = stiffness(rng);
    t.emplace_back(a, a, k);
    t.emplace_back(b, b, k);
    t.emplace_back(a, b, -k);
    t.emplace_back(b, a, -k);
  };
  for (int y = 0; y < g; ++y) {
    for (int x = 0; x < g; ++x) {
      t.emplace_back(index[static_cast<std::size_t>(y * g + x)], index[static_cast<std::size_t>(y * g + x)], 0.1);
      spring(x, y, x + 1, y);
      spring(x, y, x, y + 1);
      spring(x, y, x + 1, y + 1);
      spring(x, y, x + 2, y);
      spring(x, y, x, y + 2);
    }
  }
  Sparse a(g * g, g * g);
  a.setFromTriplets(t.begin(), t.end());
  return a;
}

/// (L D Lᵀ)⁻¹ b with L's entries rounded to single precision, one entry at a time in column order
/// (forward: each column's updates of the rows below it; backward: each column's sum over its
/// rows), the products and sums in double: the sum the supernodal solve computes, in another
/// order.
std::vector<Vec3> plain_solve(const Sparse& l, const Eigen::VectorXd& d, std::vector<Vec3> x) {
  const Eigen::Index m = l.cols();
  for (Eigen::Index j = 0; j < m; ++j) {
    for (Sparse::InnerIterator e(l, j); e; ++e) {
      x[static_cast<std::size_t>(e.index())] -= static_cast<Scalar>(static_cast<float>(e.value())) * x[static_cast<std::size_t>(j)];
    }
  }
  for (Eigen::Index j = m - 1; j >= 0; --j) {
    Vec3 sum = Vec3::Zero();
    for (Sparse::InnerIterator e(l, j); e; ++e) {
      sum += static_cast<Scalar>(static_cast<float>(e.value())) * x[static_cast<std::size_t>(e.index())];
    }
    x[static_cast<std::size_t>(j)] = (1 / d[j]) * x[static_cast<std::size_t>(j)] - sum;
  }
  return x;
}

Scalar largest(const std::vector<Vec3>& x) {
  Scalar most = 0;
  for (const Vec3& v : x) most = std::max(most, v.cwiseAbs().maxCoeff());
  return most;
}

Scalar largest_difference(const std::vector<Vec3>& x, const std::vector<Vec3>& y) {
  Scalar most = 0;
  for (std::size_t i = 0; i < x.size(); ++i) most = std::max(most, (x[i] - y[i]).cwiseAbs().maxCoeff());
  return most;
}

/// On a 31 × 31 lattice system (961 unknowns; fundamental supernodes, the default relaxation and
/// a loose one, so panels of 1 to many columns, padded and not): the supernodal solve on 1 and
/// 2 threads gives the same bits, within 1e-12 of the largest entry of the plain sweep over the
/// same single-precision factor (only the order of the sums differs), and within 1e-5 of
/// Eigen's double-precision solve (L's rounding to single precision).
TEST(Supernodal, SolveMatchesThePlainSweepOverTheSameFactor) {
  const Sparse a = lattice_system(31, 7);
  Eigen::SimplicialLDLT<Sparse, Eigen::Lower, Eigen::NaturalOrdering<int>> ldlt(a);
  ASSERT_EQ(ldlt.info(), Eigen::Success);
  const Sparse& l = ldlt.matrixL().nestedExpression();
  const Eigen::VectorXd d = ldlt.vectorD();
  const auto m = static_cast<std::size_t>(a.cols());
  std::mt19937 rng(11);
  std::uniform_real_distribution<Scalar> uniform(-1, 1);
  std::vector<Vec3> b(m);
  for (Vec3& v : b) v = Vec3(uniform(rng), uniform(rng), uniform(rng));
  const std::vector<Vec3> plain = plain_solve(l, d, b);
  std::vector<Vec3> exact(m);
  for (Eigen::Index c = 0; c < 3; ++c) {
    Eigen::VectorXd column(static_cast<Eigen::Index>(m));
    for (std::size_t i = 0; i < m; ++i) column[static_cast<Eigen::Index>(i)] = b[i][c];
    const Eigen::VectorXd solved = ldlt.solve(column);
    for (std::size_t i = 0; i < m; ++i) exact[i][c] = solved[static_cast<Eigen::Index>(i)];
  }
  for (const double relax : {0.0, detail::SupernodalSolve::kRelax, 0.5}) {
    SCOPED_TRACE("relax " + std::to_string(relax));
    detail::SupernodalSolve solve;
    solve.plan(l, d, relax);
    const auto stats = solve.stats();
    EXPECT_EQ(stats.nonzeros, static_cast<std::size_t>(l.nonZeros()));
    EXPECT_GE(stats.stored, stats.nonzeros);
    if (relax > 0) {
      EXPECT_LT(stats.supernodes, m / 8) << "columns are grouped";
    }
    EXPECT_GE(stats.widest, 8U) << "wide panels (four-column blocks and the rest)";
    EXPECT_GT(stats.top, 0U);
    EXPECT_LT(stats.top, m / 4) << "two forests below the top";
    std::vector<std::vector<Vec3>> ends;
    for (const int threads : {1, 2}) {
      std::vector<Vec3> x = b;
      solve.solve(x, threads);
      ends.push_back(x);
    }
    for (std::size_t i = 0; i < m; ++i) ASSERT_EQ(ends[0][i], ends[1][i]) << "row " << i;
    const Scalar scale = largest(plain);
    const Scalar to_plain = largest_difference(ends[0], plain) / scale;
    const Scalar to_exact = largest_difference(ends[0], exact) / largest(exact);
    EXPECT_LT(to_plain, 1e-12);
    EXPECT_LT(to_exact, 1e-5);
    std::printf("relax %.2f: %zu supernodes (widest %zu), %zu floats stored for %zu entries, %zu top columns; "
                "difference to the plain sweep %.2g, to the double solve %.2g\n",
                relax, stats.supernodes, stats.widest, stats.stored, stats.nonzeros, stats.top, to_plain, to_exact);
  }
}

}  // namespace
}  // namespace crumple::sim

#include <crumple/core/error.hpp>
#include <crumple/sim/integrator.hpp>

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseCore>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>

namespace crumple::sim {

namespace {

constexpr std::array<IntegratorKind, 4> kKinds{IntegratorKind::ExplicitEuler, IntegratorKind::SymplecticEuler,
                                               IntegratorKind::Rk4, IntegratorKind::ImplicitEuler};

/// a = M⁻¹ f (zero for pinned particles).
void accelerations(const Model& model, const ForceField& field, std::span<const Vec3> x,
                   std::span<const Vec3> v, std::vector<Vec3>& f, std::vector<Vec3>& a) {
  compute_forces(model, field, x, v, f);
  const auto inv_mass = model.inv_mass();
  a.resize(f.size());
  for (std::size_t i = 0; i < f.size(); ++i) a[i] = inv_mass[i] * f[i];
}

void check_step(const Model& model, const State& s, Scalar dt) {
  CRUMPLE_CHECK(dt > 0, "time step must be > 0");
  CRUMPLE_CHECK(s.x.size() == static_cast<std::size_t>(model.num_particles()) && s.v.size() == s.x.size(),
                "state must have #V positions and velocities");
}

class ExplicitEuler final : public Integrator {
 public:
  IntegratorKind kind() const override { return IntegratorKind::ExplicitEuler; }
  void step(const Model& model, const ForceField& field, State& s, Scalar h) override {
    check_step(model, s, h);
    accelerations(model, field, s.x, s.v, f_, a_);
    for (std::size_t i = 0; i < s.x.size(); ++i) {
      s.x[i] += h * s.v[i];
      s.v[i] += h * a_[i];
    }
    s.time += h;
  }

 private:
  std::vector<Vec3> f_, a_;
};

class SymplecticEuler final : public Integrator {
 public:
  IntegratorKind kind() const override { return IntegratorKind::SymplecticEuler; }
  void step(const Model& model, const ForceField& field, State& s, Scalar h) override {
    check_step(model, s, h);
    accelerations(model, field, s.x, s.v, f_, a_);
    for (std::size_t i = 0; i < s.x.size(); ++i) {
      s.v[i] += h * a_[i];
      s.x[i] += h * s.v[i];
    }
    s.time += h;
  }

 private:
  std::vector<Vec3> f_, a_;
};

class Rk4 final : public Integrator {
 public:
  IntegratorKind kind() const override { return IntegratorKind::Rk4; }
  void step(const Model& model, const ForceField& field, State& s, Scalar h) override {
    check_step(model, s, h);
    const std::size_t n = s.x.size();
    // k1
    accelerations(model, field, s.x, s.v, f_, a1_);
    xt_.resize(n);
    vt_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      xt_[i] = s.x[i] + 0.5 * h * s.v[i];
      vt_[i] = s.v[i] + 0.5 * h * a1_[i];
    }
    v2_ = vt_;
    accelerations(model, field, xt_, vt_, f_, a2_);
    for (std::size_t i = 0; i < n; ++i) {
      xt_[i] = s.x[i] + 0.5 * h * v2_[i];
      vt_[i] = s.v[i] + 0.5 * h * a2_[i];
    }
    v3_ = vt_;
    accelerations(model, field, xt_, vt_, f_, a3_);
    for (std::size_t i = 0; i < n; ++i) {
      xt_[i] = s.x[i] + h * v3_[i];
      vt_[i] = s.v[i] + h * a3_[i];
    }
    v4_ = vt_;
    accelerations(model, field, xt_, vt_, f_, a4_);
    for (std::size_t i = 0; i < n; ++i) {
      s.x[i] += (h / 6) * (s.v[i] + 2 * v2_[i] + 2 * v3_[i] + v4_[i]);
      s.v[i] += (h / 6) * (a1_[i] + 2 * a2_[i] + 2 * a3_[i] + a4_[i]);
    }
    s.time += h;
  }

 private:
  std::vector<Vec3> f_, a1_, a2_, a3_, a4_, xt_, vt_, v2_, v3_, v4_;
};

/// Backward Euler with one Newton step. The system matrix A = M − h ∂f/∂v − h² ∂f/∂x has a
/// fixed block pattern (diagonal blocks plus one block pair per spring), built once per model;
/// each step only refills the values in place.
class ImplicitEuler final : public Integrator {
 public:
  explicit ImplicitEuler(const IntegratorOptions& options) : options_(options) {}
  IntegratorKind kind() const override { return IntegratorKind::ImplicitEuler; }

  void step(const Model& model, const ForceField& field, State& s, Scalar h) override {
    check_step(model, s, h);
    const Index n = model.num_particles();
    const auto mass = model.mass();
    const auto inv_mass = model.inv_mass();
    const auto springs = model.springs();
    const auto damping = model.damping();
    prepare(model);

    compute_forces(model, field, s.x, s.v, f_);
    // b = h (f0 + h ∂f/∂x v0), accumulated per spring; A refilled block by block.
    b_.resize(3 * n);
    for (Index i = 0; i < n; ++i) b_.segment<3>(3 * i) = f_[static_cast<std::size_t>(i)];
    Scalar* values = a_.valuePtr();
    std::fill(values, values + a_.nonZeros(), Scalar(0));
    const auto add = [&](std::size_t block, Index col_particle, const Mat3& m) {
      // Entry (3i+r, 3j+c) lives at outer[3j+c] + block_row_offset + r.
      for (int c = 0; c < 3; ++c) {
        Scalar* col = values + a_.outerIndexPtr()[3 * col_particle + c] + block_offset_[block];
        for (int r = 0; r < 3; ++r) col[r] += m(r, c);
      }
    };
    const Scalar h2 = h * h;
    for (std::size_t k = 0; k < springs.size(); ++k) {
      const Spring& sp = springs[k];
      const auto ia = static_cast<std::size_t>(sp.a), ib = static_cast<std::size_t>(sp.b);
      const SpringBlocks blocks = spring_blocks(sp, damping[k], s.x[ia], s.x[ib]);
      const Mat3 m = -h * blocks.dv - h2 * blocks.dx;
      add(spring_block_[k][0], sp.a, m);   // (a, a)
      add(spring_block_[k][1], sp.b, m);   // (b, b)
      add(spring_block_[k][2], sp.b, -m);  // (a, b)
      add(spring_block_[k][3], sp.a, -m);  // (b, a)
      const Vec3 kv = blocks.dx * (s.v[ia] - s.v[ib]);
      b_.segment<3>(3 * sp.a) += h * kv;
      b_.segment<3>(3 * sp.b) -= h * kv;
    }
    for (Index i = 0; i < n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      Scalar diagonal = mass[k] + h * field.air_damping * mass[k];
      if (field.drag && field.drag->vertex == i) {
        diagonal += h * field.drag->damping + h2 * field.drag->stiffness;
        b_.segment<3>(3 * i) -= h * field.drag->stiffness * s.v[k];
      }
      add(diagonal_block_[k], i, diagonal * Mat3::Identity());
    }
    b_ *= h;
    // Pinned particles: zero their rows and columns, identity on the diagonal, Δv = 0.
    for (Index i = 0; i < n; ++i) {
      if (inv_mass[static_cast<std::size_t>(i)] != 0) continue;
      for (int c = 0; c < 3; ++c) {
        const Eigen::Index col = 3 * i + c;
        for (Eigen::Index p = a_.outerIndexPtr()[col]; p < a_.outerIndexPtr()[col + 1]; ++p) {
          const Eigen::Index row = a_.innerIndexPtr()[p];
          values[p] = row == col ? 1 : 0;
          if (row != col) pinned_row_zero(row, col);
        }
      }
      b_.segment<3>(3 * i).setZero();
    }
    cg_.setTolerance(options_.cg_tolerance);
    cg_.setMaxIterations(options_.cg_max_iterations);
    cg_.compute(a_);
    dv_ = cg_.solve(b_);
    last_iterations_ = static_cast<int>(cg_.iterations());
    for (Index i = 0; i < n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      if (inv_mass[k] != 0) s.v[k] += dv_.segment<3>(3 * i);
      s.x[k] += h * s.v[k];
    }
    s.time += h;
  }

 private:
  using Mat3 = Eigen::Matrix<Scalar, 3, 3>;
  using Sparse = Eigen::SparseMatrix<Scalar>;
  using Vector = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;

  /// Zeroes entry (row, col)'s symmetric partner (col, row).
  void pinned_row_zero(Eigen::Index row, Eigen::Index col) { a_.coeffRef(col, row) = 0; }

  /// Builds the block pattern when the model's springs differ from the cached ones.
  void prepare(const Model& model) {
    const auto springs = model.springs();
    const Index n = model.num_particles();
    bool same = pattern_n_ == n && pattern_pairs_.size() == springs.size();
    for (std::size_t k = 0; same && k < springs.size(); ++k) {
      same = pattern_pairs_[k] == std::array<Index, 2>{springs[k].a, springs[k].b};
    }
    if (same) return;
    pattern_n_ = n;
    pattern_pairs_.clear();
    std::vector<std::vector<Index>> neighbours(static_cast<std::size_t>(n));
    for (Index i = 0; i < n; ++i) neighbours[static_cast<std::size_t>(i)].push_back(i);
    for (const Spring& sp : springs) {
      pattern_pairs_.push_back({sp.a, sp.b});
      neighbours[static_cast<std::size_t>(sp.a)].push_back(sp.b);
      neighbours[static_cast<std::size_t>(sp.b)].push_back(sp.a);
    }
    std::vector<Eigen::Triplet<Scalar>> triplets;
    for (auto& list : neighbours) {
      std::sort(list.begin(), list.end());
      list.erase(std::unique(list.begin(), list.end()), list.end());
    }
    for (Index j = 0; j < n; ++j) {
      for (Index i : neighbours[static_cast<std::size_t>(j)]) {
        for (int c = 0; c < 3; ++c)
          for (int r = 0; r < 3; ++r) triplets.emplace_back(3 * i + r, 3 * j + c, 0.0);
      }
    }
    a_.resize(3 * n, 3 * n);
    a_.setFromTriplets(triplets.begin(), triplets.end());
    a_.makeCompressed();
    // Block (i, j) starts at row offset 3 * (rank of i among the neighbours of j) in each of
    // column j's three columns.
    const auto offset = [&](Index i, Index j) {
      const auto& list = neighbours[static_cast<std::size_t>(j)];
      return static_cast<std::size_t>(3 * (std::lower_bound(list.begin(), list.end(), i) - list.begin()));
    };
    block_offset_.clear();
    diagonal_block_.resize(static_cast<std::size_t>(n));
    for (Index i = 0; i < n; ++i) {
      diagonal_block_[static_cast<std::size_t>(i)] = block_offset_.size();
      block_offset_.push_back(offset(i, i));
    }
    spring_block_.resize(springs.size());
    for (std::size_t k = 0; k < springs.size(); ++k) {
      const Index a = springs[k].a, b = springs[k].b;
      const std::array<std::pair<Index, Index>, 4> blocks{{{a, a}, {b, b}, {a, b}, {b, a}}};
      for (int q = 0; q < 4; ++q) {
        spring_block_[k][static_cast<std::size_t>(q)] = block_offset_.size();
        block_offset_.push_back(offset(blocks[static_cast<std::size_t>(q)].first,
                                       blocks[static_cast<std::size_t>(q)].second));
      }
    }
  }

  IntegratorOptions options_;
  std::vector<Vec3> f_;
  Index pattern_n_ = -1;
  std::vector<std::array<Index, 2>> pattern_pairs_;
  Sparse a_;
  std::vector<std::size_t> block_offset_;  // row offset of each referenced block in its columns
  std::vector<std::size_t> diagonal_block_;
  std::vector<std::array<std::size_t, 4>> spring_block_;
  Vector b_, dv_;
  Eigen::ConjugateGradient<Sparse, Eigen::Lower | Eigen::Upper> cg_;
};

}  // namespace

std::string_view to_string(IntegratorKind kind) {
  switch (kind) {
    case IntegratorKind::ExplicitEuler: return "explicit-euler";
    case IntegratorKind::SymplecticEuler: return "symplectic-euler";
    case IntegratorKind::Rk4: return "rk4";
    case IntegratorKind::ImplicitEuler: return "implicit-euler";
  }
  return "?";
}

IntegratorKind parse_integrator(std::string_view name) {
  for (IntegratorKind k : kKinds) {
    if (to_string(k) == name) return k;
  }
  std::string valid;
  for (IntegratorKind k : kKinds) valid += (valid.empty() ? "" : ", ") + std::string(to_string(k));
  throw InputError("unknown integrator '" + std::string(name) + "' (valid: " + valid + ")");
}

std::span<const IntegratorKind> all_integrators() { return kKinds; }

std::unique_ptr<Integrator> make_integrator(IntegratorKind kind, const IntegratorOptions& options) {
  switch (kind) {
    case IntegratorKind::ExplicitEuler: return std::make_unique<ExplicitEuler>();
    case IntegratorKind::SymplecticEuler: return std::make_unique<SymplecticEuler>();
    case IntegratorKind::Rk4: return std::make_unique<Rk4>();
    case IntegratorKind::ImplicitEuler: return std::make_unique<ImplicitEuler>(options);
  }
  throw InputError("unknown integrator");
}

Scalar stable_time_step(const Model& model, IntegratorKind kind) {
  constexpr Scalar kInfinity = std::numeric_limits<Scalar>::infinity();
  if (kind == IntegratorKind::ImplicitEuler) return kInfinity;
  const auto mass = model.mass();
  std::vector<Scalar> row(mass.size(), 0);  // Gershgorin row sums of M^-1/2 K M^-1/2
  Scalar zeta = kInfinity;
  for (const Spring& s : model.springs()) {
    if (!(s.stiffness > 0)) continue;
    const auto a = static_cast<std::size_t>(s.a), b = static_cast<std::size_t>(s.b);
    const bool free_a = !model.pinned(s.a), free_b = !model.pinned(s.b);
    if (!free_a && !free_b) continue;
    const Scalar coupling = free_a && free_b ? s.stiffness / std::sqrt(mass[a] * mass[b]) : 0;
    if (free_a) row[a] += s.stiffness / mass[a] + coupling;
    if (free_b) row[b] += s.stiffness / mass[b] + coupling;
    zeta = std::min(zeta, s.damping_ratio);
  }
  const Scalar omega = std::sqrt(row.empty() ? 0 : *std::max_element(row.begin(), row.end()));
  if (!(omega > 0)) return kInfinity;
  switch (kind) {
    case IntegratorKind::ExplicitEuler:
      return (zeta < 1 ? 2 * zeta : 2 / (zeta + std::sqrt(zeta * zeta - 1))) / omega;
    case IntegratorKind::SymplecticEuler: {
      const Scalar u = 2 * (std::sqrt(zeta * zeta + 1) - zeta);
      return (zeta > 0 ? std::min(u, 1 / zeta) : u) / omega;
    }
    case IntegratorKind::Rk4: return 2.78 / omega;
    case IntegratorKind::ImplicitEuler: break;
  }
  return kInfinity;
}

}  // namespace crumple::sim

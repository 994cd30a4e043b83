#include <crumple/core/error.hpp>
#include <crumple/core/parallel.hpp>
#include <crumple/geometry/kernel_batch.hpp>
#include <crumple/sim/integrator.hpp>
#include <crumple/sim/supernodal_detail.hpp>

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>

namespace crumple::sim {

namespace {

constexpr std::array<IntegratorKind, 5> kKinds{IntegratorKind::ExplicitEuler, IntegratorKind::SymplecticEuler,
                                               IntegratorKind::Rk4, IntegratorKind::ImplicitEuler,
                                               IntegratorKind::Projective};

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

/// Nested dissection (George, *Nested dissection of a regular finite element mesh*, SIAM J.
/// Numer. Anal. 1973) as a fill-reducing ordering for Eigen's simplicial Cholesky, from the
/// matrix pattern only: in each connected part, a breadth-first level structure from a
/// pseudo-peripheral vertex; the smallest level with 35–65 % of the part before it separates
/// the two sides, which are ordered first (recursively), the level last; parts of at most
/// `kLeaf` vertices keep their breadth-first order. Every separator then splits the
/// elimination tree below it into two subtrees of similar size, which the parallel solve runs
/// side by side (AMD leaves a long, nearly dense chain on top instead).
struct NestedDissection {
  using PermutationType = Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int>;

  /// `a`: the full symmetric pattern. Sets `inverse` to the permutation Eigen expects from an
  /// ordering (entry k: the vertex eliminated k-th).
  template <class MatrixType>
  void operator()(const MatrixType& a, PermutationType& inverse) const {
    const auto n = static_cast<std::size_t>(a.rows());
    Graph g;
    g.start.assign(n + 1, 0);
    for (std::size_t j = 0; j < n; ++j) {
      for (typename MatrixType::InnerIterator it(a, static_cast<Eigen::Index>(j)); it; ++it) {
        if (static_cast<std::size_t>(it.index()) != j) g.adjacent.push_back(static_cast<int>(it.index()));
      }
      g.start[j + 1] = static_cast<int>(g.adjacent.size());
    }
    g.mark.assign(n, 0);
    g.level.assign(n, 0);
    std::vector<int> all(n);
    for (std::size_t i = 0; i < n; ++i) all[i] = static_cast<int>(i);
    g.dissect(all);
    inverse.resize(static_cast<Eigen::Index>(n));
    for (std::size_t k = 0; k < n; ++k) inverse.indices()[static_cast<Eigen::Index>(k)] = g.order[k];
  }

 private:
  static constexpr std::size_t kLeaf = 32;

  struct Graph {
    std::vector<int> start, adjacent;  // symmetric adjacency, by vertex
    std::vector<int> mark;             // the stamp of the part a vertex is in
    std::vector<int> level;
    std::vector<int> order;            // vertices in elimination order
    int stamp = 0;

    /// Breadth-first order of the vertices of part `tag` reachable from `source`, their levels
    /// in `level`.
    std::vector<int> search(int source, int tag) {
      const int seen = ++stamp;
      std::vector<int> queue{source};
      mark[static_cast<std::size_t>(source)] = seen;
      level[static_cast<std::size_t>(source)] = 0;
      for (std::size_t head = 0; head < queue.size(); ++head) {
        const auto v = static_cast<std::size_t>(queue[head]);
        for (int k = start[v]; k < start[v + 1]; ++k) {
          const auto w = static_cast<std::size_t>(adjacent[static_cast<std::size_t>(k)]);
          if (mark[w] != tag) continue;
          mark[w] = seen;
          level[w] = level[v] + 1;
          queue.push_back(static_cast<int>(w));
        }
      }
      for (const int v : queue) mark[static_cast<std::size_t>(v)] = tag;
      return queue;
    }

    /// Orders `part`: its connected components in turn, each searched from its vertex of least
    /// degree (the first in `part`'s order among equals), in the order of those vertices.
    void dissect(const std::vector<int>& part) {
      const int tag = ++stamp;
      for (const int v : part) mark[static_cast<std::size_t>(v)] = tag;
      const auto degree = [&](int v) { return start[static_cast<std::size_t>(v) + 1] - start[static_cast<std::size_t>(v)]; };
      std::vector<int> sources = part;
      std::stable_sort(sources.begin(), sources.end(), [&](int x, int y) { return degree(x) < degree(y); });
      for (const int source : sources) {
        if (mark[static_cast<std::size_t>(source)] != tag) continue;  // in a component done
        std::vector<int> component = search(source, tag);
        const int done = ++stamp;
        for (const int w : component) mark[static_cast<std::size_t>(w)] = done;
        dissect_connected(std::move(component));
      }
    }

    /// Orders a connected part given in breadth-first order: both sides of a separating level,
    /// then the level; a small part as it is.
    void dissect_connected(std::vector<int> queue) {
      if (queue.size() <= kLeaf) {
        order.insert(order.end(), queue.begin(), queue.end());
        return;
      }
      const int tag = ++stamp;
      for (const int v : queue) mark[static_cast<std::size_t>(v)] = tag;
      // Pseudo-peripheral source: the last vertex reached, twice.
      queue = search(queue.back(), tag);
      queue = search(queue.back(), tag);
      const auto levels = static_cast<std::size_t>(level[static_cast<std::size_t>(queue.back())]) + 1;
      std::vector<std::size_t> count(levels, 0);
      for (const int v : queue) ++count[static_cast<std::size_t>(level[static_cast<std::size_t>(v)])];
      const std::size_t total = queue.size();
      std::size_t separator = levels, before = 0;
      for (std::size_t l = 0; l < levels; ++l) {
        const bool balanced = 100 * before >= 35 * total && 100 * before <= 65 * total;
        if (balanced && (separator == levels || count[l] < count[separator])) separator = l;
        before += count[l];
      }
      if (separator == levels) {  // no level in the window (few, wide levels): the median one
        before = 0;
        for (separator = 0; 2 * (before + count[separator]) < total; ++separator) before += count[separator];
      }
      std::vector<int> low, high, middle;
      for (const int v : queue) {
        const auto l = static_cast<std::size_t>(level[static_cast<std::size_t>(v)]);
        (l < separator ? low : l > separator ? high : middle).push_back(v);
      }
      dissect(low);
      dissect(high);
      order.insert(order.end(), middle.begin(), middle.end());
    }
  };
};

/// Adds a spring's graph Laplacian, scaled by `weight`, to the triplets of the rows of its free
/// ends (`row` of a pinned particle is −1: left out).
void add_spring_triplets(const Spring& sp, Scalar weight, std::span<const Eigen::Index> row,
                         std::vector<Eigen::Triplet<Scalar>>& t) {
  const Eigen::Index ra = row[static_cast<std::size_t>(sp.a)], rb = row[static_cast<std::size_t>(sp.b)];
  if (ra >= 0) t.emplace_back(ra, ra, weight);
  if (rb >= 0) t.emplace_back(rb, rb, weight);
  if (ra >= 0 && rb >= 0) {
    t.emplace_back(ra, rb, -weight);
    t.emplace_back(rb, ra, -weight);
  }
}

/// Adds a hinge's `weight` w wᵀ to the triplets of the rows of its free vertices.
void add_hinge_triplets(const Hinge& hg, Scalar weight, std::span<const Eigen::Index> row,
                        std::vector<Eigen::Triplet<Scalar>>& t) {
  for (std::size_t i = 0; i < 4; ++i) {
    const Eigen::Index ri = row[static_cast<std::size_t>(hg.vertex[i])];
    if (ri < 0) continue;
    for (std::size_t j = 0; j < 4; ++j) {
      const Eigen::Index rj = row[static_cast<std::size_t>(hg.vertex[j])];
      if (rj >= 0) t.emplace_back(ri, rj, weight * hg.weight[i] * hg.weight[j]);
    }
  }
}

/// Backward Euler with one Newton step. The system matrix A = M − h ∂f/∂v − h² ∂f/∂x has a
/// fixed block pattern (diagonal blocks plus one block pair per spring), built once per model;
/// each step only refills the values in place.
class ImplicitEuler final : public Integrator {
 public:
  explicit ImplicitEuler(const IntegratorOptions& options) : options_(options) {
    CRUMPLE_CHECK(options.threads >= 0, "threads must be >= 0");
    threads_ = std::min(2, resolve_threads(options.threads));
  }
  ImplicitEuler(const ImplicitEuler&) = delete;
  ImplicitEuler& operator=(const ImplicitEuler&) = delete;
  IntegratorKind kind() const override { return IntegratorKind::ImplicitEuler; }
  bool takes_anchors() const override { return true; }

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
    const auto hinges = model.hinges();
    for (std::size_t k = 0; k < hinges.size(); ++k) {
      const Hinge& hg = hinges[k];
      Vec3 rate = Vec3::Zero();
      for (std::size_t i = 0; i < 4; ++i) rate += hg.weight[i] * s.v[static_cast<std::size_t>(hg.vertex[i])];
      for (std::size_t i = 0; i < 4; ++i) {
        b_.segment<3>(3 * hg.vertex[i]) -= h * hg.stiffness * hg.weight[i] * rate;
        for (std::size_t j = 0; j < 4; ++j) {
          const Scalar coefficient = (h * hg.damping + h2 * hg.stiffness) * hg.weight[i] * hg.weight[j];
          add(hinge_block_[k][4 * i + j], hg.vertex[j], coefficient * Mat3::Identity());
        }
      }
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
    // Anchors: A += c D d dᵀ, b += k d (offset − h d · v₀) before the factor h (k = c D / h²:
    // the force k d (offset − d · (x − x₀)) linearised at x₀ along x = x₀ + h (v₀ + Δv)). D is
    // read before any anchor adds to the block, so two anchors on one particle do not compound.
    anchor_diagonal_.assign(anchors_.size(), 0);
    for (std::size_t a = 0; a < anchors_.size(); ++a) {
      const Index i = anchors_[a].vertex;
      CRUMPLE_CHECK(i >= 0 && i < n, "anchor vertex out of range");
      Scalar trace = 0;
      for (int c = 0; c < 3; ++c) {
        trace += values[a_.outerIndexPtr()[3 * i + c] + block_offset_[diagonal_block_[static_cast<std::size_t>(i)]] + c];
      }
      anchor_diagonal_[a] = anchor_stiffness_ * trace / 3;
    }
    for (std::size_t a = 0; a < anchors_.size(); ++a) {
      const Anchor& anchor = anchors_[a];
      const auto k = static_cast<std::size_t>(anchor.vertex);
      if (inv_mass[k] == 0 || !(anchor_diagonal_[a] > 0)) continue;
      const Vec3 d = anchor.direction;
      // A particle already moving farther that way over the step keeps its motion.
      const Scalar offset = std::max(anchor.offset, h * d.dot(s.v[k]));
      add(diagonal_block_[k], anchor.vertex, anchor_diagonal_[a] * (d * d.transpose()));
      b_.segment<3>(3 * anchor.vertex) += (anchor_diagonal_[a] / h2) * (offset - h * d.dot(s.v[k])) * d;
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
    int products = -1;
    if (options_.cg_preconditioner == CgPreconditioner::Rest) {
      factor_rest(model, field, h);
      products = preconditioned_cg();
    }
    if (products < 0) {  // the Diagonal path, or the Rest path short of the tolerance
      cg_.setTolerance(options_.cg_tolerance);
      cg_.setMaxIterations(options_.cg_max_iterations);
      cg_.compute(a_);
      dv_ = cg_.solve(b_);
      products = static_cast<int>(cg_.iterations());
    }
    last_iterations_ = products;
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

  /// What the rest preconditioner depends on: the model (its revision names its masses,
  /// springs, damping and hinges), h and the air damping.
  struct RestKey {
    std::uint64_t revision = 0;
    Index particles = -1;
    Scalar h = 0, air = 0;
    bool operator==(const RestKey&) const = default;
  };

  /// Factors K (`CgPreconditioner::Rest`) over the free particles when its key changed. Every
  /// spring block of A, h c u uᵀ + h² k (u uᵀ + t (I − u uᵀ)) with t = max(0, 1 − L/l) < 1, is
  /// at most (h c + h² k) I, so A ≤ I₃ ⊗ K over the free rows (drag and anchors aside, which
  /// K leaves out: they change from step to step) and K⁻¹ A's spectrum lies in (0, 1] there;
  /// the along-spring stiffness, which makes A ill-conditioned, is matched exactly.
  void factor_rest(const Model& model, const ForceField& field, Scalar h) {
    RestKey key;
    key.revision = model.revision();
    key.particles = model.num_particles();
    key.h = h;
    key.air = field.air_damping;
    if (rest_factored_ && key == rest_key_) return;
    rest_key_ = key;
    const auto n = static_cast<std::size_t>(model.num_particles());
    rest_row_.assign(n, -1);
    rest_free_.clear();
    for (std::size_t i = 0; i < n; ++i) {
      if (model.pinned(static_cast<Index>(i))) continue;
      rest_row_[i] = static_cast<Eigen::Index>(rest_free_.size());
      rest_free_.push_back(i);
    }
    const auto mass = model.mass();
    const auto springs = model.springs();
    const auto damping = model.damping();
    std::vector<Eigen::Triplet<Scalar>> t;
    for (std::size_t r = 0; r < rest_free_.size(); ++r) {
      const auto rr = static_cast<Eigen::Index>(r);
      t.emplace_back(rr, rr, mass[rest_free_[r]] * (1 + h * field.air_damping));
    }
    for (std::size_t k = 0; k < springs.size(); ++k) {
      add_spring_triplets(springs[k], h * damping[k] + h * h * springs[k].stiffness, rest_row_, t);
    }
    for (const Hinge& hg : model.hinges()) add_hinge_triplets(hg, h * hg.damping + h * h * hg.stiffness, rest_row_, t);
    const auto m = static_cast<Eigen::Index>(rest_free_.size());
    Sparse k(m, m);
    k.setFromTriplets(t.begin(), t.end());
    rest_factored_ = false;
    if (m > 0) {
      rest_solver_.compute(k);
      CRUMPLE_CHECK(rest_solver_.info() == Eigen::Success,
                    "implicit Euler: the rest preconditioner is not positive definite");
      rest_supernodal_.plan(rest_solver_.matrixL().nestedExpression(), rest_solver_.vectorD());
    }
    ++factorizations_;
    rest_factored_ = true;
  }

  /// z = P⁻¹ r, P⁻¹ = I₃ ⊗ K⁻¹ + B⁻¹ on the free rows, B A's 3 × 3 diagonal blocks (the
  /// step's), z = r on the pinned rows (where r stays 0). Both terms are symmetric positive
  /// definite (K's factor with its entries rounded to single precision is still a fixed SPD
  /// operator), so their sum is, all CG needs. K⁻¹ takes the smooth, stiff modes along the
  /// springs; B⁻¹ the local ones across them, where A's stiffness is the springs' tension only
  /// (t ≪ 1) and K alone would overestimate it by up to 1/t.
  void precondition(const Vector& r, Vector& z) {
    z = r;
    if (rest_free_.empty()) return;
    const auto& p = rest_solver_.permutationP().indices();
    rest_tmp_.resize(rest_free_.size());
    for (std::size_t q = 0; q < rest_free_.size(); ++q) {
      rest_tmp_[static_cast<std::size_t>(p[static_cast<Eigen::Index>(q)])] =
          r.segment<3>(3 * static_cast<Eigen::Index>(rest_free_[q]));
    }
    rest_supernodal_.solve(rest_tmp_, threads_);
    for (std::size_t q = 0; q < rest_free_.size(); ++q) {
      const auto at = 3 * static_cast<Eigen::Index>(rest_free_[q]);
      z.segment<3>(at) = rest_tmp_[static_cast<std::size_t>(p[static_cast<Eigen::Index>(q)])] +
                         block_inverse_[rest_free_[q]] * r.segment<3>(at);
    }
  }

  /// y = A x, particle by particle: A is symmetric, so particle j's three rows are its three
  /// columns, which hold the same neighbour blocks (B_ij, i increasing) at the same offsets;
  /// y_j = Σ_i B_ijᵀ x_i in that order (the same bits on any thread count).
  void multiply(const Vector& x, Vector& y) const {
    const auto* outer = a_.outerIndexPtr();
    const Scalar* values = a_.valuePtr();
    const auto particles = static_cast<std::size_t>(a_.cols() / 3);
    y.resize(a_.cols());
    const Scalar* xp = x.data();
    Scalar* yp = y.data();
    parallel_for_chunks(particles, threads_, balanced_grain(particles, threads_, 512, 1 << 15),
                        [&](std::size_t begin, std::size_t end) {
                          for (std::size_t j = begin; j < end; ++j) {
                            const auto start = outer[3 * j];
                            const auto count = outer[3 * j + 1] - start;  // 3 × neighbours
                            const Scalar* c0 = values + start;
                            const Scalar* c1 = values + outer[3 * j + 1];
                            const Scalar* c2 = values + outer[3 * j + 2];
                            const int* rows = block_row_.data() + start / 9;
                            Scalar s0 = 0, s1 = 0, s2 = 0;
                            for (std::ptrdiff_t q = 0; q < count; q += 3) {
                              const Scalar* xi = xp + rows[q / 3];
                              const Scalar a = xi[0], b = xi[1], c = xi[2];
                              s0 += (c0[q] * a + c0[q + 1] * b) + c0[q + 2] * c;
                              s1 += (c1[q] * a + c1[q + 1] * b) + c1[q + 2] * c;
                              s2 += (c2[q] * a + c2[q + 1] * b) + c2[q + 2] * c;
                            }
                            yp[3 * j] = s0;
                            yp[3 * j + 1] = s1;
                            yp[3 * j + 2] = s2;
                          }
                        });
  }

  /// Preconditioned conjugate gradient on A Δv = b from Δv = 0, preconditioned by
  /// `precondition`; stops as Eigen's `ConjugateGradient` does (the `Diagonal` path): once the
  /// recurrence's residual |r|² < cg_tolerance² |b|². Returns the products with A, or −1 when it
  /// did not get there within cg_max_iterations products (or broke down: a curvature pᵀAp or
  /// rᵀz not positive and finite, which exact arithmetic rules out).
  int preconditioned_cg() {
    const Eigen::Index size = b_.size();
    dv_.setZero(size);
    const Scalar rhs2 = b_.squaredNorm();
    if (rhs2 == 0) return 0;
    const Scalar threshold =
        std::max(options_.cg_tolerance * options_.cg_tolerance * rhs2, std::numeric_limits<Scalar>::min());
    block_inverse_.resize(static_cast<std::size_t>(size / 3));
    const Scalar* values = a_.valuePtr();
    for (std::size_t i = 0; i < block_inverse_.size(); ++i) {
      Mat3 d;
      for (std::size_t c = 0; c < 3; ++c) {
        const Scalar* column = values + a_.outerIndexPtr()[3 * i + c] + block_offset_[diagonal_block_[i]];
        for (std::size_t r = 0; r < 3; ++r) d(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) = column[r];
      }
      block_inverse_[i] = d.inverse();
    }
    residual_ = b_;
    precondition(residual_, direction_);
    Scalar rz = residual_.dot(direction_);
    int products = 0;
    while (products < options_.cg_max_iterations) {
      if (!(rz > 0) || !std::isfinite(rz)) return -1;
      multiply(direction_, product_);
      ++products;
      const Scalar curvature = direction_.dot(product_);
      if (!(curvature > 0) || !std::isfinite(curvature)) return -1;
      const Scalar alpha = rz / curvature;
      dv_ += alpha * direction_;
      residual_ -= alpha * product_;
      if (residual_.squaredNorm() < threshold) return products;
      precondition(residual_, z_);
      const Scalar previous = rz;
      rz = residual_.dot(z_);
      direction_ = z_ + (rz / previous) * direction_;
    }
    return -1;
  }

  /// Zeroes entry (row, col)'s symmetric partner (col, row).
  void pinned_row_zero(Eigen::Index row, Eigen::Index col) { a_.coeffRef(col, row) = 0; }

  /// Builds the block pattern when the model's springs differ from the cached ones.
  void prepare(const Model& model) {
    const auto springs = model.springs();
    const auto hinges = model.hinges();
    const Index n = model.num_particles();
    bool same = pattern_n_ == n && pattern_pairs_.size() == springs.size() && pattern_hinges_.size() == hinges.size();
    for (std::size_t k = 0; same && k < springs.size(); ++k) {
      same = pattern_pairs_[k] == std::array<Index, 2>{springs[k].a, springs[k].b};
    }
    for (std::size_t k = 0; same && k < hinges.size(); ++k) same = pattern_hinges_[k] == hinges[k].vertex;
    if (same) return;
    pattern_n_ = n;
    pattern_pairs_.clear();
    pattern_hinges_.clear();
    std::vector<std::vector<Index>> neighbours(static_cast<std::size_t>(n));
    for (Index i = 0; i < n; ++i) neighbours[static_cast<std::size_t>(i)].push_back(i);
    for (const Spring& sp : springs) {
      pattern_pairs_.push_back({sp.a, sp.b});
      neighbours[static_cast<std::size_t>(sp.a)].push_back(sp.b);
      neighbours[static_cast<std::size_t>(sp.b)].push_back(sp.a);
    }
    for (const Hinge& hg : hinges) {
      pattern_hinges_.push_back(hg.vertex);
      for (Index a : hg.vertex) {
        for (Index b : hg.vertex) neighbours[static_cast<std::size_t>(a)].push_back(b);
      }
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
    // Each particle's blocks' first rows, compact: particle j's start at outer(3j) / 9 (the
    // particles before it store 9 entries per block).
    block_row_.clear();
    for (Index j = 0; j < n; ++j) {
      for (Index i : neighbours[static_cast<std::size_t>(j)]) block_row_.push_back(static_cast<int>(3 * i));
    }
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
    hinge_block_.resize(hinges.size());
    for (std::size_t k = 0; k < hinges.size(); ++k) {
      for (std::size_t i = 0; i < 4; ++i) {
        for (std::size_t j = 0; j < 4; ++j) {
          hinge_block_[k][4 * i + j] = block_offset_.size();
          block_offset_.push_back(offset(hinges[k].vertex[i], hinges[k].vertex[j]));
        }
      }
    }
  }

  IntegratorOptions options_;
  std::vector<Vec3> f_;
  Index pattern_n_ = -1;
  std::vector<std::array<Index, 2>> pattern_pairs_;
  Sparse a_;
  std::vector<int> block_row_;  // per particle j, its neighbour blocks' first rows 3i, i increasing
  std::vector<std::size_t> block_offset_;  // row offset of each referenced block in its columns
  std::vector<std::size_t> diagonal_block_;
  std::vector<std::array<std::size_t, 4>> spring_block_;
  std::vector<std::array<Index, 4>> pattern_hinges_;
  std::vector<std::array<std::size_t, 16>> hinge_block_;  // block (vertex i, vertex j) at 4i + j
  Vector b_, dv_;
  std::vector<Scalar> anchor_diagonal_;  // c D per anchor (the step's)
  Eigen::ConjugateGradient<Sparse, Eigen::Lower | Eigen::Upper> cg_;  // the Diagonal path
  int threads_ = 1;
  // The Rest path: K's factor, the free particles' rows, the CG vectors.
  RestKey rest_key_;
  bool rest_factored_ = false;
  std::vector<Eigen::Index> rest_row_;  // K's row of each particle, -1 when pinned
  std::vector<std::size_t> rest_free_;  // the particle of each row of K
  Eigen::SimplicialLDLT<Sparse, Eigen::Lower, NestedDissection> rest_solver_;
  detail::SupernodalSolve rest_supernodal_;
  std::vector<Vec3> rest_tmp_;
  Vector residual_, direction_, product_, z_;
  std::vector<Mat3> block_inverse_;  // per particle: A's diagonal block, inverted (the step's)
};

/// pull[k] = k_s (L_s / l) d for the springs [begin, end): d = x_a − x_b, l = √((d_x² + d_y²) + d_z²)
/// (zero where l = 0), the spring's rest-length projection times its stiffness.
void spring_pulls_scalar(std::span<const Spring> springs, const std::vector<Vec3>& x, std::vector<Vec3>& pull,
                         std::size_t begin, std::size_t end) {
  for (std::size_t k = begin; k < end; ++k) {
    const Spring& sp = springs[k];
    const Vec3 d = x[static_cast<std::size_t>(sp.a)] - x[static_cast<std::size_t>(sp.b)];
    const Scalar l = std::sqrt((d.x() * d.x() + d.y() * d.y()) + d.z() * d.z());
    if (l > 0) {
      const Scalar s = sp.rest_length / l;
      pull[k] = Vec3(sp.stiffness * (s * d.x()), sp.stiffness * (s * d.y()), sp.stiffness * (s * d.z()));
    } else {
      pull[k] = Vec3::Zero();
    }
  }
}

#if defined(__x86_64__) && defined(__GNUC__) && !defined(CRUMPLE_SANITIZED)
/// `spring_pulls_scalar`, four springs at a time in AVX: the same operations in the same order,
/// each correctly rounded, so the same bits (a zero length's quotient, infinite or NaN, is
/// masked to zero).
__attribute__((target("avx2"))) void spring_pulls_avx2(std::span<const Spring> springs, const std::vector<Vec3>& x,
                                                       std::vector<Vec3>& pull, std::size_t begin, std::size_t end) {
  std::size_t k = begin;
  for (; k + 4 <= end; k += 4) {
    alignas(32) std::array<Scalar, 4> dx, dy, dz, stiffness, rest;
    for (std::size_t j = 0; j < 4; ++j) {
      const Spring& sp = springs[k + j];
      const Vec3 d = x[static_cast<std::size_t>(sp.a)] - x[static_cast<std::size_t>(sp.b)];
      dx[j] = d.x();
      dy[j] = d.y();
      dz[j] = d.z();
      stiffness[j] = sp.stiffness;
      rest[j] = sp.rest_length;
    }
    const __m256d vx = _mm256_load_pd(dx.data()), vy = _mm256_load_pd(dy.data()), vz = _mm256_load_pd(dz.data());
    const __m256d l = _mm256_sqrt_pd(
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(vx, vx), _mm256_mul_pd(vy, vy)), _mm256_mul_pd(vz, vz)));
    const __m256d s = _mm256_div_pd(_mm256_load_pd(rest.data()), l);
    const __m256d kk = _mm256_load_pd(stiffness.data());
    const __m256d live = _mm256_cmp_pd(l, _mm256_setzero_pd(), _CMP_GT_OQ);
    _mm256_store_pd(dx.data(), _mm256_and_pd(live, _mm256_mul_pd(kk, _mm256_mul_pd(s, vx))));
    _mm256_store_pd(dy.data(), _mm256_and_pd(live, _mm256_mul_pd(kk, _mm256_mul_pd(s, vy))));
    _mm256_store_pd(dz.data(), _mm256_and_pd(live, _mm256_mul_pd(kk, _mm256_mul_pd(s, vz))));
    for (std::size_t j = 0; j < 4; ++j) pull[k + j] = Vec3(dx[j], dy[j], dz[j]);
  }
  spring_pulls_scalar(springs, x, pull, k, end);
}
#endif

/// `spring_pulls_scalar` (in AVX where the CPU has it: the same bits).
void spring_pulls(std::span<const Spring> springs, const std::vector<Vec3>& x, std::vector<Vec3>& pull,
                  std::size_t begin, std::size_t end) {
#if defined(__x86_64__) && defined(__GNUC__) && !defined(CRUMPLE_SANITIZED)
  if (geometry::has_avx2()) {
    spring_pulls_avx2(springs, x, pull, begin, end);
    return;
  }
#endif
  spring_pulls_scalar(springs, x, pull, begin, end);
}

/// Projective dynamics (see the header). The system is over the free particles only: a pinned
/// particle's known new position moves to the right-hand side.
class Projective final : public Integrator {
 public:
  explicit Projective(const IntegratorOptions& options) : options_(options) {
    CRUMPLE_CHECK(options.projective_iterations >= 1, "projective iterations must be >= 1");
    CRUMPLE_CHECK(options.projective_tolerance >= 0 && std::isfinite(options.projective_tolerance),
                  "projective tolerance must be finite and >= 0");
    CRUMPLE_CHECK(options.projective_tolerance == 0 ||
                      options.projective_max_iterations >= options.projective_iterations,
                  "projective max iterations must be >= projective iterations");
    CRUMPLE_CHECK(options.threads >= 0, "threads must be >= 0");
    threads_ = std::min(2, resolve_threads(options.threads));
    response_ = [this](std::span<const Vec3> force, std::span<Vec3> displacement) {
      const auto& p = solver_.permutationP().indices();
      solve_.resize(free_.size());
      for (std::size_t r = 0; r < free_.size(); ++r) solve_[static_cast<std::size_t>(p[static_cast<Eigen::Index>(r)])] = force[free_[r]];
      supernodal_.solve(solve_, threads_);
      std::fill(displacement.begin(), displacement.end(), Vec3::Zero());
      for (std::size_t r = 0; r < free_.size(); ++r) displacement[free_[r]] = solve_[static_cast<std::size_t>(p[static_cast<Eigen::Index>(r)])];
    };
  }
  IntegratorKind kind() const override { return IntegratorKind::Projective; }
  bool takes_contact_forces() const override { return true; }
  Projective(const Projective&) = delete;
  Projective& operator=(const Projective&) = delete;

  void step(const Model& model, const ForceField& field, State& s, Scalar h) override {
    check_step(model, s, h);
    prepare(model, field, h);
    const std::size_t n = s.x.size();
    const auto mass = model.mass();
    const auto springs = model.springs();
    const auto hinges = model.hinges();
    const Scalar inv_h2 = 1 / (h * h);
    // Every loop below writes each row (or particle, or hinge) from reads of others only, each
    // row's sums in a fixed order: the same bits on any thread count.
    const std::size_t m = free_.size();
    const std::size_t spring_grain = balanced_grain(springs.size(), threads_, 1024, 1 << 16);
    const std::size_t row_grain = balanced_grain(m, threads_, 512, 1 << 15);
    // Pinned particles move by h v₀; free ones start from the inertial prediction, and their
    // rows' constant part of the right-hand side (pinned ends of springs included) from it.
    next_.resize(n);
    for (const std::size_t i : pinned_) next_[i] = s.x[i] + h * s.v[i];
    base_.resize(m);
    parallel_for_chunks(m, threads_, row_grain, [&](std::size_t begin, std::size_t end) {
      for (std::size_t r = begin; r < end; ++r) {
        const std::size_t i = free_[r];
        next_[i] = s.x[i] + h * s.v[i];
        base_[r] = mass[i] * (inv_h2 * next_[i] + (field.air_damping / h) * s.x[i] + field.gravity);
      }
    });
    if (field.drag && row_[static_cast<std::size_t>(field.drag->vertex)] >= 0) {
      const auto i = static_cast<std::size_t>(field.drag->vertex);
      base_[static_cast<std::size_t>(row_[i])] += field.drag->stiffness * field.drag->target + (field.drag->damping / h) * s.x[i];
    }
    for (const Boundary& e : boundary_) base_[static_cast<std::size_t>(e.row)] += e.stiffness * next_[static_cast<std::size_t>(e.pinned)];
    // Each hinge's term g = (c/h) Σ w_c x_c − (s + c/h) Σ_pinned w_c y_c, then each row gathers
    // w_c g over its hinges in increasing order (the order of a scatter hinge by hinge).
    hinge_term_.resize(hinges.size());
    parallel_for_chunks(hinges.size(), threads_, balanced_grain(hinges.size(), threads_, 1024, 1 << 16),
                        [&](std::size_t begin, std::size_t end) {
                          for (std::size_t k = begin; k < end; ++k) {
                            const Hinge& hg = hinges[k];
                            const std::array<int, 4>& rows = hinge_rows_[k];
                            Vec3 rest = Vec3::Zero(), fixed = Vec3::Zero();
                            for (std::size_t c = 0; c < 4; ++c) {
                              const auto v = static_cast<std::size_t>(hg.vertex[c]);
                              rest += hg.weight[c] * s.x[v];
                              if (rows[c] < 0) fixed += hg.weight[c] * next_[v];
                            }
                            hinge_term_[k] = hinge_rate_[k] * rest - hinge_hold_[k] * fixed;
                          }
                        });
    const auto& p = solver_.permutationP().indices();
    pull_.resize(springs.size());
    tmp_.resize(m);
    older_.resize(n);
    // The global steps solve for x̂ − y, y the inertial prediction: the right-hand side's
    // constant part becomes base − A y (in double), so the factor's single-precision rounding
    // scales with the step's displacement from y, not with the coordinates.
    origin_.resize(m);
    parallel_for_chunks(m, threads_, row_grain, [&](std::size_t begin, std::size_t end) {
      for (std::size_t r = begin; r < end; ++r) {
        Vec3 b = base_[r];
        for (int e = hinge_incident_start_[r]; e < hinge_incident_start_[r + 1]; ++e) {
          const auto at = static_cast<std::size_t>(e);
          b += hinge_weight_[at] * hinge_term_[static_cast<std::size_t>(hinge_incident_[at])];
        }
        origin_[r] = next_[free_[r]];
        base_[r] = a_rows_.reduce(r, b, next_);
      }
    });
    Scalar omega = 1;
    const Scalar tolerance = options_.projective_tolerance;
    const int most = tolerance > 0 ? options_.projective_max_iterations : options_.projective_iterations;
    int it = 0;
    for (; it < most; ++it) {
      // Local step: each spring's pull k d_s at the current positions (d_s its rest-length
      // projection); then each free row's right-hand side (less A y), gathered over its springs
      // in a fixed order and placed at its permuted row for the solve.
      parallel_for_chunks(springs.size(), threads_, spring_grain, [&](std::size_t begin, std::size_t end) {
        spring_pulls(springs, next_, pull_, begin, end);
      });
      // The contacts' part of the local step: forces on the right-hand side, matrix unchanged.
      if (contact_forces_) {
        contact_force_.assign(n, Vec3::Zero());
        contact_forces_(next_, diagonal_, response_, contact_force_);
      }
      parallel_for_chunks(m, threads_, row_grain, [&](std::size_t begin, std::size_t end) {
        for (std::size_t r = begin; r < end; ++r) {
          Vec3 b = base_[r];
          if (contact_forces_) b += contact_force_[free_[r]];
          for (int e = incident_start_[r]; e < incident_start_[r + 1]; ++e) {
            const int k = incident_[static_cast<std::size_t>(e)];
            if (k >= 0) {
              b += pull_[static_cast<std::size_t>(k)];
            } else {
              b -= pull_[static_cast<std::size_t>(~k)];
            }
          }
          tmp_[static_cast<std::size_t>(p[static_cast<Eigen::Index>(r)])] = b;
        }
      });
      // tmp_ = P A⁻¹ b (A = Pᵀ L D Lᵀ P), L's entries rounded to single precision, so to a
      // relative 1e-7 or so: the global step solves for corrections.
      supernodal_.solve(tmp_, threads_);
      // Chebyshev semi-iterative acceleration (Wang, *A Chebyshev semi-iterative approach for
      // accelerating projective and position-based dynamics*, SIGGRAPH Asia 2015):
      // x⁽ᵏ⁺¹⁾ = ω (x̂ − x⁽ᵏ⁻¹⁾) + x⁽ᵏ⁻¹⁾ with ω from the spectral radius estimate ρ.
      const Scalar rho = options_.projective_rho;
      omega = it == 0 ? 1 : it == 1 ? 2 / (2 - rho * rho) : 4 / (4 - rho * rho * omega);
      parallel_for_chunks(m, threads_, row_grain, [&](std::size_t begin, std::size_t end) {
        for (std::size_t r = begin; r < end; ++r) {
          const std::size_t i = free_[r];
          const Vec3 solved = origin_[r] + tmp_[static_cast<std::size_t>(p[static_cast<Eigen::Index>(r)])];
          const Vec3 previous = it == 0 ? next_[i] : older_[i];
          older_[i] = next_[i];
          next_[i] = omega * (solved - previous) + previous;
        }
      });
      // Settled: no free particle moved more than the tolerance in this iteration (older_
      // holds the previous iterate; a serial scan, so the same bits on any thread count).
      if (tolerance > 0 && it + 1 >= options_.projective_iterations) {
        Scalar moved = 0;
        for (const std::size_t i : free_) moved = std::max(moved, (next_[i] - older_[i]).squaredNorm());
        if (moved <= tolerance * tolerance) {
          ++it;
          break;
        }
      }
    }
    last_iterations_ = it;
    parallel_for_chunks(m, threads_, row_grain, [&](std::size_t begin, std::size_t end) {
      for (std::size_t r = begin; r < end; ++r) {
        const std::size_t i = free_[r];
        s.v[i] = (next_[i] - s.x[i]) / h;
        s.x[i] = next_[i];
      }
    });
    for (const std::size_t i : pinned_) s.x[i] = next_[i];
    s.time += h;
  }

 private:
  using Sparse = Eigen::SparseMatrix<Scalar>;

  /// What the factored matrix depends on: the model (its revision names its masses, springs
  /// and hinges), h, the air damping and the drag's spring.
  struct Key {
    std::uint64_t revision = 0;
    Index particles = -1;
    Scalar h = 0, air = 0;
    Index drag_vertex = -1;
    Scalar drag_stiffness = 0, drag_damping = 0;
    bool operator==(const Key&) const = default;
  };

  void prepare(const Model& model, const ForceField& field, Scalar h) {
    CRUMPLE_CHECK(!field.drag || (field.drag->vertex >= 0 && field.drag->vertex < model.num_particles()),
                  "drag vertex out of range");
    Key key;
    key.revision = model.revision();
    key.particles = model.num_particles();
    key.h = h;
    key.air = field.air_damping;
    if (field.drag && !model.pinned(field.drag->vertex)) {
      key.drag_vertex = field.drag->vertex;
      key.drag_stiffness = field.drag->stiffness;
      key.drag_damping = field.drag->damping;
    }
    if (factored_ && key == key_) return;
    key_ = key;
    const std::size_t n = static_cast<std::size_t>(model.num_particles());
    row_.assign(n, -1);
    free_.clear();
    pinned_.clear();
    for (std::size_t i = 0; i < n; ++i) {
      if (!model.pinned(static_cast<Index>(i))) {
        row_[i] = static_cast<Eigen::Index>(free_.size());
        free_.push_back(i);
      } else {
        pinned_.push_back(i);
      }
    }
    const auto springs = model.springs();
    // The springs with one pinned end, in order, and each hinge's free rows: what every step
    // adds to the right-hand side's constant part, without looking rows up again.
    boundary_.clear();
    for (const Spring& sp : springs) {
      const Eigen::Index ra = row_[static_cast<std::size_t>(sp.a)], rb = row_[static_cast<std::size_t>(sp.b)];
      if (ra >= 0 && rb < 0) boundary_.push_back({static_cast<int>(ra), sp.b, sp.stiffness});
      if (rb >= 0 && ra < 0) boundary_.push_back({static_cast<int>(rb), sp.a, sp.stiffness});
    }
    const auto hinges = model.hinges();
    hinge_rows_.resize(hinges.size());
    hinge_rate_.resize(hinges.size());
    hinge_hold_.resize(hinges.size());
    hinge_incident_start_.assign(free_.size() + 1, 0);
    for (std::size_t k = 0; k < hinges.size(); ++k) {
      for (std::size_t c = 0; c < 4; ++c) {
        const auto r = static_cast<int>(row_[static_cast<std::size_t>(hinges[k].vertex[c])]);
        hinge_rows_[k][c] = r;
        if (r >= 0) ++hinge_incident_start_[static_cast<std::size_t>(r) + 1];
      }
      hinge_rate_[k] = hinges[k].damping / h;
      hinge_hold_[k] = hinges[k].stiffness + hinges[k].damping / h;
    }
    for (std::size_t r = 0; r < free_.size(); ++r) hinge_incident_start_[r + 1] += hinge_incident_start_[r];
    hinge_incident_.resize(static_cast<std::size_t>(hinge_incident_start_.back()));
    hinge_weight_.resize(hinge_incident_.size());
    {
      std::vector<int> at(hinge_incident_start_.begin(), hinge_incident_start_.end() - 1);
      for (std::size_t k = 0; k < hinges.size(); ++k) {
        for (std::size_t c = 0; c < 4; ++c) {
          if (const int r = hinge_rows_[k][c]; r >= 0) {
            const auto e = static_cast<std::size_t>(at[static_cast<std::size_t>(r)]++);
            hinge_incident_[e] = static_cast<int>(k);
            hinge_weight_[e] = hinges[k].weight[c];
          }
        }
      }
    }
    incident_start_.assign(free_.size() + 1, 0);
    for (const Spring& sp : springs) {
      for (const Index end : {sp.a, sp.b}) {
        if (const Eigen::Index r = row_[static_cast<std::size_t>(end)]; r >= 0) ++incident_start_[static_cast<std::size_t>(r) + 1];
      }
    }
    for (std::size_t r = 0; r < free_.size(); ++r) incident_start_[r + 1] += incident_start_[r];
    incident_.resize(static_cast<std::size_t>(incident_start_.back()));
    {
      std::vector<int> at(incident_start_.begin(), incident_start_.end() - 1);
      for (std::size_t k = 0; k < springs.size(); ++k) {
        const Eigen::Index ra = row_[static_cast<std::size_t>(springs[k].a)], rb = row_[static_cast<std::size_t>(springs[k].b)];
        if (ra >= 0) incident_[static_cast<std::size_t>(at[static_cast<std::size_t>(ra)]++)] = static_cast<int>(k);
        if (rb >= 0) incident_[static_cast<std::size_t>(at[static_cast<std::size_t>(rb)]++)] = ~static_cast<int>(k);
      }
    }
    std::vector<Eigen::Triplet<Scalar>> t;
    const auto mass = model.mass();
    for (std::size_t r = 0; r < free_.size(); ++r) {
      const auto rr = static_cast<Eigen::Index>(r);
      Scalar diagonal = mass[free_[r]] * (1 / (h * h) + field.air_damping / h);
      if (static_cast<Index>(free_[r]) == key_.drag_vertex) diagonal += key_.drag_stiffness + key_.drag_damping / h;
      t.emplace_back(rr, rr, diagonal);
    }
    for (const Spring& sp : model.springs()) add_spring_triplets(sp, sp.stiffness, row_, t);
    for (const Hinge& hg : model.hinges()) add_hinge_triplets(hg, hg.stiffness + hg.damping / h, row_, t);
    const auto m = static_cast<Eigen::Index>(free_.size());
    Sparse a(m, m);
    a.setFromTriplets(t.begin(), t.end());
    diagonal_.assign(n, 0);
    {
      const Eigen::VectorXd d = a.diagonal();
      for (std::size_t r = 0; r < free_.size(); ++r) diagonal_[free_[r]] = d[static_cast<Eigen::Index>(r)];
    }
    {
      const Eigen::SparseMatrix<Scalar, Eigen::RowMajor> rows = a;
      a_rows_.clear();
      for (Eigen::Index r = 0; r < m; ++r) {
        for (Eigen::SparseMatrix<Scalar, Eigen::RowMajor>::InnerIterator e(rows, r); e; ++e) {
          a_rows_.add(static_cast<int>(free_[static_cast<std::size_t>(e.index())]), e.value());
        }
        a_rows_.close();
      }
    }
    factored_ = false;
    solver_.compute(a);
    CRUMPLE_CHECK(solver_.info() == Eigen::Success, "projective dynamics: the system matrix is not positive definite");
    ++factorizations_;
    factored_ = true;
    supernodal_.plan(solver_.matrixL().nestedExpression(), solver_.vectorD());
  }

  /// Rows of A, each stored in the order its sum visits its entries.
  struct Rows {
    std::vector<int> start{0}, index;
    std::vector<Scalar> value;
    void clear() {
      start.assign(1, 0);
      index.clear();
      value.clear();
    }
    void add(int i, Scalar v) {
      index.push_back(i);
      value.push_back(v);
    }
    void close() { start.push_back(static_cast<int>(index.size())); }
    /// y − Σ value · x[index] over line `t`: four partial sums over the entries k ≡ 0, 1, 2, 3
    /// (mod 4) from the line's start, each in stored order, then y − ((s₀ + s₁) + (s₂ + s₃)).
    /// A fixed order (the same bits on every call and thread count); four chains instead of one
    /// let the additions overlap.
    Vec3 reduce(std::size_t t, const Vec3& y, const std::vector<Vec3>& x) const {
      const int* i = index.data();
      const Scalar* v = value.data();
      static_assert(sizeof(Vec3) == 3 * sizeof(Scalar), "Vec3 is three packed Scalars");
      const Scalar* p = x.data()->data();
      int k = start[t];
      const int end = start[t + 1];
      // Partial sum r of coordinate c in s[3 r + c]: plain scalars, kept in registers.
      Scalar s[12] = {};
      const auto add = [&](int r, int e) {
        const Scalar w = v[e];
        const Scalar* q = p + 3 * static_cast<std::ptrdiff_t>(i[e]);
        s[3 * r] += w * q[0];
        s[3 * r + 1] += w * q[1];
        s[3 * r + 2] += w * q[2];
      };
      for (; k + 4 <= end; k += 4) {
        add(0, k);
        add(1, k + 1);
        add(2, k + 2);
        add(3, k + 3);
      }
      if (k < end) add(0, k);
      if (k + 1 < end) add(1, k + 1);
      if (k + 2 < end) add(2, k + 2);
      return y - Vec3((s[0] + s[3]) + (s[6] + s[9]), (s[1] + s[4]) + (s[7] + s[10]), (s[2] + s[5]) + (s[8] + s[11]));
    }
  };

  IntegratorOptions options_;
  int threads_ = 1;
  Key key_;
  bool factored_ = false;
  std::vector<Eigen::Index> row_;  // free row of each particle, -1 when pinned
  std::vector<std::size_t> free_;  // particle of each free row
  std::vector<std::size_t> pinned_;  // the pinned particles
  Eigen::SimplicialLDLT<Sparse, Eigen::Lower, NestedDissection> solver_;
  detail::SupernodalSolve supernodal_;  // the factor's triangular solves
  /// A spring with one pinned end: its free end's row, the pinned particle, its stiffness.
  struct Boundary {
    int row;
    Index pinned;
    Scalar stiffness;
  };
  std::vector<Boundary> boundary_;                 // in the springs' order
  std::vector<std::array<int, 4>> hinge_rows_;     // per hinge: its vertices' free rows, -1 pinned
  std::vector<Scalar> hinge_rate_, hinge_hold_;    // per hinge: c / h and s + c / h
  std::vector<int> hinge_incident_start_, hinge_incident_;  // per free row: its hinges k, increasing
  std::vector<Scalar> hinge_weight_;               // per entry of hinge_incident_: the row's weight w_c
  std::vector<Vec3> hinge_term_;                   // per hinge: the step's g
  std::vector<int> incident_start_, incident_;  // per free row: its springs, ~k where it is end b
  Rows a_rows_;                // A by free rows, each entry at its column's particle
  std::vector<Vec3> origin_;    // per free row: the inertial prediction y the solves start from
  std::vector<Vec3> next_, older_, tmp_, base_, pull_;
  std::vector<Scalar> diagonal_;    // per particle: A's diagonal entry, 0 for a pinned one
  std::vector<Vec3> contact_force_;  // per particle: the contact forces of the iteration
  std::vector<Vec3> solve_;          // per permuted free row: the contact response's solve
  ContactSolve response_;            // A⁻¹ over the free particles, for the contact forces
};

}  // namespace

std::string_view to_string(IntegratorKind kind) {
  switch (kind) {
    case IntegratorKind::ExplicitEuler: return "explicit-euler";
    case IntegratorKind::SymplecticEuler: return "symplectic-euler";
    case IntegratorKind::Rk4: return "rk4";
    case IntegratorKind::ImplicitEuler: return "implicit-euler";
    case IntegratorKind::Projective: return "projective";
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
    case IntegratorKind::Projective: return std::make_unique<Projective>(options);
  }
  throw InputError("unknown integrator");
}

namespace {

/// Bounds on the linearized equations M x'' + C x' + K x = 0 of a model at shape x without
/// tension (every spring as if at its rest length), over the free particles. An eigenvalue λ
/// with eigenvector u (u*Mu = 1) is a root of λ² + c λ + k = 0 with c = u*Cu and k = u*Ku, and
/// these Rayleigh quotients satisfy
///   0 ≤ k ≤ k_max,  c ≤ air + c_max,  air + τ_min k ≤ c ≤ air + τ_max k,
/// k_max and c_max the largest eigenvalues of M^-1/2 K M^-1/2 and of the elastic part of
/// M^-1/2 C M^-1/2, τ = c_e / k_e the ratio of each element's damping to its stiffness (every
/// element's C_e is τ_e K_e without tension: a spring's dashpot acts along it, a hinge's on its
/// bend).
struct RestSpectrum {
  Scalar k_max = 0, c_max = 0, air = 0;
  Scalar tau_min = std::numeric_limits<Scalar>::infinity();
  Scalar tau_max = 0;
};

/// The largest eigenvalue of the PSD operator y = apply(u) (u, y over all particles, pinned
/// entries zero): the Rayleigh quotient after `kIterations` power iterations from a fixed start,
/// at most `bound` (Gershgorin's). The quotient approaches the eigenvalue from below, within
/// a few per cent on cloth lattices, where the top of the spectrum is a tight cluster.
template <class Apply>
Scalar largest_eigenvalue(const Model& model, Scalar bound, const Apply& apply) {
  constexpr int kIterations = 100;
  const auto n = static_cast<std::size_t>(model.num_particles());
  std::vector<Vec3> u(n, Vec3::Zero()), y(n);
  std::uint64_t h = 0x9e3779b97f4a7c15ULL;  // splitmix64: the same start on every platform
  const auto next = [&h] {
    std::uint64_t z = (h += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return static_cast<Scalar>((z ^ (z >> 31)) >> 11) * 0x1.0p-53 - 0.5;
  };
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 r(next(), next(), next());
    if (!model.pinned(static_cast<Index>(i))) u[i] = r;
  }
  Scalar quotient = 0;
  for (int it = 0; it < kIterations; ++it) {
    Scalar norm2 = 0;
    for (const Vec3& e : u) norm2 += e.squaredNorm();
    if (!(norm2 > 0)) return 0;
    const Scalar scale = 1 / std::sqrt(norm2);
    for (Vec3& e : u) e *= scale;
    std::fill(y.begin(), y.end(), Vec3::Zero());
    apply(u, y);
    quotient = 0;
    for (std::size_t i = 0; i < n; ++i) quotient += u[i].dot(y[i]);
    std::swap(u, y);
  }
  return std::min(quotient, bound);
}

RestSpectrum rest_spectrum(const Model& model, const ForceField& field, std::span<const Vec3> x) {
  RestSpectrum r;
  const auto mass = model.mass();
  const auto damping = model.damping();
  std::vector<Scalar> row_k(mass.size(), 0), row_c(mass.size(), 0);
  const auto ratio = [&](Scalar c, Scalar k) {
    if (!(k > 0)) {
      if (c > 0) r.tau_max = std::numeric_limits<Scalar>::infinity();  // a pure dashpot
      return;
    }
    r.tau_min = std::min(r.tau_min, c / k);
    r.tau_max = std::max(r.tau_max, c / k);
  };
  // Adds coefficient × (the pair's entry of a PSD element, |w_i w_j| scaled) to both rows.
  const auto springs = model.springs();
  for (std::size_t e = 0; e < springs.size(); ++e) {
    const Spring& s = springs[e];
    const auto a = static_cast<std::size_t>(s.a), b = static_cast<std::size_t>(s.b);
    const bool free_a = !model.pinned(s.a), free_b = !model.pinned(s.b);
    if (!free_a && !free_b) continue;
    const Scalar k = std::max<Scalar>(s.stiffness, 0), c = std::max<Scalar>(damping[e], 0);
    ratio(c, k);
    // The 3×3 block of a spring has norm k (c): Gershgorin over blocks.
    const Scalar coupling = free_a && free_b ? 1 / std::sqrt(mass[a] * mass[b]) : 0;
    if (free_a) {
      row_k[a] += k * (1 / mass[a] + coupling);
      row_c[a] += c * (1 / mass[a] + coupling);
    }
    if (free_b) {
      row_k[b] += k * (1 / mass[b] + coupling);
      row_c[b] += c * (1 / mass[b] + coupling);
    }
  }
  for (const Hinge& hg : model.hinges()) {
    bool any_free = false;
    for (std::size_t i = 0; i < 4; ++i) {
      const auto a = static_cast<std::size_t>(hg.vertex[i]);
      if (model.pinned(hg.vertex[i])) continue;
      any_free = true;
      for (std::size_t j = 0; j < 4; ++j) {
        const auto b = static_cast<std::size_t>(hg.vertex[j]);
        if (model.pinned(hg.vertex[j])) continue;
        const Scalar w = std::abs(hg.weight[i] * hg.weight[j]) / std::sqrt(mass[a] * mass[b]);
        row_k[a] += std::max<Scalar>(hg.stiffness, 0) * w;
        row_c[a] += std::max<Scalar>(hg.damping, 0) * w;
      }
    }
    if (any_free) ratio(std::max<Scalar>(hg.damping, 0), std::max<Scalar>(hg.stiffness, 0));
  }
  if (field.drag && field.drag->vertex >= 0 && field.drag->vertex < model.num_particles() &&
      !model.pinned(field.drag->vertex)) {
    const auto i = static_cast<std::size_t>(field.drag->vertex);
    const Scalar k = std::max<Scalar>(field.drag->stiffness, 0), c = std::max<Scalar>(field.drag->damping, 0);
    ratio(c, k);
    row_k[i] += k / mass[i];
    row_c[i] += c / mass[i];
  }
  for (std::size_t i = 0; i < mass.size(); ++i) {
    if (model.pinned(static_cast<Index>(i))) continue;
    r.k_max = std::max(r.k_max, row_k[i]);
    r.c_max = std::max(r.c_max, row_c[i]);
  }
  // M^-1/2 (Σ coefficient_e K_e) M^-1/2 u at shape x without tension: a spring's block is
  // d̂d̂ᵀ (its dashpot's too), a hinge's w wᵀ ⊗ I, the drag's I.
  const auto inv_sqrt = [&](std::size_t i) { return model.pinned(static_cast<Index>(i)) ? 0 : 1 / std::sqrt(mass[i]); };
  const auto operator_of = [&](bool damped) {
    return [&, damped](const std::vector<Vec3>& u, std::vector<Vec3>& y) {
      for (std::size_t e = 0; e < springs.size(); ++e) {
        const Spring& sp = springs[e];
        const auto a = static_cast<std::size_t>(sp.a), b = static_cast<std::size_t>(sp.b);
        const Vec3 d = x[a] - x[b];
        const Scalar l = d.norm();
        const Scalar coefficient = std::max<Scalar>(damped ? damping[e] : sp.stiffness, 0);
        if (!(l > 0) || coefficient == 0) continue;
        const Vec3 dir = d / l;
        const Scalar stretch = coefficient * dir.dot(inv_sqrt(a) * u[a] - inv_sqrt(b) * u[b]);
        y[a] += inv_sqrt(a) * stretch * dir;
        y[b] -= inv_sqrt(b) * stretch * dir;
      }
      for (const Hinge& hg : model.hinges()) {
        const Scalar coefficient = std::max<Scalar>(damped ? hg.damping : hg.stiffness, 0);
        Vec3 bend = Vec3::Zero();
        for (std::size_t i = 0; i < 4; ++i) {
          const auto v = static_cast<std::size_t>(hg.vertex[i]);
          bend += hg.weight[i] * inv_sqrt(v) * u[v];
        }
        for (std::size_t i = 0; i < 4; ++i) {
          const auto v = static_cast<std::size_t>(hg.vertex[i]);
          y[v] += coefficient * hg.weight[i] * inv_sqrt(v) * bend;
        }
      }
      if (field.drag && field.drag->vertex >= 0 && field.drag->vertex < model.num_particles()) {
        const auto i = static_cast<std::size_t>(field.drag->vertex);
        y[i] += std::max<Scalar>(damped ? field.drag->damping : field.drag->stiffness, 0) * inv_sqrt(i) * inv_sqrt(i) * u[i];
      }
    };
  };
  r.k_max = largest_eigenvalue(model, r.k_max, operator_of(false));
  r.c_max = largest_eigenvalue(model, r.c_max, operator_of(true));
  r.air = std::max<Scalar>(field.air_damping, 0);
  if (!(r.tau_min < std::numeric_limits<Scalar>::infinity())) r.tau_min = 0;  // no elastic element
  return r;
}

/// Whether one step of `kind` with step h keeps every solution of x'' + c x' + k x = 0 bounded.
/// Explicit Euler and RK4 amplify the mode e^{λt} by R(hλ) = 1 + w (w = z, and
/// z + z²/2 + z³/6 + z⁴/24, z = hλ): stable when |R|² − 1 = 2 Re w + |w|² ≤ 0, evaluated in this
/// form so that a neutral or nearly neutral mode is not lost to cancellation against 1.
/// Symplectic Euler (v += h a, then x += h v) has the 2×2 amplification matrix with trace
/// t = 2 − hc − h²k and determinant d = 1 − hc: stable when |d| ≤ 1 and |t| ≤ 1 + d (Jury),
/// i.e. hc ≤ 2 and h²k + 2hc ≤ 4 (c, k ≥ 0).
bool mode_is_stable(IntegratorKind kind, Scalar h, Scalar c, Scalar k) {
  using Complex = std::complex<Scalar>;
  if (kind == IntegratorKind::SymplecticEuler) return h * c <= 2 && h * h * k + 2 * h * c <= 4;
  // Roots of λ² + c λ + k, the small one without cancellation.
  const Complex root = std::sqrt(Complex(c * c - 4 * k, 0));
  const Complex big = -0.5 * (c + root);
  const std::array<Complex, 2> lambdas{big, std::abs(big) > 0 ? Complex(k) / big : Complex(0)};
  for (const Complex lambda : lambdas) {
    const Complex z = h * lambda;
    const Complex w = kind == IntegratorKind::ExplicitEuler ? z : z * (1.0 + z * (0.5 + z * (1.0 / 6 + z / 24.0)));
    // Rounding in the sum is a multiple of |w|²'s ulp: a neutral mode passes.
    if (2 * w.real() + std::norm(w) > 1e-10 * std::norm(w)) return false;
  }
  return true;
}

/// Whether h is stable for every (c, k) the bounds allow, checked on a grid: k at 0, 160 even
/// steps up to k_max and 24 halvings below them; c at 17 even steps over its range for each k.
bool stable_for(IntegratorKind kind, const RestSpectrum& r, Scalar h) {
  const auto check_k = [&](Scalar k) {
    const Scalar low = r.air + r.tau_min * k;
    const Scalar high = std::min(r.air + r.c_max, r.air + r.tau_max * k);
    if (low > high) return true;  // no mode has this k
    for (int i = 0; i <= 16; ++i) {
      if (!mode_is_stable(kind, h, low + (high - low) * i / 16, k)) return false;
    }
    return true;
  };
  for (int i = 0; i <= 160; ++i) {
    if (!check_k(r.k_max * i / 160)) return false;
  }
  Scalar k = r.k_max / 160;
  for (int i = 0; i < 24; ++i) {
    if (!check_k(k *= 0.5)) return false;
  }
  return true;
}

}  // namespace

Scalar stable_time_step(const Model& model, const ForceField& field, std::span<const Vec3> x,
                        IntegratorKind kind) {
  constexpr Scalar kInfinity = std::numeric_limits<Scalar>::infinity();
  if (kind == IntegratorKind::ImplicitEuler || kind == IntegratorKind::Projective) return kInfinity;
  CRUMPLE_CHECK(x.size() == static_cast<std::size_t>(model.num_particles()), "x must have #V positions");
  const RestSpectrum r = rest_spectrum(model, field, x);
  if (!(r.k_max > 0) && !(r.c_max > 0)) return kInfinity;  // no elastic force: only air damping
  // |λ| ≤ c + √k: below 1/(c_max + air + √k_max) every |hλ| ≤ 1. Bracket, then bisect.
  Scalar lo = 0, hi = 1 / (r.c_max + r.air + std::sqrt(r.k_max));
  while (stable_for(kind, r, hi)) {
    lo = hi;
    hi *= 2;
    if (!(hi < 1e30)) return kInfinity;
  }
  for (int i = 0; i < 60 && hi - lo > 1e-12 * hi; ++i) {
    const Scalar mid = 0.5 * (lo + hi);
    (stable_for(kind, r, mid) ? lo : hi) = mid;
  }
  return lo;
}

}  // namespace crumple::sim

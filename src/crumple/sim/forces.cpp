#include <crumple/core/error.hpp>
#include <crumple/sim/forces.hpp>

#include <algorithm>
#include <cmath>

namespace crumple::sim {

namespace {
inline std::size_t at(Index i) { return static_cast<std::size_t>(i); }
using Mat3 = Eigen::Matrix<Scalar, 3, 3>;
}  // namespace

void compute_forces(const Model& model, const ForceField& field, std::span<const Vec3> x,
                    std::span<const Vec3> v, std::vector<Vec3>& f) {
  const std::size_t n = static_cast<std::size_t>(model.num_particles());
  CRUMPLE_CHECK(x.size() == n && v.size() == n, "positions and velocities must have #V entries");
  f.assign(n, Vec3::Zero());
  const auto mass = model.mass();
  for (std::size_t i = 0; i < n; ++i) {
    f[i] = mass[i] * (field.gravity - field.air_damping * v[i]);
  }
  const auto springs = model.springs();
  const auto damping = model.damping();
  for (std::size_t s = 0; s < springs.size(); ++s) {
    const Spring& sp = springs[s];
    const Vec3 d = x[at(sp.a)] - x[at(sp.b)];
    const Scalar l = d.norm();
    if (!(l > 0)) continue;
    const Vec3 dir = d / l;
    const Scalar magnitude =
        sp.stiffness * (l - sp.rest_length) + damping[s] * (v[at(sp.a)] - v[at(sp.b)]).dot(dir);
    const Vec3 fa = -magnitude * dir;
    f[at(sp.a)] += fa;
    f[at(sp.b)] -= fa;
  }
  for (const Hinge& hg : model.hinges()) {
    Vec3 bend = Vec3::Zero(), rate = Vec3::Zero();
    for (std::size_t k = 0; k < 4; ++k) {
      bend += hg.weight[k] * x[at(hg.vertex[k])];
      rate += hg.weight[k] * v[at(hg.vertex[k])];
    }
    const Vec3 g = hg.stiffness * bend + hg.damping * rate;
    for (std::size_t k = 0; k < 4; ++k) f[at(hg.vertex[k])] -= hg.weight[k] * g;
  }
  if (field.drag) {
    const DragForce& g = *field.drag;
    CRUMPLE_CHECK(g.vertex >= 0 && at(g.vertex) < n, "drag vertex out of range");
    f[at(g.vertex)] += g.stiffness * (g.target - x[at(g.vertex)]) - g.damping * v[at(g.vertex)];
  }
}

ForceJacobians compute_force_jacobians(const Model& model, const ForceField& field,
                                       std::span<const Vec3> x) {
  const Index n = model.num_particles();
  std::vector<Eigen::Triplet<Scalar>> tx, tv;
  const auto springs = model.springs();
  const auto damping = model.damping();
  tx.reserve(springs.size() * 36 + 3);
  tv.reserve(springs.size() * 36 + 3 * static_cast<std::size_t>(n) + 3);
  const auto add_block = [](std::vector<Eigen::Triplet<Scalar>>& t, Index i, Index j, const Mat3& m) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) t.emplace_back(3 * i + r, 3 * j + c, m(r, c));
  };
  for (std::size_t s = 0; s < springs.size(); ++s) {
    const Spring& sp = springs[s];
    const SpringBlocks b = spring_blocks(sp, damping[s], x[at(sp.a)], x[at(sp.b)]);
    add_block(tx, sp.a, sp.a, b.dx);
    add_block(tx, sp.b, sp.b, b.dx);
    add_block(tx, sp.a, sp.b, -b.dx);
    add_block(tx, sp.b, sp.a, -b.dx);
    if (damping[s] > 0) {
      add_block(tv, sp.a, sp.a, b.dv);
      add_block(tv, sp.b, sp.b, b.dv);
      add_block(tv, sp.a, sp.b, -b.dv);
      add_block(tv, sp.b, sp.a, -b.dv);
    }
  }
  for (const Hinge& hg : model.hinges()) {
    for (std::size_t i = 0; i < 4; ++i) {
      for (std::size_t j = 0; j < 4; ++j) {
        const Scalar ww = hg.weight[i] * hg.weight[j];
        for (int r = 0; r < 3; ++r) {
          tx.emplace_back(3 * hg.vertex[i] + r, 3 * hg.vertex[j] + r, -hg.stiffness * ww);
          if (hg.damping > 0) tv.emplace_back(3 * hg.vertex[i] + r, 3 * hg.vertex[j] + r, -hg.damping * ww);
        }
      }
    }
  }
  if (field.air_damping != 0) {
    const auto mass = model.mass();
    for (Index i = 0; i < n; ++i) {
      for (int r = 0; r < 3; ++r) tv.emplace_back(3 * i + r, 3 * i + r, -field.air_damping * mass[at(i)]);
    }
  }
  if (field.drag) {
    const Index i = field.drag->vertex;
    for (int r = 0; r < 3; ++r) {
      tx.emplace_back(3 * i + r, 3 * i + r, -field.drag->stiffness);
      tv.emplace_back(3 * i + r, 3 * i + r, -field.drag->damping);
    }
  }
  ForceJacobians j;
  j.dfdx.resize(3 * n, 3 * n);
  j.dfdv.resize(3 * n, 3 * n);
  j.dfdx.setFromTriplets(tx.begin(), tx.end());
  j.dfdv.setFromTriplets(tv.begin(), tv.end());
  return j;
}

SpringBlocks spring_blocks(const Spring& sp, Scalar damping, const Vec3& xa, const Vec3& xb) {
  const Vec3 d = xa - xb;
  const Scalar l = d.norm();
  if (!(l > 0)) return {Mat3::Zero(), Mat3::Zero()};
  const Vec3 dir = d / l;
  const Mat3 outer = dir * dir.transpose();
  const Scalar transverse = std::max<Scalar>(0, 1 - sp.rest_length / l);
  return {-sp.stiffness * (outer + transverse * (Mat3::Identity() - outer)), -damping * outer};
}

Energy compute_energy(const Model& model, const ForceField& field, const State& state) {
  Energy e;
  const auto mass = model.mass();
  for (std::size_t i = 0; i < state.x.size(); ++i) {
    if (model.inv_mass()[i] == 0) continue;
    e.kinetic += 0.5 * mass[i] * state.v[i].squaredNorm();
    e.gravity -= mass[i] * field.gravity.dot(state.x[i]);
  }
  for (const Spring& sp : model.springs()) {
    const Scalar stretch = (state.x[at(sp.a)] - state.x[at(sp.b)]).norm() - sp.rest_length;
    e.spring += 0.5 * sp.stiffness * stretch * stretch;
  }
  for (const Hinge& hg : model.hinges()) {
    Vec3 bend = Vec3::Zero();
    for (std::size_t k = 0; k < 4; ++k) bend += hg.weight[k] * state.x[at(hg.vertex[k])];
    e.bending += 0.5 * hg.stiffness * bend.squaredNorm();
  }
  if (field.drag) {
    e.drag = 0.5 * field.drag->stiffness * (field.drag->target - state.x[at(field.drag->vertex)]).squaredNorm();
  }
  return e;
}

Vec3 linear_momentum(const Model& model, std::span<const Vec3> v) {
  Vec3 p = Vec3::Zero();
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (model.inv_mass()[i] > 0) p += model.mass()[i] * v[i];
  }
  return p;
}

Scalar longest_spring_ratio(const Model& model, std::span<const Vec3> x) {
  Scalar most = 0;
  for (const Spring& s : model.springs()) {
    if (!(s.rest_length > 0)) continue;
    most = std::max(most, (x[at(s.a)] - x[at(s.b)]).norm() / s.rest_length);
  }
  return most;
}

}  // namespace crumple::sim

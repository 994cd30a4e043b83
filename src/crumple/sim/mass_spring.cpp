#include <crumple/core/error.hpp>
#include <crumple/sim/mass_spring.hpp>

#include <cmath>
#include <string>

namespace crumple::sim {

namespace {
inline std::size_t at(Index i) { return static_cast<std::size_t>(i); }
bool finite_non_negative(Scalar x) { return std::isfinite(x) && x >= 0; }
}  // namespace

Model Model::create(std::vector<Scalar> masses, std::vector<Spring> springs, std::vector<Face> faces) {
  const Index n = static_cast<Index>(masses.size());
  for (std::size_t i = 0; i < masses.size(); ++i) {
    if (!finite_non_negative(masses[i])) {
      throw InputError("particle " + std::to_string(i) + ": mass must be finite and >= 0");
    }
  }
  for (std::size_t s = 0; s < springs.size(); ++s) {
    const Spring& sp = springs[s];
    const std::string where = "spring " + std::to_string(s) + ": ";
    if (sp.a < 0 || sp.a >= n || sp.b < 0 || sp.b >= n) throw InputError(where + "particle id out of range");
    if (sp.a == sp.b) throw InputError(where + "joins a particle to itself");
    if (!finite_non_negative(sp.stiffness) || !finite_non_negative(sp.damping_ratio) ||
        !finite_non_negative(sp.rest_length)) {
      throw InputError(where + "stiffness, damping ratio and rest length must be finite and >= 0");
    }
  }
  Model m;
  m.topology_ = std::make_shared<const Topology>(Topology::build(n, std::move(faces)));
  m.inv_mass_.resize(masses.size());
  for (std::size_t i = 0; i < masses.size(); ++i) m.inv_mass_[i] = masses[i] > 0 ? 1 / masses[i] : 0;
  m.damping_.resize(springs.size());
  for (std::size_t s = 0; s < springs.size(); ++s) {
    const Spring& sp = springs[s];
    const Scalar ia = m.inv_mass_[at(sp.a)], ib = m.inv_mass_[at(sp.b)];
    const Scalar inv_reduced = ia + ib;  // 1/μ = 1/m_a + 1/m_b
    m.damping_[s] = inv_reduced > 0 ? 2 * sp.damping_ratio * std::sqrt(sp.stiffness / inv_reduced) : 0;
  }
  m.mass_ = std::move(masses);
  m.springs_ = std::move(springs);
  return m;
}

Scalar Model::free_mass() const {
  Scalar total = 0;
  for (std::size_t i = 0; i < mass_.size(); ++i) {
    if (inv_mass_[i] > 0) total += mass_[i];
  }
  return total;
}

std::vector<Spring> cloth_springs(const Topology& topo, PositionsView x, const ClothParams& p) {
  std::vector<Spring> out;
  for (const Edge& e : topo.edges()) {
    out.push_back({e[0], e[1], p.stiffness, p.damping_ratio, (x[at(e[0])] - x[at(e[1])]).norm()});
  }
  if (p.bending_stiffness > 0) {
    for (Index e = 0; e < topo.num_edges(); ++e) {
      const auto faces = topo.edge_faces()[e];
      if (faces.size() != 2) continue;
      const Edge& ed = topo.edge(e);
      Index opposite[2] = {-1, -1};
      for (int k = 0; k < 2; ++k) {
        for (Index v : topo.face(faces[static_cast<std::size_t>(k)])) {
          if (v != ed[0] && v != ed[1]) opposite[k] = v;
        }
      }
      if (opposite[0] < 0 || opposite[1] < 0 || opposite[0] == opposite[1]) continue;
      out.push_back({opposite[0], opposite[1], p.bending_stiffness, p.bending_damping_ratio,
                     (x[at(opposite[0])] - x[at(opposite[1])]).norm()});
    }
  }
  return out;
}

Cloth make_cloth(const TriMesh& mesh, const ClothParams& params) {
  const Topology& topo = mesh.topology();
  const Positions& x = mesh.positions();
  std::vector<Scalar> masses(x.size(), 0);
  for (const Face& f : topo.faces()) {
    const Scalar area = 0.5 * (x[at(f[1])] - x[at(f[0])]).cross(x[at(f[2])] - x[at(f[0])]).norm();
    for (Index v : f) masses[at(v)] += params.density * area / 3;
  }
  for (Index p : params.pins) {
    if (p < 0 || p >= mesh.num_vertices()) {
      throw InputError("pin " + std::to_string(p) + " out of range (mesh has " +
                       std::to_string(mesh.num_vertices()) + " vertices)");
    }
  }
  for (std::size_t i = 0; i < masses.size(); ++i) {
    if (masses[i] <= 0) {
      throw InputError("vertex " + std::to_string(i) +
                       " has no mass (isolated or only on zero-area faces)");
    }
  }
  for (Index p : params.pins) masses[at(p)] = 0;
  std::vector<Spring> springs = cloth_springs(topo, x, params);
  std::vector<Face> faces(topo.faces().begin(), topo.faces().end());
  Cloth c{Model::create(std::move(masses), std::move(springs), std::move(faces)), State{}};
  c.state.x = x;
  c.state.v.assign(x.size(), Vec3::Zero());
  return c;
}

}  // namespace crumple::sim

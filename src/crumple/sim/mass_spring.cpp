#include <crumple/core/error.hpp>
#include <crumple/sim/mass_spring.hpp>

#include <atomic>
#include <cmath>
#include <utility>
#include <string>

namespace crumple::sim {

namespace {
inline std::size_t at(Index i) { return static_cast<std::size_t>(i); }
bool finite_non_negative(Scalar x) { return std::isfinite(x) && x >= 0; }
std::uint64_t next_revision() {
  static std::atomic<std::uint64_t> last{0};
  return ++last;
}
}  // namespace

namespace {
void check_hinges(std::span<const Hinge> hinges, Index n) {
  for (std::size_t h = 0; h < hinges.size(); ++h) {
    const Hinge& hg = hinges[h];
    const std::string where = "hinge " + std::to_string(h) + ": ";
    for (std::size_t i = 0; i < 4; ++i) {
      if (hg.vertex[i] < 0 || hg.vertex[i] >= n) throw InputError(where + "particle id out of range");
      if (!std::isfinite(hg.weight[i])) throw InputError(where + "weights must be finite");
      for (std::size_t j = 0; j < i; ++j) {
        if (hg.vertex[i] == hg.vertex[j]) throw InputError(where + "repeats a particle");
      }
    }
    if (!finite_non_negative(hg.stiffness) || !finite_non_negative(hg.damping)) {
      throw InputError(where + "stiffness and damping must be finite and >= 0");
    }
  }
}
}  // namespace

Model Model::with_hinges(std::vector<Hinge> hinges) const {
  check_hinges(hinges, num_particles());
  Model m = *this;
  m.hinges_ = std::move(hinges);
  m.revision_ = next_revision();
  return m;
}

Model Model::create(std::vector<Scalar> masses, std::vector<Spring> springs, std::vector<Face> faces,
                    std::vector<Hinge> hinges) {
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
  check_hinges(hinges, n);
  Model m;
  m.hinges_ = std::move(hinges);
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
  m.revision_ = next_revision();
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

namespace {

Scalar face_area(PositionsView x, const Face& f) {
  return 0.5 * (x[at(f[1])] - x[at(f[0])]).cross(x[at(f[2])] - x[at(f[0])]).norm();
}

/// Lumped masses (a third of density × area per corner), pins checked and set to 0.
std::vector<Scalar> lumped_masses(const TriMesh& mesh, Scalar density, std::span<const Index> pins) {
  const Topology& topo = mesh.topology();
  const Positions& x = mesh.positions();
  std::vector<Scalar> masses(x.size(), 0);
  for (const Face& f : topo.faces()) {
    const Scalar area = face_area(x, f);
    for (Index v : f) masses[at(v)] += density * area / 3;
  }
  for (Index p : pins) {
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
  for (Index p : pins) masses[at(p)] = 0;
  return masses;
}

/// The vertices of the two faces of interior edge e opposite to it, or {-1, -1}.
std::array<Index, 2> opposite_vertices(const Topology& topo, Index e) {
  const auto faces = topo.edge_faces()[e];
  if (faces.size() != 2) return {-1, -1};
  const Edge& ed = topo.edge(e);
  std::array<Index, 2> opposite{-1, -1};
  for (std::size_t k = 0; k < 2; ++k) {
    for (Index v : topo.face(faces[k])) {
      if (v != ed[0] && v != ed[1]) opposite[k] = v;
    }
  }
  if (opposite[0] < 0 || opposite[1] < 0 || opposite[0] == opposite[1]) return {-1, -1};
  return opposite;
}

/// ζ giving the damping coefficient c on a spring of stiffness k between particles with inverse
/// masses ia, ib (`Model::create` computes c = 2 ζ √(k μ) back from it); 0 when both are pinned.
Scalar damping_ratio_for(Scalar c, Scalar k, Scalar ia, Scalar ib) {
  const Scalar inv_reduced = ia + ib;
  if (!(inv_reduced > 0) || !(k > 0)) return 0;
  return c / (2 * std::sqrt(k / inv_reduced));
}

}  // namespace

Cloth make_cloth(const TriMesh& mesh, const ClothParams& params) {
  const Topology& topo = mesh.topology();
  const Positions& x = mesh.positions();
  std::vector<Scalar> masses = lumped_masses(mesh, params.density, params.pins);
  std::vector<Spring> springs = cloth_springs(topo, x, params);
  std::vector<Face> faces(topo.faces().begin(), topo.faces().end());
  Cloth c{Model::create(std::move(masses), std::move(springs), std::move(faces)), State{}};
  c.state.x = x;
  c.state.v.assign(x.size(), Vec3::Zero());
  return c;
}

Cloth make_cloth(const TriMesh& mesh, const Material& mat) {
  for (const auto& [name, value] : {std::pair<const char*, Scalar>{"stretch", mat.stretch},
                                    {"shear", mat.shear},
                                    {"bending", mat.bending},
                                    {"damping", mat.damping}}) {
    if (!finite_non_negative(value)) {
      throw InputError(std::string("material ") + name + " must be finite and >= 0");
    }
  }
  if (!(std::isfinite(mat.density) && mat.density > 0)) throw InputError("material density must be finite and > 0");
  const Topology& topo = mesh.topology();
  const Positions& x = mesh.positions();
  std::vector<Scalar> masses = lumped_masses(mesh, mat.density, mat.pins);
  const auto inv = [&](Index v) { return masses[at(v)] > 0 ? 1 / masses[at(v)] : 0; };
  // A_e: a third of the area of each face on the edge.
  std::vector<Scalar> edge_area(static_cast<std::size_t>(topo.num_edges()), 0);
  for (Index f = 0; f < topo.num_faces(); ++f) {
    const Scalar third = face_area(x, topo.face(f)) / 3;
    for (Index e : topo.face_edges(f)) edge_area[at(e)] += third;
  }
  std::vector<Spring> springs;
  const auto add_spring = [&](Index a, Index b, Scalar modulus, Scalar area) {
    const Scalar rest = (x[at(a)] - x[at(b)]).norm();
    if (!(rest > 0)) return;
    const Scalar k = modulus * area / (rest * rest);
    springs.push_back({a, b, k, damping_ratio_for(mat.damping * k, k, inv(a), inv(b)), rest});
  };
  for (Index e = 0; e < topo.num_edges(); ++e) {
    add_spring(topo.edge(e)[0], topo.edge(e)[1], mat.stretch, edge_area[at(e)]);
  }
  if (mat.shear > 0) {
    for (Index e = 0; e < topo.num_edges(); ++e) {
      const auto opposite = opposite_vertices(topo, e);
      if (opposite[0] >= 0) add_spring(opposite[0], opposite[1], mat.shear, edge_area[at(e)]);
    }
  }
  std::vector<Hinge> hinges;
  if (mat.bending > 0) {
    for (Index e = 0; e < topo.num_edges(); ++e) {
      const auto opposite = opposite_vertices(topo, e);
      if (opposite[0] < 0) continue;
      const Edge& ed = topo.edge(e);
      const Vec3 p0 = x[at(ed[0])];
      const Vec3 along = x[at(ed[1])] - p0;
      const Scalar length = along.norm();
      if (!(length > 0)) continue;
      const Vec3 t = along / length;
      // Offsets of the opposite vertices along the edge (a) and from its line (h).
      std::array<Scalar, 2> a{}, h{};
      for (std::size_t k = 0; k < 2; ++k) {
        const Vec3 r = x[at(opposite[k])] - p0;
        a[k] = r.dot(t);
        h[k] = (r - a[k] * t).norm();
      }
      if (!(h[0] > 1e-9 * length && h[1] > 1e-9 * length)) continue;
      Hinge hg;
      hg.vertex = {ed[0], ed[1], opposite[0], opposite[1]};
      const Scalar w2 = 1 / h[0], w3 = 1 / h[1];
      const Scalar w1 = -(w2 * a[0] + w3 * a[1]) / length;
      hg.weight = {-(w2 + w3) - w1, w1, w2, w3};
      const Scalar d = 0.5 * (h[0] + h[1]);
      // 3: each hinge feels only the curvature across its own edge, so over a mesh's edge
      // directions a cylinder loads about a third of them fully (tests/sim/material_test.cpp).
      hg.stiffness = 3 * mat.bending * edge_area[at(e)] / (d * d);
      hg.damping = mat.damping * hg.stiffness;
      hinges.push_back(hg);
    }
  }
  std::vector<Face> faces(topo.faces().begin(), topo.faces().end());
  Cloth c{Model::create(std::move(masses), std::move(springs), std::move(faces), std::move(hinges)), State{}};
  c.state.x = x;
  c.state.v.assign(x.size(), Vec3::Zero());
  return c;
}

}  // namespace crumple::sim

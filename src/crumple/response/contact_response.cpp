#include <crumple/core/error.hpp>
#include <crumple/core/parallel.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/response/contact_response.hpp>

#include <algorithm>
#include <cmath>

namespace crumple::response {

namespace {
inline std::size_t at(Index i) { return static_cast<std::size_t>(i); }
}  // namespace

Stencil vertex_face_stencil(Index vertex, const Face& f, const Vec3& w, const Vec3& normal) {
  Stencil s;
  s.count = 4;
  s.vertex = {vertex, f[0], f[1], f[2]};
  s.weight = {1, -w[0], -w[1], -w[2]};
  s.normal = normal;
  return s;
}

Stencil edge_edge_stencil(const Edge& a, const Edge& b, Scalar s_a, Scalar t_b, const Vec3& normal) {
  Stencil s;
  s.count = 4;
  s.vertex = {a[0], a[1], b[0], b[1]};
  s.weight = {-(1 - s_a), -s_a, 1 - t_b, t_b};
  s.normal = normal;
  s.edge_edge = true;
  return s;
}

Stencil make_stencil(const VertexFaceContact& c, std::span<const Face> faces) {
  CRUMPLE_CHECK(c.face >= 0 && at(c.face) < faces.size(), "vertex-face contact face out of range");
  return vertex_face_stencil(c.vertex, faces[at(c.face)], c.barycentric, c.normal);
}

Stencil make_stencil(const EdgeEdgeContact& c) { return edge_edge_stencil(c.a, c.b, c.s, c.t, c.normal); }

std::vector<Stencil> make_stencils(const ContactSet& contacts, std::span<const Face> faces) {
  std::vector<Stencil> out;
  out.reserve(contacts.vf.size() + contacts.ee.size());
  for (const auto& c : contacts.vf) {
    if (c.normal.squaredNorm() > 0) out.push_back(make_stencil(c, faces));
  }
  for (const auto& c : contacts.ee) {
    if (c.normal.squaredNorm() > 0) out.push_back(make_stencil(c));
  }
  return out;
}

namespace {
/// The first half of `refresh_stencil`: the closest points' weights into `s`, their difference
/// (from the first primitive to the second) and the stencil's extent.
inline void closest_points(Stencil& s, std::span<const Vec3> x, Vec3& d, Scalar& extent) {
  const auto p = [&](int k) { return x[at(s.vertex[static_cast<std::size_t>(k)])]; };
  Vec3 from, to;
  if (s.edge_edge) {
    const geometry::SegmentSegmentResult r = geometry::segment_segment(p(0), p(1), p(2), p(3));
    s.weight = {-(1 - r.s), -r.s, 1 - r.t, r.t};
    from = r.closest0;
    to = r.closest1;
  } else {
    const geometry::PointTriangleResult r = geometry::point_triangle(p(0), p(1), p(2), p(3));
    s.weight = {1, -r.barycentric[0], -r.barycentric[1], -r.barycentric[2]};
    from = r.closest;
    to = p(0);
  }
  d = to - from;
  extent = 0;
  for (int k = 1; k < s.count; ++k) extent = std::max(extent, (p(k) - p(0)).cwiseAbs().maxCoeff());
}

/// The second half: the normal along `d`, on the side of the current one.
inline void turn_normal(Stencil& s, const Vec3& d, Scalar extent) {
  const Scalar length = d.norm();
  // The closest points carry rounding errors of a few ulps of the configuration's size: at a
  // distance within a small multiple of that, d's direction is noise (a vertex landing on its
  // face can get an in-plane "normal", and the push-out then moves it sideways and lets it
  // through). Such a pair touches: it keeps its normal.
  if (!(length > 1e-9 * extent)) return;
  const Vec3 n = d / length;
  s.normal = n.dot(s.normal) >= 0 ? n : Vec3(-n);
}
}  // namespace

void refresh_stencil(Stencil& s, std::span<const Vec3> x) {
  Vec3 d;
  Scalar extent;
  closest_points(s, x, d, extent);
  turn_normal(s, d, extent);
}

void refresh_stencils(std::span<Stencil> stencils, std::span<const Vec3> x) {
  // In blocks: the closest points (branchy) of the whole block first, then its square roots and
  // divisions, which no longer wait behind each stencil's mispredicted branches. The same
  // operations on the same values as `refresh_stencil`, stencil by stencil.
  constexpr std::size_t kBlock = 32;
  std::array<Vec3, kBlock> d;
  std::array<Scalar, kBlock> extent;
  for (std::size_t begin = 0; begin < stencils.size(); begin += kBlock) {
    const std::size_t count = std::min(kBlock, stencils.size() - begin);
    for (std::size_t k = 0; k < count; ++k) closest_points(stencils[begin + k], x, d[k], extent[k]);
    for (std::size_t k = 0; k < count; ++k) turn_normal(stencils[begin + k], d[k], extent[k]);
  }
}

namespace {
/// Whether some vertex of `a` is within `rings` (1 or 2) one-rings of some vertex of `b`.
bool within_rings(std::span<const Index> a, std::span<const Index> b, const Adjacency& ring, int rings) {
  for (const Index u : a) {
    for (const Index w : b) {
      if (u == w) return true;
      const auto ru = ring[u];
      if (std::find(ru.begin(), ru.end(), w) != ru.end()) return true;
      if (rings < 2) continue;
      const auto rw = ring[w];
      for (const Index k : ru) {
        if (std::find(rw.begin(), rw.end(), k) != rw.end()) return true;
      }
    }
  }
  return false;
}
}  // namespace

std::size_t drop_flat_neighbours(std::vector<Stencil>& stencils, const Topology& topology,
                                 std::span<const Vec3> x, const FlatNeighbourOptions& options) {
  CRUMPLE_CHECK(options.rings >= 1 && options.rings <= 2, "flat neighbour rings must be 1 or 2");
  CRUMPLE_CHECK(x.size() == static_cast<std::size_t>(topology.num_vertices()),
                "positions must have #V entries");
  if (stencils.empty()) return 0;
  // Area-weighted face normals (unnormalised); a side's normal is their sum over the side's faces.
  const auto faces = topology.faces();
  std::vector<Vec3> face_normal(faces.size());
  parallel_for_chunks(faces.size(), options.threads, balanced_grain(faces.size(), options.threads, 1024, 65536),
                      [&](std::size_t begin, std::size_t end) {
                        for (std::size_t f = begin; f < end; ++f) {
                          const Face& t = faces[f];
                          face_normal[f] = (x[at(t[1])] - x[at(t[0])]).cross(x[at(t[2])] - x[at(t[0])]);
                        }
                      });
  const auto unit_sum = [&](std::span<const Index> incident) {
    Vec3 n = Vec3::Zero();
    for (const Index f : incident) n += face_normal[at(f)];
    const Scalar length = n.norm();
    return length > 0 ? Vec3(n / length) : Vec3(Vec3::Zero());
  };
  const auto find_edge = [&](Index u, Index w) {
    for (const Index e : topology.vertex_edges()[u]) {
      const Edge& g = topology.edge(e);
      if ((g[0] == u && g[1] == w) || (g[0] == w && g[1] == u)) return e;
    }
    return Index{-1};
  };
  const auto flat = [&](const Stencil& s) {
    if (relative_normal(s, x) < options.keep_within) return false;
    Vec3 na, nb;
    if (s.edge_edge) {
      const Index ea = find_edge(s.vertex[0], s.vertex[1]);
      const Index eb = find_edge(s.vertex[2], s.vertex[3]);
      if (ea < 0 || eb < 0) return false;
      na = unit_sum(topology.edge_faces()[ea]);
      nb = unit_sum(topology.edge_faces()[eb]);
    } else {
      na = unit_sum(topology.vertex_faces()[s.vertex[0]]);
      // The face is the stencil's last three vertices; its normal is its own.
      const Vec3 n = (x[at(s.vertex[2])] - x[at(s.vertex[1])]).cross(x[at(s.vertex[3])] - x[at(s.vertex[1])]);
      const Scalar length = n.norm();
      nb = length > 0 ? Vec3(n / length) : Vec3(Vec3::Zero());
    }
    // A zero normal (a degenerate side) fails `alike` and keeps the pair.
    if (!(na.dot(nb) >= options.alike)) return false;
    if (!(std::abs(s.normal.dot(na)) <= options.along) || !(std::abs(s.normal.dot(nb)) <= options.along)) {
      return false;
    }
    const std::span<const Index> all(s.vertex.data(), 4);
    const std::size_t split = s.edge_edge ? 2 : 1;
    return within_rings(all.first(split), all.subspan(split), topology.vertex_vertices(), options.rings);
  };
  std::vector<char> drop(stencils.size());
  parallel_for_chunks(stencils.size(), options.threads,
                      balanced_grain(stencils.size(), options.threads, 1024, 65536),
                      [&](std::size_t begin, std::size_t end) {
                        for (std::size_t i = begin; i < end; ++i) drop[i] = flat(stencils[i]) ? 1 : 0;
                      });
  std::size_t kept = 0;
  for (std::size_t i = 0; i < stencils.size(); ++i) {
    if (!drop[i]) stencils[kept++] = stencils[i];
  }
  const std::size_t dropped = stencils.size() - kept;
  stencils.resize(kept);
  return dropped;
}

namespace {
/// `relative_normal`, inlined into the sweep that tests every stencil several times a step.
inline Scalar relative_normal_inline(const Stencil& s, std::span<const Vec3> q) {
  Vec3 r = Vec3::Zero();
  for (int k = 0; k < s.count; ++k) r += s.weight[k] * q[at(s.vertex[k])];
  return r.dot(s.normal);
}
}  // namespace

Scalar relative_normal(const Stencil& s, std::span<const Vec3> q) { return relative_normal_inline(s, q); }

Scalar inverse_effective_mass(const Stencil& s, std::span<const Scalar> inv_mass) {
  Scalar d = 0;
  for (int k = 0; k < s.count; ++k) d += s.weight[k] * s.weight[k] * inv_mass[at(s.vertex[k])];
  return d;
}

namespace {
void apply(const Stencil& s, std::span<const Scalar> inv_mass, std::span<Vec3> q, Scalar lambda) {
  for (int k = 0; k < s.count; ++k) {
    const Scalar w = s.weight[k] * inv_mass[at(s.vertex[k])];
    if (w != 0) q[at(s.vertex[k])] += (w * lambda) * s.normal;
  }
}
}  // namespace

Scalar correct_velocity(const Stencil& s, std::span<const Scalar> inv_mass, std::span<Vec3> v) {
  const Scalar vn = relative_normal(s, v);
  if (!(vn < 0)) return 0;
  const Scalar d = inverse_effective_mass(s, inv_mass);
  if (!(d > 0)) return 0;
  const Scalar lambda = -vn / d;
  apply(s, inv_mass, v, lambda);
  return lambda;
}

Scalar correct_position(const Stencil& s, std::span<const Scalar> inv_mass, std::span<Vec3> x,
                        Scalar target) {
  const Scalar gap = relative_normal(s, x);
  if (!(gap < target)) return 0;
  const Scalar d = inverse_effective_mass(s, inv_mass);
  if (!(d > 0)) return 0;
  const Scalar mu = (target - gap) / d;
  apply(s, inv_mass, x, mu);
  return mu;
}

ResponseStats resolve(std::span<const Stencil> stencils, std::span<const Scalar> inv_mass,
                      std::span<Vec3> x, std::span<Vec3> v, const ResponseOptions& options) {
  CRUMPLE_CHECK(options.passes >= 1, "response passes must be >= 1");
  CRUMPLE_CHECK(x.size() == inv_mass.size() && v.size() == inv_mass.size(),
                "response arrays must have #V entries");
  ResponseStats stats;
  const Scalar too_close = options.thickness * (1 - options.position_tolerance);
  for (int pass = 0; pass < options.passes; ++pass) {
    ++stats.passes;
    std::size_t applied = 0;
    for (const Stencil& s : stencils) {
      if (options.velocity && relative_normal(s, v) < -options.velocity_tolerance) {
        if (correct_velocity(s, inv_mass, v) > 0) ++applied;
      }
      if (options.position && options.thickness > 0 && relative_normal(s, x) < too_close) {
        if (correct_position(s, inv_mass, x, options.thickness) > 0) ++applied;
      }
    }
    stats.corrections += applied;
    if (applied == 0) {
      stats.converged = true;
      break;
    }
  }
  return stats;
}

namespace {
/// Adds cᵢ mᵢ⁻¹ λ `direction` to every vertex of the stencil.
void apply_along(const Stencil& s, std::span<const Scalar> inv_mass, std::span<Vec3> q, Scalar lambda,
                 const Vec3& direction) {
  for (int k = 0; k < s.count; ++k) {
    const Scalar w = s.weight[k] * inv_mass[at(s.vertex[k])];
    if (w != 0) q[at(s.vertex[k])] += (w * lambda) * direction;
  }
}
}  // namespace

ResponseStats resolve_proximity(std::span<const Stencil> stencils, std::span<const Scalar> inv_mass,
                                std::span<Vec3> x, std::span<Vec3> v, const ProximityOptions& options) {
  CRUMPLE_CHECK(options.passes >= 1, "response passes must be >= 1");
  CRUMPLE_CHECK(options.friction >= 0, "friction must be >= 0");
  CRUMPLE_CHECK(options.relaxation > 0 && options.relaxation <= 1, "proximity relaxation must be in (0, 1]");
  CRUMPLE_CHECK(x.size() == inv_mass.size() && v.size() == inv_mass.size(),
                "response arrays must have #V entries");
  ResponseStats stats;
  const Scalar h = options.thickness;
  const Scalar omega = options.relaxation;
  const Scalar too_close = h * (1 - options.position_tolerance);
  for (int pass = 0; pass < options.passes; ++pass) {
    ++stats.passes;
    std::size_t applied = 0;
    for (const Stencil& s : stencils) {
      const Scalar gap = relative_normal_inline(s, x);
      if (!(gap < too_close)) continue;
      const Scalar d = inverse_effective_mass(s, inv_mass);
      if (!(d > 0)) continue;
      apply_along(s, inv_mass, x, omega * (h - gap) / d, s.normal);
      Vec3 r = Vec3::Zero();
      for (int k = 0; k < s.count; ++k) r += s.weight[k] * v[at(s.vertex[k])];
      const Scalar vn = r.dot(s.normal);
      const Scalar lambda = vn < 0 ? -vn / d : 0;
      if (lambda > 0) apply_along(s, inv_mass, v, lambda, s.normal);
      const Vec3 tangential = r - vn * s.normal;
      const Scalar slide = tangential.norm();
      if (options.friction > 0 && lambda > 0 && slide > 0) {
        const Scalar lambda_t = std::min(options.friction * lambda, slide / d);
        apply_along(s, inv_mass, v, -lambda_t, tangential / slide);
      }
      ++applied;
    }
    stats.corrections += applied;
    if (applied == 0) {
      stats.converged = true;
      break;
    }
  }
  return stats;
}

void update_contact_forces(std::span<const Stencil> stencils, std::span<const Vec3> x,
                           std::span<const Scalar> diagonal,
                           const std::function<void(std::span<const Vec3>, std::span<Vec3>)>& solve,
                           const ContactForceOptions& options, std::span<Scalar> lambda, std::span<Vec3> force,
                           ContactForceScratch& scratch) {
  CRUMPLE_CHECK(options.relaxation > 0 && options.relaxation <= 1, "contact force relaxation must be in (0, 1]");
  CRUMPLE_CHECK(lambda.size() == stencils.size(), "contact forces need one multiplier per stencil");
  CRUMPLE_CHECK(diagonal.size() == x.size() && force.size() == x.size(), "contact force arrays must have #V entries");
  const Scalar h = options.thickness;
  std::vector<Scalar>& change = scratch.change;
  std::vector<Scalar>& asked = scratch.asked;
  std::vector<int>& count = scratch.count;
  std::vector<char>& acting = scratch.acting;
  change.assign(stencils.size(), 0);
  asked.assign(stencils.size(), 0);
  count.assign(x.size(), 0);
  acting.assign(stencils.size(), 0);
  for (std::size_t k = 0; k < stencils.size(); ++k) {
    const Stencil& s = stencils[k];
    asked[k] = relative_normal(s, x);  // the gap, for now
    if (!(asked[k] < h || lambda[k] > 0)) continue;
    acting[k] = 1;
    for (int c = 0; c < s.count; ++c) {
      if (diagonal[at(s.vertex[c])] > 0 && s.weight[c] != 0) ++count[at(s.vertex[c])];
    }
  }
  // The proposed changes, and the gap change each asks for.
  std::vector<Vec3>& proposed = scratch.proposed;
  proposed.assign(x.size(), Vec3::Zero());
  bool any = false;
  for (std::size_t k = 0; k < stencils.size(); ++k) {
    if (!acting[k]) continue;
    const Stencil& s = stencils[k];
    Scalar compliance = 0;
    for (int c = 0; c < s.count; ++c) {
      const Scalar d = diagonal[at(s.vertex[c])];
      if (d > 0) compliance += s.weight[c] * s.weight[c] * count[at(s.vertex[c])] / d;
    }
    if (!(compliance > 0)) {
      change[k] = -lambda[k];
      asked[k] = 0;
      continue;
    }
    change[k] = std::max<Scalar>(-lambda[k], options.relaxation * (h - asked[k]) / compliance);
    asked[k] = change[k] * compliance;
    if (change[k] == 0) continue;
    any = true;
    for (int c = 0; c < s.count; ++c) {
      if (diagonal[at(s.vertex[c])] > 0) proposed[at(s.vertex[c])] += (s.weight[c] * change[k]) * s.normal;
    }
  }
  if (any) {
    // Their response in the global step; a pair moved farther than it asked takes its share.
    std::vector<Vec3>& moved = scratch.moved;
    moved.assign(x.size(), Vec3::Zero());
    solve(proposed, moved);
    for (std::size_t k = 0; k < stencils.size(); ++k) {
      if (change[k] == 0 || asked[k] == 0) continue;
      const Scalar got = relative_normal(stencils[k], moved);
      if (std::abs(got) > std::abs(asked[k])) change[k] *= std::abs(asked[k]) / std::abs(got);
    }
  }
  for (std::size_t k = 0; k < stencils.size(); ++k) {
    if (!acting[k]) continue;
    lambda[k] = std::max<Scalar>(0, lambda[k] + change[k]);
    if (!(lambda[k] > 0)) continue;
    const Stencil& s = stencils[k];
    for (int c = 0; c < s.count; ++c) {
      if (diagonal[at(s.vertex[c])] > 0) force[at(s.vertex[c])] += (s.weight[c] * lambda[k]) * s.normal;
    }
  }
}

}  // namespace crumple::response

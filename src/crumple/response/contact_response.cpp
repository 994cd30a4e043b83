#include <crumple/core/error.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/response/contact_response.hpp>

#include <algorithm>

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

void refresh_stencil(Stencil& s, std::span<const Vec3> x) {
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
  const Vec3 d = to - from;
  const Scalar length = d.norm();
  // The closest points carry rounding errors of a few ulps of the configuration's size: at a
  // distance within a small multiple of that, d's direction is noise (a vertex landing on its
  // face can get an in-plane "normal", and the push-out then moves it sideways and lets it
  // through). Such a pair touches: it keeps its normal.
  Scalar extent = 0;
  for (int k = 1; k < s.count; ++k) extent = std::max(extent, (p(k) - p(0)).cwiseAbs().maxCoeff());
  if (!(length > 1e-9 * extent)) return;
  const Vec3 n = d / length;
  s.normal = n.dot(s.normal) >= 0 ? n : Vec3(-n);
}

Scalar relative_normal(const Stencil& s, std::span<const Vec3> q) {
  Vec3 r = Vec3::Zero();
  for (int k = 0; k < s.count; ++k) r += s.weight[k] * q[at(s.vertex[k])];
  return r.dot(s.normal);
}

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
  CRUMPLE_CHECK(x.size() == inv_mass.size() && v.size() == inv_mass.size(),
                "response arrays must have #V entries");
  ResponseStats stats;
  const Scalar h = options.thickness;
  const Scalar too_close = h * (1 - options.position_tolerance);
  for (int pass = 0; pass < options.passes; ++pass) {
    ++stats.passes;
    std::size_t applied = 0;
    for (const Stencil& s : stencils) {
      const Scalar gap = relative_normal(s, x);
      if (!(gap < too_close)) continue;
      const Scalar d = inverse_effective_mass(s, inv_mass);
      if (!(d > 0)) continue;
      apply_along(s, inv_mass, x, (h - gap) / d, s.normal);
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

}  // namespace crumple::response

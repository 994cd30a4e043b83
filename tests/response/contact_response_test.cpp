// Velocity and position correction of single contacts and of stacks (SPEC.md §5, Annex B).
#include <crumple/detect/detector.hpp>
#include <crumple/response/contact_response.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace crumple::response {
namespace {

Vec3 random_vec(std::mt19937_64& rng, double scale) {
  std::uniform_real_distribution<double> u(-scale, scale);
  return {u(rng), u(rng), u(rng)};
}

Vec3 momentum(std::span<const Scalar> inv_mass, std::span<const Vec3> v) {
  Vec3 p = Vec3::Zero();
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (inv_mass[i] > 0) p += v[i] / inv_mass[i];
  }
  return p;
}

/// One VF and one EE contact over 8 vertices with random masses, velocities, normals.
struct Fixture {
  std::vector<Scalar> inv_mass;
  std::vector<Vec3> x, v;
  std::vector<Face> faces{{1, 2, 3}};
  VertexFaceContact vf;
  EdgeEdgeContact ee;

  explicit Fixture(std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> mass(0.2, 5.0), unit(0.05, 0.95);
    for (int i = 0; i < 8; ++i) {
      inv_mass.push_back(1 / mass(rng));
      x.push_back(random_vec(rng, 1));
      v.push_back(random_vec(rng, 2));
    }
    vf.vertex = 0;
    vf.face = 0;
    const Scalar w1 = unit(rng) * 0.5, w2 = unit(rng) * 0.5;
    vf.barycentric = Vec3(w1, w2, 1 - w1 - w2);
    vf.normal = random_vec(rng, 1).normalized();
    ee.a = {4, 5};
    ee.b = {6, 7};
    ee.s = unit(rng);
    ee.t = unit(rng);
    ee.normal = random_vec(rng, 1).normalized();
  }
};

TEST(ContactResponse, StencilWeightsSumToZero) {
  const Fixture f(1);
  for (const Stencil& s : {make_stencil(f.vf, f.faces), make_stencil(f.ee)}) {
    Scalar sum = 0;
    for (int k = 0; k < s.count; ++k) sum += s.weight[k];
    EXPECT_NEAR(sum, 0, 1e-15);
  }
}

TEST(ContactResponse, VelocityCorrectionCancelsApproachAndConservesMomentum) {
  int corrected = 0;
  for (std::uint64_t seed = 1; seed <= 200; ++seed) {
    Fixture f(seed);
    for (const Stencil& s : {make_stencil(f.vf, f.faces), make_stencil(f.ee)}) {
      std::vector<Vec3> v = f.v;
      const Vec3 p0 = momentum(f.inv_mass, v);
      const Scalar before = relative_normal(s, v);
      Scalar scale = 0;
      for (int k = 0; k < s.count; ++k) scale += std::abs(s.weight[k]) * v[static_cast<std::size_t>(s.vertex[k])].norm();
      const Scalar lambda = correct_velocity(s, f.inv_mass, v);
      const Scalar after = relative_normal(s, v);
      if (before < 0) {
        ++corrected;
        EXPECT_GT(lambda, 0);
        EXPECT_LE(std::abs(after), 1e-12 * scale) << "seed " << seed;
      } else {
        EXPECT_EQ(lambda, 0) << "a separating contact is left alone";
        EXPECT_EQ(after, before);
      }
      EXPECT_LE((momentum(f.inv_mass, v) - p0).norm(), 1e-12 * (1 + p0.norm())) << "seed " << seed;
    }
  }
  EXPECT_GT(corrected, 100) << "about half the random contacts approach";
}

TEST(ContactResponse, PositionCorrectionReachesThicknessAndConservesCentreOfMass) {
  for (std::uint64_t seed = 1; seed <= 100; ++seed) {
    Fixture f(seed);
    for (const Stencil& s : {make_stencil(f.vf, f.faces), make_stencil(f.ee)}) {
      std::vector<Vec3> x = f.x;
      const Vec3 c0 = momentum(f.inv_mass, x);  // Σ m x
      const Scalar gap = relative_normal(s, x);
      const Scalar target = gap + 0.1;  // always a push-out of 0.1
      EXPECT_GT(correct_position(s, f.inv_mass, x, target), 0);
      EXPECT_NEAR(relative_normal(s, x), target, 1e-12 * (1 + std::abs(target)));
      EXPECT_LE((momentum(f.inv_mass, x) - c0).norm(), 1e-12 * (1 + c0.norm()));
      EXPECT_EQ(correct_position(s, f.inv_mass, x, target - 0.05), 0) << "already far enough";
    }
  }
}

TEST(ContactResponse, EqualMassesGiveTheThesisEdgeEdgeFormula) {
  // Annex B.1: f = ((v' − v)·u) / ((1−s)² + s² + (1−t)² + t²), v1 += (1−s) f u, v2 += s f u,
  // and the opposite on the second edge.
  Fixture f(7);
  std::fill(f.inv_mass.begin(), f.inv_mass.end(), 1.0);
  const Vec3 u = f.ee.normal;
  const Scalar s = f.ee.s, t = f.ee.t;
  // Make edge b approach edge a along u.
  f.v[6] = f.v[4] - 1.0 * u;
  f.v[7] = f.v[5] - 0.5 * u;
  const Vec3 va = (1 - s) * f.v[4] + s * f.v[5], vb = (1 - t) * f.v[6] + t * f.v[7];
  const Scalar fthesis = (vb - va).dot(u) / ((1 - s) * (1 - s) + s * s + (1 - t) * (1 - t) + t * t);
  ASSERT_LT(fthesis, 0);
  std::vector<Vec3> v = f.v;
  correct_velocity(make_stencil(f.ee), f.inv_mass, v);
  EXPECT_LE((v[4] - (f.v[4] + (1 - s) * fthesis * u)).norm(), 1e-14);
  EXPECT_LE((v[5] - (f.v[5] + s * fthesis * u)).norm(), 1e-14);
  EXPECT_LE((v[6] - (f.v[6] - (1 - t) * fthesis * u)).norm(), 1e-14);
  EXPECT_LE((v[7] - (f.v[7] - t * fthesis * u)).norm(), 1e-14);
}

TEST(ContactResponse, PinnedVerticesDoNotMove) {
  Fixture f(3);
  f.inv_mass[1] = f.inv_mass[2] = f.inv_mass[3] = 0;  // the face is pinned
  const Stencil s = make_stencil(f.vf, f.faces);
  std::vector<Vec3> v = f.v, x = f.x;
  const Vec3& w = f.vf.barycentric;
  v[0] = w[0] * f.v[1] + w[1] * f.v[2] + w[2] * f.v[3] - f.vf.normal;  // approaching
  correct_velocity(s, f.inv_mass, v);
  correct_position(s, f.inv_mass, x, relative_normal(s, x) + 0.2);
  for (int i = 1; i <= 3; ++i) {
    EXPECT_EQ(v[static_cast<std::size_t>(i)], f.v[static_cast<std::size_t>(i)]);
    EXPECT_EQ(x[static_cast<std::size_t>(i)], f.x[static_cast<std::size_t>(i)]);
  }
  EXPECT_NEAR(relative_normal(s, v), 0, 1e-12);
  // Everything pinned: nothing happens.
  std::fill(f.inv_mass.begin(), f.inv_mass.end(), 0.0);
  std::vector<Vec3> v2 = f.v;
  EXPECT_EQ(correct_velocity(s, f.inv_mass, v2), 0);
}

/// Two parallel triangles closer than the thickness and approaching: after `resolve` the
/// detector finds no pair closer than the thickness and no pair approaching.
TEST(ContactResponse, ResolvesDetectedContactsBetweenTwoTriangles) {
  const Scalar h = 0.1;
  std::vector<Vec3> x{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.2, 0.2, 0.04}, {1.2, 0.2, 0.04}, {0.2, 1.2, 0.04}};
  std::vector<Face> faces{{0, 1, 2}, {3, 4, 5}};
  std::vector<Vec3> v{{0, 0, 0.5}, {0, 0, 0.5}, {0, 0, 0.5}, {0, 0, -1}, {0, 0, -1}, {0, 0, -1}};
  std::vector<Scalar> inv_mass{1, 1, 1, 0.5, 0.5, 0.5};
  const TriMesh mesh = TriMesh::create(x, faces);
  auto detector = make_detector(MethodSpec::parse("naive"), {.thickness = h, .threads = 1});
  detector->set_topology(mesh.topology_ptr());
  ContactSet contacts;
  detector->update(x, contacts);
  ASSERT_FALSE(contacts.empty());
  const auto stencils = make_stencils(contacts, faces);
  const ResponseStats stats = resolve(stencils, inv_mass, x, v, {.thickness = h, .passes = 20});
  EXPECT_TRUE(stats.converged);
  for (const Stencil& s : stencils) {
    EXPECT_GE(relative_normal(s, v), -1e-9);
    EXPECT_GE(relative_normal(s, x), h * (1 - 1e-6));
  }
  // The corrections tilt the triangles, so new pairs may come closer than h: detecting and
  // resolving again (as the simulation does every step) settles them.
  for (int round = 0; round < 10; ++round) {
    detector->update(x, contacts);
    resolve(make_stencils(contacts, faces), inv_mass, x, v, {.thickness = h, .passes = 20});
  }
  detector->update(x, contacts);
  for (const auto& c : contacts.vf) EXPECT_GE(c.distance, h * (1 - 1e-6));
  for (const auto& c : contacts.ee) EXPECT_GE(c.distance, h * (1 - 1e-6));
  EXPECT_LE((momentum(inv_mass, v) - Vec3(0, 0, 1.5 - 6)).norm(), 1e-12);
}

/// A vertical stack of particles, each resting on the next through a VF contact with a small
/// triangle of its own: the corrections interact, one sweep is not enough, several converge.
TEST(ContactResponse, StackOfContactsConvergesOverPasses) {
  const int layers = 8;
  const Scalar h = 0.1;
  std::vector<Vec3> x, v;
  std::vector<Scalar> inv_mass;
  std::vector<Face> faces;
  std::vector<Stencil> stencils;
  // Layer k: a triangle (3 vertices) at height k * 0.05 (closer than h), falling faster on top.
  for (int k = 0; k < layers; ++k) {
    const Scalar z = 0.05 * k;
    const Index base = static_cast<Index>(x.size());
    for (const Vec3& p : {Vec3(0, 0, z), Vec3(1, 0, z), Vec3(0, 1, z)}) {
      x.push_back(p);
      v.push_back(Vec3(0, 0, -0.3 * k));
      inv_mass.push_back(k == 0 ? 0.0 : 1.0);  // the bottom layer is pinned (the ground)
    }
    faces.push_back({base, base + 1, base + 2});
  }
  for (int k = 1; k < layers; ++k) {
    for (int corner = 0; corner < 3; ++corner) {
      VertexFaceContact c;
      c.vertex = static_cast<Index>(3 * k + corner);
      c.face = k - 1;
      c.barycentric = Vec3::Zero();
      c.barycentric[corner] = 1;
      c.normal = Vec3::UnitZ();
      stencils.push_back(make_stencil(c, faces));
    }
  }
  std::vector<Vec3> x1 = x, v1 = v;
  const ResponseStats one = resolve(stencils, inv_mass, x1, v1, {.thickness = h, .passes = 1});
  EXPECT_FALSE(one.converged);
  const ResponseStats many = resolve(stencils, inv_mass, x, v, {.thickness = h, .passes = 500});
  EXPECT_TRUE(many.converged) << many.passes << " passes";
  EXPECT_GT(many.passes, 2);
  for (const Stencil& s : stencils) {
    EXPECT_GE(relative_normal(s, v), -1e-9);
    EXPECT_GE(relative_normal(s, x), h * (1 - 1e-6));
  }
  for (int k = 1; k < layers; ++k) EXPECT_NEAR(v[static_cast<std::size_t>(3 * k)].z(), 0, 1e-8);
}

// The contacts' share of a projective local step: a vertex 0.5 h above a held face gets a force
// along the normal that grows while the pair stays closer than h, shrinks once it is farther
// and is gone when it has separated; a held vertex (diagonal 0) takes none, and with both sides
// free the forces sum to zero.
TEST(ContactForces, GrowWhileClosePushApartAndReleaseWhenFar) {
  const Scalar h = 0.1;
  std::vector<Vec3> x{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.25, 0.25, 0.5 * h)};
  const std::vector<Stencil> stencils{vertex_face_stencil(3, {0, 1, 2}, Vec3(0.5, 0.25, 0.25), Vec3::UnitZ())};
  ContactForceOptions options;
  options.thickness = h;
  options.relaxation = 0.5;
  std::vector<Scalar> lambda(1, 0);
  // The global step's response: each vertex by its force over its diagonal, times `spread`
  // (a patch moving as one goes farther than its diagonal says).
  Scalar spread = 1;
  ContactForceScratch scratch;  // reused by every update, as the simulation does
  const auto update = [&](std::span<const Scalar> diagonal) {
    std::vector<Vec3> force(x.size(), Vec3::Zero());
    const auto solve = [&](std::span<const Vec3> f, std::span<Vec3> moved) {
      for (std::size_t i = 0; i < f.size(); ++i) moved[i] = diagonal[i] > 0 ? Vec3((spread / diagonal[i]) * f[i]) : Vec3::Zero();
    };
    update_contact_forces(stencils, x, diagonal, solve, options, lambda, force, scratch);
    return force;
  };
  const std::vector<Scalar> held{0, 0, 0, 200};
  std::vector<Vec3> f = update(held);
  // λ = ω (h − g) / (1² · 1 / D) = 0.5 · 0.05 · 200.
  EXPECT_NEAR(lambda[0], 5, 1e-12);
  EXPECT_EQ(f[3], lambda[0] * Vec3::UnitZ());
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(f[i], Vec3::Zero()) << "held vertex " << i;
  f = update(held);
  EXPECT_NEAR(lambda[0], 10, 1e-12) << "still 0.5 h apart: the force grows";
  x[3].z() = 1.5 * h;
  f = update(held);
  EXPECT_NEAR(lambda[0], 5, 1e-12) << "farther than h: it shrinks";
  f = update(held);
  EXPECT_EQ(lambda[0], 0) << "clamped at 0";
  EXPECT_EQ(f[3], Vec3::Zero());
  f = update(held);
  EXPECT_EQ(lambda[0], 0) << "a separated pair with no force does not act";
  // Both sides free: equal and opposite forces, shared over the face by its weights.
  x[3].z() = 0.5 * h;
  f = update(std::vector<Scalar>{100, 100, 100, 100});
  EXPECT_GT(lambda[0], 0);
  Vec3 sum = Vec3::Zero();
  for (const Vec3& fi : f) sum += fi;
  EXPECT_LT(sum.norm(), 1e-12 * lambda[0]);
  EXPECT_NEAR(f[0].z(), -0.5 * lambda[0], 1e-12);
  // A response 10 times what the diagonal says: the change is scaled to what the pair asked.
  lambda[0] = 0;
  spread = 10;
  update(held);
  EXPECT_NEAR(lambda[0], 0.5, 1e-12) << "a tenth of the diagonal's 5";
  spread = 0.5;
  update(held);
  EXPECT_NEAR(lambda[0], 5.5, 1e-12) << "a response below the estimate is not scaled up";
}

}  // namespace
}  // namespace crumple::response

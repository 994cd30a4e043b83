// Proximity impulses with friction (`resolve_proximity`).
#include <crumple/response/contact_response.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

namespace crumple::response {
namespace {

/// Vertex 3 above the triangle (0, 1, 2) in z = 0, at height `gap`, moving with `velocity`.
struct VertexOverFace {
  std::vector<Vec3> x{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.25, 0.25, 0)};
  std::vector<Vec3> v{Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};
  std::vector<Scalar> inv_mass{1, 1, 1, 1};
  Stencil stencil;
  VertexOverFace(Scalar gap, const Vec3& velocity) {
    x[3].z() = gap;
    v[3] = velocity;
    stencil.count = 4;
    stencil.vertex = {3, 0, 1, 2};
    stencil.weight = {1, -0.5, -0.25, -0.25};
    stencil.normal = Vec3::UnitZ();
  }
  Vec3 momentum() const { return v[0] + v[1] + v[2] + v[3]; }
  Vec3 relative() const { return v[3] - 0.5 * v[0] - 0.25 * v[1] - 0.25 * v[2]; }
};

TEST(Proximity, PushesOutStopsApproachAndAppliesCoulombFriction) {
  const Scalar h = 0.1;
  VertexOverFace c(0.04, Vec3(1, 0, -2));
  ProximityOptions options;
  options.thickness = h;
  options.friction = 0.2;
  const Vec3 p0 = c.momentum();
  const ResponseStats stats = resolve_proximity(std::span<const Stencil>(&c.stencil, 1), c.inv_mass, c.x, c.v, options);
  EXPECT_TRUE(stats.converged);
  EXPECT_NEAR(relative_normal(c.stencil, c.x), h, 1e-12) << "pushed out to the thickness";
  const Vec3 r = c.relative();
  EXPECT_NEAR(r.z(), 0, 1e-12) << "no approaching normal velocity left";
  // λ = 2 / d, λ_t = μ λ: the relative tangential speed drops by μ λ d = μ · 2 = 0.4.
  EXPECT_NEAR(r.x(), 1 - 0.2 * 2, 1e-12);
  EXPECT_NEAR(r.y(), 0, 1e-12);
  EXPECT_NEAR((c.momentum() - p0).norm(), 0, 1e-12) << "momentum is conserved";
}

TEST(Proximity, FrictionStopsSlowSlidingWithoutReversingIt) {
  VertexOverFace c(0.04, Vec3(0.1, 0, -2));
  ProximityOptions options;
  options.thickness = 0.1;
  options.friction = 0.5;
  resolve_proximity(std::span<const Stencil>(&c.stencil, 1), c.inv_mass, c.x, c.v, options);
  EXPECT_NEAR(c.relative().x(), 0, 1e-12);
}

TEST(Proximity, PairsFartherThanTheThicknessAreLeftAlone) {
  VertexOverFace c(0.2, Vec3(1, 0, -2));
  const auto x = c.x, v = c.v;
  ProximityOptions options;
  options.thickness = 0.1;
  options.friction = 0.5;
  const ResponseStats stats = resolve_proximity(std::span<const Stencil>(&c.stencil, 1), c.inv_mass, c.x, c.v, options);
  EXPECT_EQ(stats.corrections, 0u);
  EXPECT_EQ(c.x, x);
  EXPECT_EQ(c.v, v);
}

TEST(Proximity, RefreshKeepsTheSideACrossedPairCameFrom) {
  VertexOverFace c(-0.03, Vec3::Zero());  // the vertex went through the face
  c.x[3].x() = 0.5;
  refresh_stencil(c.stencil, c.x);
  EXPECT_EQ(c.stencil.normal, Vec3::UnitZ()) << "still the side it came from";
  EXPECT_NEAR(c.stencil.weight[1], -0.25, 1e-12);  // closest point (0.5, 0.25): w = (0.25, 0.5, 0.25)
  EXPECT_NEAR(c.stencil.weight[2], -0.5, 1e-12);
  EXPECT_NEAR(relative_normal(c.stencil, c.x), -0.03, 1e-12);
}

// `refresh_stencils` refreshes in blocks (a block's closest points, then its normals): the same
// bits as `refresh_stencil` stencil by stencil, over several blocks and a partial one, for EE
// and VF pairs apart (normals turned to either side) and touching (normals kept).
TEST(Proximity, BlockRefreshGivesTheBitsOfEachStencilsRefresh) {
  std::mt19937 random(7);
  std::uniform_real_distribution<Scalar> coordinate(-1, 1);
  constexpr int kStencils = 100;
  std::vector<Vec3> x(4 * kStencils);
  for (Vec3& p : x) p = Vec3(coordinate(random), coordinate(random), coordinate(random));
  std::vector<Stencil> stencils(kStencils);
  for (int i = 0; i < kStencils; ++i) {
    Stencil& s = stencils[static_cast<std::size_t>(i)];
    s.count = 4;
    s.vertex = {4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3};
    s.edge_edge = i % 3 != 0;
    s.normal = Vec3(coordinate(random), coordinate(random), coordinate(random)).normalized();
    const auto p = [&](int k) -> Vec3& { return x[static_cast<std::size_t>(4 * i + k)]; };
    if (i % 7 == 3) {  // touching: the vertex on its face, or the edges crossing
      if (s.edge_edge) {
        const Vec3 middle = 0.5 * (p(0) + p(1)), u = p(3) - p(2);
        p(2) = middle - 0.5 * u;
        p(3) = middle + 0.5 * u;
      } else {
        p(0) = (p(1) + p(2) + p(3)) / 3;
      }
    }
  }
  const std::vector<Stencil> before = stencils;
  std::vector<Stencil> each = stencils;
  for (Stencil& s : each) refresh_stencil(s, x);
  refresh_stencils(stencils, x);
  int kept = 0, turned = 0;
  for (std::size_t i = 0; i < stencils.size(); ++i) {
    EXPECT_EQ(std::memcmp(stencils[i].weight.data(), each[i].weight.data(), sizeof(Scalar) * 4), 0) << "stencil " << i;
    EXPECT_EQ(std::memcmp(stencils[i].normal.data(), each[i].normal.data(), sizeof(Scalar) * 3), 0) << "stencil " << i;
    kept += each[i].normal == before[i].normal ? 1 : 0;
    turned += each[i].normal.dot(before[i].normal) >= 0 && each[i].normal != before[i].normal ? 1 : 0;
  }
  EXPECT_GE(kept, kStencils / 7) << "the touching pairs keep their normals";
  EXPECT_GT(turned, kStencils / 2) << "the others take their closest points' direction";
}

// A vertex that lands on its face (the squeezed pile's steps carry vertices onto the layer
// below): the closest points then differ by rounding noise, whose direction may lie in the
// face's plane. The stencil keeps its normal, and the push-out lifts the vertex back to h
// along it, never sideways. Landing points over a grid of the face (z = 0 and a few ulps off).
TEST(Proximity, AVertexLandingOnItsFaceKeepsItsNormal) {
  const Scalar h = 0.01;
  for (int i = 1; i < 20; ++i) {
    for (int j = 1; i + j < 20; ++j) {
      for (const Scalar z : {0.0, 1e-18, -1e-18, 1e-12}) {
        VertexOverFace c(0, Vec3::Zero());
        c.x = {Vec3(0.3, 0.1, 0.2), Vec3(0.4, 0.1, 0.2), Vec3(0.3, 0.2, 0.2), Vec3::Zero()};
        c.x[3] = Vec3(0.3 + 0.005 * i, 0.1 + 0.005 * j, 0.2 + z);
        refresh_stencil(c.stencil, c.x);
        EXPECT_EQ(c.stencil.normal, Vec3::UnitZ()) << "landing point " << i << ", " << j << ", z " << z;
        ProximityOptions options;
        options.thickness = h;
        resolve_proximity(std::span<const Stencil>(&c.stencil, 1), c.inv_mass, c.x, c.v, options);
        const Scalar lifted = c.x[3].z() - (c.x[0].z() + c.x[1].z() + c.x[2].z()) / 3;
        EXPECT_GT(lifted, 0.5 * h) << "landing point " << i << ", " << j << ", z " << z;
      }
    }
  }
}

}  // namespace
}  // namespace crumple::response

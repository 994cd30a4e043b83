// The simulation loop: collision share, determinism, obstacles, self-collision response.
#include <crumple/sim/scene.hpp>

#include <gtest/gtest.h>

#include <cstdio>

namespace crumple::sim {
namespace {

Simulation make_simulation(const std::string& spec, std::uint64_t seed = 1,
                           std::optional<bool> response = std::nullopt) {
  Scene s = make_scene(SceneSpec::parse(spec), seed);
  Settings settings = s.settings;
  settings.detector.threads = 1;
  if (response) settings.response = *response;
  return Simulation(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles),
                    std::move(s.kinematics), settings);
}

TEST(Simulation, CollisionShareCountsEdgesOfContactPrimitives) {
  const TriMesh mesh = TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(1, 1, 0),
                                        Vec3(5, 5, 5), Vec3(6, 5, 5), Vec3(5, 6, 5)},
                                       {{0, 1, 2}, {2, 1, 3}, {4, 5, 6}});
  const Topology& topo = mesh.topology();  // 8 edges
  ContactSet contacts;
  EXPECT_EQ(collision_share(topo, contacts), 0);
  VertexFaceContact vf;
  vf.vertex = 0;
  vf.face = 2;
  contacts.vf.push_back(vf);  // the 3 sides of face 2
  EXPECT_DOUBLE_EQ(collision_share(topo, contacts), 3.0 / 8);
  EdgeEdgeContact ee;
  ee.edge0 = 0;
  ee.edge1 = topo.face_edges(2)[0];
  contacts.ee.push_back(ee);  // adds edge 0 only
  EXPECT_DOUBLE_EQ(collision_share(topo, contacts), 4.0 / 8);
}

TEST(Simulation, DeterministicAndFramesAdvanceTime) {
  Simulation a = make_simulation("hanging-cloth:nx=6,ny=6"), b = make_simulation("hanging-cloth:nx=6,ny=6");
  for (int i = 0; i < 20; ++i) {
    const FrameStats sa = a.advance_frame(), sb = b.advance_frame();
    EXPECT_EQ(sa.vf, sb.vf);
    EXPECT_EQ(sa.ee, sb.ee);
    EXPECT_EQ(sa.frame, i + 1);
  }
  EXPECT_EQ(a.state().x, b.state().x);
  EXPECT_EQ(a.state().v, b.state().v);
  EXPECT_NEAR(a.state().time, 20 * a.settings().substeps * a.settings().dt, 1e-12);
  EXPECT_EQ(a.state().x[0], Vec3::Zero()) << "the pinned corner stays";
}

/// cloth-on-sphere with response on (small): no vertex ends inside the sphere or the floor,
/// and close pairs (< h/2) are rare.
TEST(Simulation, ClothOnSphereStaysOutsideAndApart) {
  Simulation sim = make_simulation("cloth-on-sphere:n=6");
  ASSERT_TRUE(sim.settings().response);
  const Scalar h = sim.settings().detector.thickness;
  int close = 0, frames = 0;
  std::size_t contacts = 0;
  for (int i = 0; i < 60; ++i) {
    const FrameStats s = sim.advance_frame();
    ++frames;
    EXPECT_LE(s.obstacle_penetration, 1e-12) << "frame " << s.frame;
    close += s.min_distance < 0.5 * h;
    contacts += s.vf + s.ee;
  }
  for (const Vec3& p : sim.state().x) {
    const auto q = response::query(std::get<response::Sphere>(sim.obstacles()[0].shape), p);
    EXPECT_GE(q.distance, 0);
  }
  std::printf("cloth-on-sphere n=6: %d of %d frames with a pair < h/2, %zu contacts seen\n", close, frames, contacts);
  EXPECT_LE(close, frames / 100);
}

/// The pile: response on keeps layers apart much better than response off.
TEST(Simulation, ResponseKeepsTheCrumplePileApart) {
  const std::string spec = "crumple:n=6,push-time=0.7";
  int close_on = 0, close_off = 0;
  std::size_t contacts_on = 0;
  Simulation on = make_simulation(spec, 1, true), off = make_simulation(spec, 1, false);
  const Scalar h = on.settings().detector.thickness;
  for (int i = 0; i < 60; ++i) {
    const FrameStats a = on.advance_frame(), b = off.advance_frame();
    close_on += a.min_distance < 0.5 * h;
    close_off += b.min_distance < 0.5 * h;
    contacts_on += a.vf + a.ee;
    EXPECT_LE(a.obstacle_penetration, 1e-12);
  }
  std::printf("crumple n=6: frames with a pair < h/2: %d with response, %d without (%zu contacts)\n", close_on,
              close_off, contacts_on);
  EXPECT_GT(contacts_on, 0u) << "the pile makes self-contacts";
  EXPECT_GT(close_off, 5);
  EXPECT_LE(close_on, 2);
}

TEST(Simulation, RibbonEndFollowsTheTwist) {
  Simulation sim = make_simulation("twisted-ribbon:nx=12,ny=2,turns=1,twist-time=1,approach=0");
  const Index driven = 12;  // lattice vertex (nx, 0)
  const Vec3 start = sim.state().x[static_cast<std::size_t>(driven)];
  const Vec3 fixed = sim.state().x[0];
  for (int i = 0; i < 15; ++i) sim.advance_frame();  // t = 0.25 s: a quarter turn
  const Vec3 axis_point(2, 1, 0.075);
  const Vec3 r0 = start - axis_point;
  const Vec3 r = sim.state().x[static_cast<std::size_t>(driven)] - axis_point;
  EXPECT_NEAR(r.x(), r0.x(), 1e-12);
  EXPECT_NEAR(r.y(), -r0.z(), 1e-9) << "rotated by +90 degrees about x";
  EXPECT_NEAR(r.z(), r0.y(), 1e-9);
  EXPECT_EQ(sim.state().x[0], fixed);
}

}  // namespace
}  // namespace crumple::sim

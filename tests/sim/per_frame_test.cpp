// Detection once per frame (ResponseModel::Proximity) and the end-of-frame fail-safe hook.
#include <crumple/sim/scene.hpp>

#include <gtest/gtest.h>

namespace crumple::sim {
namespace {

Simulation make(const std::string& spec, ResponseModel model) {
  Scene s = make_scene(SceneSpec::parse(spec), 1);
  Settings settings = s.settings;
  settings.detector.threads = 1;
  settings.response_model = model;
  return Simulation(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles), std::move(s.kinematics),
                    settings);
}

TEST(PerFrame, ProximityDetectsOncePerFrameAnnexBOncePerStep) {
  Simulation once = make("cloth-on-sphere:n=8", ResponseModel::Proximity);
  Simulation every = make("cloth-on-sphere:n=8", ResponseModel::AnnexB);
  ASSERT_EQ(once.settings().substeps, 4);
  once.current_stats();  // detects frame 0, as `crumple simulate` does
  every.current_stats();
  std::size_t contacts = 0;
  for (int f = 0; f < 40; ++f) {
    const FrameStats a = once.advance_frame();
    EXPECT_EQ(a.detections, 1) << "frame " << f;
    EXPECT_EQ(every.advance_frame().detections, 4) << "frame " << f;
    contacts += a.vf + a.ee;
    EXPECT_LE(a.obstacle_penetration, 1e-12);
  }
  EXPECT_GT(contacts, 0u) << "the frames compared have self-contacts";
  // The statistics count only the contacts closer than the thickness.
  for (const auto& c : once.contacts().vf) EXPECT_LT(c.distance, once.settings().detector.thickness);
  for (const auto& c : once.contacts().ee) EXPECT_LT(c.distance, once.settings().detector.thickness);
}

TEST(PerFrame, FailSafeSeesEachFrameStartOnce) {
  Simulation sim = make("cloth-on-sphere:n=6", ResponseModel::Proximity);
  int calls = 0;
  Positions expected_start = sim.state().x;
  bool starts_match = true;
  sim.set_fail_safe([&](PositionsView start, State& state) {
    ++calls;
    starts_match &= Positions(start.begin(), start.end()) == expected_start;
    EXPECT_EQ(state.x.size(), start.size());
  });
  for (int f = 0; f < 5; ++f) {
    sim.advance_frame();
    expected_start = sim.state().x;
  }
  EXPECT_EQ(calls, 5);
  EXPECT_TRUE(starts_match);
}

}  // namespace
}  // namespace crumple::sim

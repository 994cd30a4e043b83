// Untangling in the simulation: a hanging cloth left to fall through itself with the response
// off, then simulated with the response on, reaches 0 intersecting triangle pairs with the
// untangler and keeps its intersections without it.
#include <crumple/sim/scene.hpp>

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <string>

namespace crumple::sim {
namespace {

/// Intersecting triangle pairs (faces sharing no vertex) at `x`, by the exact kdop detector.
std::size_t intersecting_pairs(std::shared_ptr<const Topology> topology, PositionsView x) {
  DetectorOptions options;
  options.kinds = ContactKinds::parse("tt");
  options.threads = 1;
  auto detector = make_detector(MethodSpec::parse("kdop"), options);
  detector->set_topology(std::move(topology));
  ContactSet contacts;
  detector->update(x, contacts);
  return contacts.tt.size();
}

struct Untangled {
  std::size_t tangled_pairs = 0;  ///< at the frame the response starts
  int frames_to_clean = -1;       ///< frames with the response on until 0 pairs (-1: never)
  std::size_t last_pairs = 0;
};

/// `spec` simulated `off_frames` frames with the response off, then up to `on_frames` with it on.
Untangled run(const std::string& spec, int off_frames, int on_frames, bool untangle, bool verbose = false) {
  Scene s = make_scene(SceneSpec::parse(spec), 1);
  Settings off = s.settings;
  off.response = false;
  off.detector.threads = 1;
  Simulation first(s.model, s.state, s.field, s.obstacles, s.kinematics, off);
  for (int f = 0; f < off_frames; ++f) first.advance_frame();
  Settings on = off;
  on.response = true;
  on.untangle = untangle;
  Simulation sim(first.model(), first.state(), first.field(), first.obstacles(), s.kinematics, on, first.frame());
  Untangled r;
  r.tangled_pairs = intersecting_pairs(sim.model().topology_ptr(), sim.state().x);
  for (int f = 1; f <= on_frames; ++f) {
    const FrameStats st = sim.advance_frame();
    r.last_pairs = intersecting_pairs(sim.model().topology_ptr(), sim.state().x);
    if (verbose) {
      std::printf("frame %d pairs %zu reported %lld contours %zu pulls %zu\n", f, r.last_pairs,
                  static_cast<long long>(st.intersecting_pairs), st.contours, st.untangle_pulls);
    }
    if (r.last_pairs == 0 && r.frames_to_clean < 0) r.frames_to_clean = f;
    if (r.frames_to_clean > 0) break;
  }
  return r;
}

TEST(Untangle, Explore) {
  const char* spec = std::getenv("UNTANGLE_SPEC");
  if (!spec) GTEST_SKIP();
  const int off = std::atoi(std::getenv("UNTANGLE_OFF"));
  const int on = std::atoi(std::getenv("UNTANGLE_ON"));
  const bool untangle = std::getenv("UNTANGLE_NO") == nullptr;
  const Untangled r = run(spec, off, on, untangle, true);
  std::printf("tangled %zu -> frames to clean %d, last %zu\n", r.tangled_pairs, r.frames_to_clean, r.last_pairs);
}

}  // namespace
}  // namespace crumple::sim

// Detection once per frame (ResponseModel::Proximity), its motion search and the end-of-frame
// fail-safe hook.
#include <crumple/detect/continuous.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/response/contact_response.hpp>
#include <crumple/sim/scene.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

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

/// Two triangles, no gravity, no springs, thickness h = 1 cm: A (z = 0) at rest, B a smaller one
/// above A's interior at z = 3.5 h moving by `fall` (× h) along −z in the frame of 1/60 s, and
/// both moving by `drift` along x. The detection radius is 2 h, so at the frame's start the
/// detection sees nothing.
struct TwoTriangles {
  static constexpr Scalar h = 0.01;
  Model model = Model::create({0.01, 0.01, 0.01, 0.01, 0.01, 0.01}, {}, {{0, 1, 2}, {3, 4, 5}});
  State state;
  Settings settings;
  TwoTriangles(Scalar fall, Scalar drift, bool motion_search) {
    state.x = {Vec3(0, 0, 0), Vec3(0.1, 0, 0), Vec3(0, 0.1, 0),
               Vec3(0.02, 0.02, 3.5 * h), Vec3(0.05, 0.02, 3.5 * h), Vec3(0.02, 0.05, 3.5 * h)};
    state.v.assign(6, Vec3(drift * h * 60, 0, 0));
    for (std::size_t i = 3; i < 6; ++i) state.v[i].z() = -fall * h * 60;
    settings.dt = 1.0 / 240;
    settings.substeps = 4;
    settings.integrator = IntegratorKind::SymplecticEuler;
    settings.detector.thickness = h;
    settings.detector.threads = 1;
    settings.response = true;
    settings.response_model = ResponseModel::Proximity;
    settings.untangle = false;
    settings.motion_search = motion_search;
  }
  Simulation make(bool built_in_fail_safe = true) const {
    Settings s = settings;
    s.fail_safe = built_in_fail_safe;
    ForceField field;
    field.gravity = Vec3::Zero();
    return Simulation(model, state, field, {}, {}, s);
  }
};

/// The impacts (within δ = 0.1 h) of the frame's proposed motion, the fail-safe's input, counted
/// by the exact continuous query on a twin run whose fail-safe hook only records that motion.
std::size_t exact_impacts(const TwoTriangles& scene) {
  Simulation twin = scene.make(false);
  ImpactSet impacts;
  twin.set_fail_safe([&](PositionsView start, State& state) {
    ContinuousOptions options;
    options.min_separation = 0.1 * TwoTriangles::h;
    options.threads = 1;
    impacts = continuous_impacts(twin.model().topology_ptr(), start, state.x, options);
  });
  twin.advance_frame();
  for (const auto& i : impacts.vf) EXPECT_GT(i.toi, 0) << "apart at the start: every impact is live";
  for (const auto& i : impacts.ee) EXPECT_GT(i.toi, 0) << "apart at the start: every impact is live";
  return impacts.size();
}

// B falls 8 h through A within one frame. Without the motion search the detection (radius 2 h)
// misses the pair, the steps carry B through A and the fail-safe finds B's three corners
// against A; with it, the predicted motion puts the three pairs among the frame's contacts, the
// proximity impulses stop B at h above A and the fail-safe finds nothing.
TEST(PerFrame, MotionSearchCatchesAFastPairInTheProximityStage) {
  for (const bool search : {false, true}) {
    SCOPED_TRACE(search ? "motion search on" : "motion search off");
    const TwoTriangles scene(8, 0, search);
    const std::size_t exact = exact_impacts(scene);
    Simulation sim = scene.make();
    const FrameStats st = sim.advance_frame();
    EXPECT_EQ(st.ccd_impacts, exact) << "the fail-safe's live impacts are the exact count";
    EXPECT_EQ(exact, search ? 0u : 3u);
    EXPECT_EQ(st.motion_pairs, search ? 3u : 0u) << "B's corners against A";
    EXPECT_EQ(st.motion_vertices, search ? 6u : 0u);
    EXPECT_EQ(st.ccd_frozen, 0u);
    const Positions& x = sim.state().x;
    const Vec3 up = (x[1] - x[0]).cross(x[2] - x[0]).normalized();
    for (std::size_t i = 3; i < 6; ++i) {
      EXPECT_GT((x[i] - x[0]).dot(up), 0) << "B stays above A, vertex " << i;
      if (search) {
        const Scalar d = std::sqrt(geometry::point_triangle(x[i], x[0], x[1], x[2]).sqr_distance);
        EXPECT_GT(d, 0.99 * TwoTriangles::h) << "the impulses hold B at h from A, vertex " << i;
      }
    }
  }
}

// The same pair moving together (no relative motion) or closing in slowly has no fast vertex:
// the detection's radius covers it, and the search queries nothing.
TEST(PerFrame, MotionSearchSkipsMotionTheRadiusCovers) {
  const TwoTriangles drifting(0, 8, true);
  Simulation sim = drifting.make();
  FrameStats st = sim.advance_frame();
  EXPECT_EQ(st.motion_vertices, 0u) << "a uniform motion is no relative motion";
  EXPECT_EQ(st.motion_pairs, 0u);
  const TwoTriangles slow(0.5, 0, true);  // 0.25 h each way from the mean: below (2h - h) / 2
  Simulation slow_sim = slow.make();
  st = slow_sim.advance_frame();
  EXPECT_EQ(st.motion_vertices, 0u);
  EXPECT_EQ(st.ccd_impacts, 0u);
}

// The pile at n = 200's edge (5 mm: 16 quads on 8 cm) searches 4 thicknesses, 1.2 edges: the flat
// cloth's own neighbours fall within it. Flat neighbours keep 2 h_c (`flat_neighbour_rings`): the
// frame's proximity impulses serve the other pairs only (the cloth's crease over the ridge, a
// sharp one at this edge, keeps its pairs), and the motion of the lying cloth is the same, bit
// for bit, as with every pair served (none of the pairs left out comes within h_c).
// A vertex squeezed between two held layers 0.6 h apart (no room for the two gaps h it wants):
// its two pairs conflict. Full pushes (ω = 1) alternate between the ends, each moving the
// vertex by a whole violation, and the last one wins: after the sweeps it lies 0.4 h past the
// lower layer, and the next sweep would put it back 1.4 h up — the exchange the springs of the
// `crumple` pile stored at every step. The scene's half pushes settle between the layers.
TEST(PerFrame, CrumplePushesASqueezedVertexWithoutPassingEitherLayer) {
  const Scalar h = 0.1;
  const Scene scene = make_scene(SceneSpec::parse("crumple:n=4"), 1);
  ASSERT_EQ(scene.settings.response_model, ResponseModel::Proximity);
  // The squeezed vertex's height after the scene's sweeps with relaxation ω.
  const auto squeeze = [&](Scalar omega) {
    // Faces A (0, 1, 2) at z = 0 and B (3, 4, 5) at z = 0.6 h, held; vertex 6 between them.
    std::vector<Vec3> x{Vec3(0, 0, 0),       Vec3(1, 0, 0),       Vec3(0, 1, 0),          Vec3(0, 0, 0.6 * h),
                        Vec3(1, 0, 0.6 * h), Vec3(0, 1, 0.6 * h), Vec3(0.25, 0.25, 0.3 * h)};
    std::vector<Vec3> v(x.size(), Vec3::Zero());
    const std::vector<Scalar> inv_mass{0, 0, 0, 0, 0, 0, 1};
    const Vec3 w(0.5, 0.25, 0.25);
    const std::vector<response::Stencil> stencils{response::vertex_face_stencil(6, {0, 1, 2}, w, Vec3::UnitZ()),
                                                  response::vertex_face_stencil(6, {3, 4, 5}, w, -Vec3::UnitZ())};
    response::ProximityOptions options;
    options.thickness = h;
    options.passes = scene.settings.passes;
    options.relaxation = omega;
    response::resolve_proximity(stencils, inv_mass, x, v, options);
    return x[6].z();
  };
  EXPECT_NEAR(squeeze(1), -0.4 * h, 1e-12) << "full pushes: the last one wins, past layer A";
  const Scalar z = squeeze(scene.settings.proximity_relaxation);
  EXPECT_GT(z, 0.05 * h) << "above layer A";
  EXPECT_LT(z, 0.55 * h) << "below layer B";
}

TEST(PerFrame, FlatNeighboursKeepTwoThicknesses) {
  const auto run = [](const std::string& spec, int rings) {
    Scene s = make_scene(SceneSpec::parse(spec), 1);
    s.settings.detector.threads = 1;
    s.settings.flat_neighbour_rings = rings;
    Simulation sim(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles), std::move(s.kinematics),
                   s.settings);
    std::vector<FrameStats> frames;
    for (int f = 0; f < 4; ++f) frames.push_back(sim.advance_frame());
    return std::make_pair(frames, sim.state().x);
  };
  for (const std::string fine : {"crumple:n=16,size=0.08", "crumple:n=16,size=0.08,ridge=0"}) {
    ASSERT_GT(make_scene(SceneSpec::parse(fine), 1).settings.search_factor, 3.9);
    const auto [left_out, x] = run(fine, 2);
    const auto [all, x_all] = run(fine, 0);
    const auto [two, x_two] = run(fine + ",search=0", 2);  // 2 h_c: nothing to leave out
    EXPECT_EQ(x, x_all) << fine << ": the pairs left out never came within h_c";
    EXPECT_EQ(x, x_two) << fine;
    for (std::size_t f = 0; f < left_out.size(); ++f) {
      EXPECT_EQ(all[f].flat_pairs, 0u);
      EXPECT_EQ(two[f].flat_pairs, 0u);
      EXPECT_EQ(left_out[f].flat_pairs + left_out[f].proximity_pairs, all[f].proximity_pairs);
      EXPECT_LT(5 * left_out[f].proximity_pairs, all[f].proximity_pairs) << fine << ", frame " << f;
      if (fine.ends_with("ridge=0")) {
        EXPECT_LE(left_out[f].proximity_pairs, two[f].proximity_pairs) << "flat: as few as 2 h_c finds";
      }
    }
  }
}

/// A pinned at z = 0, B at rest 3.5 h above it, pulled down by a field of 576 m/s² that carries
/// it 8 h in the frame: the motion a stretched spring releases from rest (the squeezed pile's
/// case, docs/simulation.md "Energy under contact"), which the predicted motion x + H v, with
/// v = 0, does not see.
TwoTriangles pulled(bool motion_search, int retries) {
  TwoTriangles scene(0, 0, motion_search);
  scene.model = Model::create({0, 0, 0, 0.01, 0.01, 0.01}, {}, {{0, 1, 2}, {3, 4, 5}});
  scene.settings.motion_retries = retries;
  return scene;
}

Simulation make_pulled(const TwoTriangles& scene) {
  ForceField field;
  field.gravity = Vec3(0, 0, -576);
  return Simulation(scene.model, scene.state, field, {}, {}, scene.settings);
}

// Without a retry the steps carry B through A and the fail-safe stops B's three corners at the
// frame's end (the motion search too: it predicts no motion from rest); with one, the frame's
// own motion puts the three pairs among its contacts, the frame runs again, the proximity
// impulses hold B at h above A at every step and the fail-safe finds nothing.
TEST(PerFrame, MotionRetryCatchesAPairThePredictionMisses) {
  for (const bool search : {false, true}) {
    for (const int retries : {0, 1, 2}) {
      SCOPED_TRACE(std::string(search ? "motion search on" : "motion search off") + ", retries " +
                   std::to_string(retries));
      Simulation sim = make_pulled(pulled(search, retries));
      const FrameStats st = sim.advance_frame();
      EXPECT_EQ(st.ccd_impacts, retries > 0 ? 0u : 3u);
      EXPECT_EQ(st.retries, retries > 0 ? 1 : 0) << "the second run finds no new pair";
      EXPECT_EQ(st.motion_pairs, retries > 0 ? 3u : 0u) << "B's corners against A";
      EXPECT_EQ(st.motion_vertices, 0u) << "the prediction from rest moves nothing";
      const Positions& x = sim.state().x;
      for (std::size_t i = 3; i < 6; ++i) {
        EXPECT_GT(x[i].z(), 0) << "B stays above A, vertex " << i;
        if (retries > 0) {
          EXPECT_GT(x[i].z(), 0.99 * TwoTriangles::h) << "held at h from A, vertex " << i;
          EXPECT_GE(sim.state().v[i].z(), -1e-9) << "no approaching velocity left, vertex " << i;
        }
      }
    }
  }
}

// B thrown at 8 h a frame onto a free triangle A, which lies 2.5 h above a pinned one C (both
// gaps beyond the radius of 2 h; no motion search, so nothing predicts B): the first run carries
// B through A, and its retry has B hit A, which then moves into C, a pair that only the rerun's
// motion brings. With one retry the fail-safe stops A against C at the frame's end; with two
// (the `crumple` scene's count) the frame runs a third time with A–C among its contacts, A stays
// about h above C and the fail-safe finds nothing.
TEST(PerFrame, SecondRetryCatchesAPairTheFirstRerunBrings) {
  const auto run = [](int retries) {
    TwoTriangles scene(0, 0, false);
    const Scalar h = TwoTriangles::h;
    scene.model = Model::create({0.01, 0.01, 0.01, 0.01, 0.01, 0.01, 0, 0, 0}, {},
                                {{0, 1, 2}, {3, 4, 5}, {6, 7, 8}});
    scene.state.x.push_back(Vec3(-0.05, -0.05, -2.5 * h));
    scene.state.x.push_back(Vec3(0.2, -0.05, -2.5 * h));
    scene.state.x.push_back(Vec3(-0.05, 0.2, -2.5 * h));
    scene.state.v.assign(9, Vec3::Zero());
    for (std::size_t i = 3; i < 6; ++i) scene.state.v[i].z() = -8 * h * 60;
    scene.settings.motion_retries = retries;
    Simulation sim = scene.make();
    const FrameStats st = sim.advance_frame();
    return std::make_pair(st, sim.state().x);
  };
  const auto [once, x_once] = run(1);
  const auto [twice, x] = run(2);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_GT(x[i].z(), -1.51 * TwoTriangles::h) << "A held about h above C, vertex " << i;
  }
  EXPECT_EQ(once.retries, 1);
  EXPECT_GT(once.ccd_impacts, 0u) << "A stopped against C by the fail-safe";
  EXPECT_EQ(twice.retries, 2);
  EXPECT_GT(twice.motion_pairs, once.motion_pairs) << "A against C joins the contacts";
  EXPECT_EQ(twice.ccd_impacts, 0u);
  EXPECT_EQ(make_scene(SceneSpec::parse("crumple:n=16"), 1).settings.motion_retries, 2);
  EXPECT_EQ(make_scene(SceneSpec::parse("crumple:n=100"), 1).settings.motion_retries, 2);
  EXPECT_EQ(make_scene(SceneSpec::parse("crumple:n=101"), 1).settings.motion_retries, 1)
      << "above n = 100 the count the n = 200 run was measured with";
}

// A frame whose motion the detection's radius covers (B falls under plain gravity, 1.4 mm a
// frame against a radius of 2 h) runs once, bit for bit as without retries.
TEST(PerFrame, MotionRetryLeavesACoveredFrameAlone) {
  ForceField field;
  field.gravity = Vec3(0, 0, -9.81);
  const TwoTriangles with = pulled(false, 1), without = pulled(false, 0);
  Simulation a(with.model, with.state, field, {}, {}, with.settings);
  Simulation b(without.model, without.state, field, {}, {}, without.settings);
  for (int f = 0; f < 3; ++f) {
    const FrameStats st = a.advance_frame();
    b.advance_frame();
    EXPECT_EQ(st.retries, 0);
    EXPECT_EQ(st.motion_pairs, 0u);
    EXPECT_EQ(a.state().x, b.state().x);
    EXPECT_EQ(a.state().v, b.state().v);
  }
}

// The scene key `contact-forces` has one rule in both scenes that have it: auto = on above
// n = 100 quads a side.
TEST(PerFrame, ScenesHaveContactForcesAboveOneHundredQuads) {
  const auto forces = [](const std::string& spec) {
    return make_scene(SceneSpec::parse(spec), 1).settings.contact_forces;
  };
  for (const std::string scene : {"crumple", "cloth-on-sphere"}) {
    SCOPED_TRACE(scene);
    EXPECT_FALSE(forces(scene + ":n=16"));
    EXPECT_FALSE(forces(scene + ":n=100"));
    EXPECT_TRUE(forces(scene + ":n=101"));
    EXPECT_TRUE(forces(scene + ":n=16,contact-forces=on"));
    EXPECT_FALSE(forces(scene + ":n=101,contact-forces=off"));
    EXPECT_TRUE(forces(scene + ":n=101,contact-forces=auto"));
    EXPECT_THROW(forces(scene + ":n=16,contact-forces=maybe"), InputError);
  }
}

// The scene of `spec`, whose key turns the contact forces on, on one thread with
// `Settings::contact_forces` = `forces`.
Simulation one_thread_simulation(const char* spec, bool forces) {
  Scene s = make_scene(SceneSpec::parse(spec), 1);
  EXPECT_TRUE(s.settings.contact_forces) << "the scene key";
  s.settings.detector.threads = 1;
  s.settings.contact_forces = forces;
  return Simulation(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles), std::move(s.kinematics),
                    s.settings);
}

// `cloth-on-sphere` runs its frames again (`Settings::motion_retries`) above n = 100 quads a
// side, as it turns its contact forces on; the key `motion-retries` sets the count at any size.
TEST(PerFrame, SphereRetriesItsFramesAboveOneHundredQuads) {
  const auto retries = [](const std::string& spec) {
    return make_scene(SceneSpec::parse("cloth-on-sphere:" + spec), 1).settings.motion_retries;
  };
  EXPECT_EQ(retries("n=16"), 0);
  EXPECT_EQ(retries("n=100"), 0);
  EXPECT_EQ(retries("n=101"), 1);
  EXPECT_EQ(retries("n=101,sweep-speed=5"), 1);
  EXPECT_EQ(retries("n=16,motion-retries=2"), 2);
  EXPECT_EQ(retries("n=101,motion-retries=0"), 0);
  EXPECT_EQ(retries("n=16,motion-retries=auto"), 0);
  EXPECT_THROW(retries("n=16,motion-retries=-1"), InputError);
  EXPECT_THROW(retries("n=16,motion-retries=once"), InputError);
}

// `twisted-ribbon` turns its contact forces and motion retries on above 100 quads along the
// ribbon and takes more steps a frame above 200 (the finer ribbons ran away once their coils
// touched; ContactForcesAndRetriesKeepAStiffRibbonCalm below); the 48 × 3 and 96 × 6 ribbons keep
// their bits. Its keys set them at any size.
TEST(PerFrame, RibbonTurnsItsContactCuresOnAboveOneHundredQuadsAlong) {
  const auto settings = [](const std::string& spec) {
    return make_scene(SceneSpec::parse("twisted-ribbon" + spec), 1).settings;
  };
  for (const std::string spec : {"", ":nx=96,ny=6", ":nx=100,ny=25"}) {
    SCOPED_TRACE(spec);
    EXPECT_FALSE(settings(spec).contact_forces);
    EXPECT_EQ(settings(spec).motion_retries, 0);
  }
  for (const std::string spec : {":nx=101", ":nx=400,ny=25"}) {
    SCOPED_TRACE(spec);
    EXPECT_TRUE(settings(spec).contact_forces);
    EXPECT_EQ(settings(spec).motion_retries, 3);
  }
  EXPECT_TRUE(settings(":contact-forces=on").contact_forces);
  EXPECT_FALSE(settings(":nx=400,ny=25,contact-forces=off").contact_forces);
  EXPECT_EQ(settings(":motion-retries=2").motion_retries, 2);
  EXPECT_EQ(settings(":nx=400,ny=25,motion-retries=0").motion_retries, 0);
  EXPECT_THROW(settings(":contact-forces=maybe"), InputError);
  EXPECT_THROW(settings(":motion-retries=-1"), InputError);
  // Steps a frame: 4 up to nx = 200, 4 more for each further 200 (the frame stays 1/60 s).
  for (const auto& [spec, steps] : {std::pair{"", 4}, std::pair{":nx=200,ny=12", 4}, std::pair{":nx=201", 8},
                                    std::pair{":nx=400,ny=25", 8}, std::pair{":nx=800,ny=50", 16},
                                    std::pair{":steps=6", 6}}) {
    SCOPED_TRACE(spec);
    const Settings s = settings(spec);
    EXPECT_EQ(s.substeps, steps);
    EXPECT_EQ(s.dt, 1.0 / (60 * steps));
  }
  EXPECT_EQ(settings("").dt, 1.0 / 240);  // the coarse ribbons' step, bit for bit
  EXPECT_THROW(settings(":steps=0"), InputError);
  EXPECT_THROW(settings(":steps=many"), InputError);
}

// The landing of `cloth-on-sphere` at n = 200's ωh, in small: `n=24` with the stiffness scaled
// by (200/24)², its contact forces on (as at n = 200), and a thickness of 0.1 edge, so that the
// skirt's folds falling onto the cloth on the floor (~3 m/s, 5 cm a frame) close in from
// farther than the search radius (1.25 cm) within a frame, as at n = 200 (1 cm). Left to the
// fail-safe, they are stopped at the frame's end against springs the steps did not see, and the
// next frames release that stretch: measured, 70 live impacts, 57 J and a spring 1.63x its rest
// length (frames 45-46). Run again with those pairs among its contacts, a frame answers them at every step:
// at most 14.9 J over frames 30-54 and no spring beyond 1.12x (the sphere's impact, frame 12;
// no live impact at all). Intersection-free both ways.
TEST(PerFrame, MotionRetriesKeepAStiffLandingCalm) {
  struct Landing {
    Scalar energy = 0, longest = 0;  // the most over frames 30-54
    std::size_t impacts = 0;         // the fail-safe's live impacts, summed
  };
  const auto land = [](int retries) {
    const std::string spec = "cloth-on-sphere:n=24,stretch=27778,thickness=0.1,height=0.6,contact-forces=on,"
                             "motion-retries=" + std::to_string(retries);
    Simulation sim = one_thread_simulation(spec.c_str(), true);
    Landing out;
    for (int f = 1; f <= 54; ++f) {
      const FrameStats st = sim.advance_frame();
      EXPECT_EQ(st.intersecting_pairs, 0) << "frame " << f << ", retries " << retries;
      out.impacts += st.ccd_impacts;
      if (f >= 30) {
        out.energy = std::max(out.energy, st.energy);
        out.longest = std::max(out.longest, st.longest_spring);
      }
    }
    return out;
  };
  const Landing with = land(1), without = land(0);
  EXPECT_GT(without.impacts, 30u) << "the fail-safe stops the folds";
  EXPECT_GT(without.longest, 1.4);
  EXPECT_GT(without.energy, 40) << "J";
  EXPECT_LT(with.impacts, 10u);
  EXPECT_LT(with.longest, 1.25);
  EXPECT_LT(with.energy, 20) << "J";
}

// The coiling ribbon at the ωh of `twisted-ribbon:nx=400,ny=25`, in small: 48 × 3 with the
// stiffness scaled by (400/48)² and a thickness of 0.03 edge (h_c = 1.5 mm, near 400 × 25's
// 1.9 mm), so that its coils close in from farther than the search radius (2 h_c) within a frame
// (~1 m/s, 1.7 cm a frame), as at 400 × 25. Measured: with the push-outs after the steps alone it
// runs away once the coils touch (11.5 J at frame 166, diverged at 210); with the contact forces
// alone the fail-safe's stops at the frames' ends start it (9 J at frame 157, diverged at 220);
// with one motion retry alone the push-outs' exchange with the springs does, later (6.7 J at
// frame 246, diverged at 281); with both it stays at most 0.15 J with springs at most 1.01x
// their rest length and one live impact in 300 frames. Intersection-free every way.
TEST(PerFrame, ContactForcesAndRetriesKeepAStiffRibbonCalm) {
  struct Run {
    Scalar energy = 0, longest = 0;  // the most over the frames run
    std::size_t impacts = 0;         // the fail-safe's live impacts, summed
    int frames = 0;                  // frames run: up to the first past 5 J, or a divergence
  };
  const auto run = [](bool forces, int retries, int frames) {
    Scene s = make_scene(SceneSpec::parse("twisted-ribbon:stretch=27778,thickness=0.03,contact-forces=" +
                                          std::string(forces ? "on" : "off") +
                                          ",motion-retries=" + std::to_string(retries)),
                         1);
    s.settings.detector.threads = s.settings.integrator_options.threads = 1;
    Simulation sim(std::move(s.model), std::move(s.state), s.field, std::move(s.obstacles), std::move(s.kinematics),
                   s.settings);
    Run out;
    for (int f = 1; f <= frames && out.energy <= 5; ++f) {
      FrameStats st;
      try {
        st = sim.advance_frame();
      } catch (const DivergenceError&) {
        out.energy = std::numeric_limits<Scalar>::infinity();
        break;
      }
      EXPECT_EQ(st.intersecting_pairs, 0) << "frame " << f << ", forces " << forces << ", retries " << retries;
      out.impacts += st.ccd_impacts;
      out.energy = std::max(out.energy, st.energy);
      out.longest = std::max(out.longest, st.longest_spring);
      out.frames = f;
    }
    return out;
  };
  const Run with = run(true, 1, 260);
  EXPECT_EQ(with.frames, 260);
  EXPECT_LT(with.energy, 0.5) << "J";
  EXPECT_LT(with.longest, 1.1);
  EXPECT_LE(with.impacts, 10u);
  for (const auto& [forces, retries] : {std::pair{false, 0}, std::pair{true, 0}, std::pair{false, 1}}) {
    const Run without = run(forces, retries, 260);
    EXPECT_GT(without.energy, 5) << "J; forces " << forces << ", retries " << retries << ", " << without.frames
                                 << " frames";
  }
}

// `crumple:n=16` with the stiffness scaled by (200/16)², so that its steps have the ωh of
// `crumple:n=200` (ω² = k/m: a spring's stiffness stays `stretch` while a vertex's mass falls
// as the edge squared), squeezed by walls that close in 2 s. With the contacts only pushed out
// after the steps, the springs and the push-outs trade energy at every step and the pile heats
// (a mean of 9.4 J over frames 21-120, up to 181 J); with the contacts as forces of the
// projective step it stays near its resting energy (a mean of 2.1 J, at most 4.6 J; the flat
// cloth's jitter holds ~46 J at frame 0, released over the first frames). Intersection-free
// both ways.

TEST(PerFrame, ContactForcesKeepAStiffPileCalm) {
  const auto mean_energy = [](bool forces) {
    Simulation sim = one_thread_simulation("crumple:n=16,stretch=62500,push-time=2,contact-forces=on", forces);
    Scalar sum = 0;
    int frames = 0;
    for (int f = 0; f < 120; ++f) {
      const FrameStats st = sim.advance_frame();
      EXPECT_EQ(st.intersecting_pairs, 0) << "frame " << st.frame;
      if (f >= 20) {
        sum += st.energy;
        ++frames;
      }
    }
    return sum / frames;
  };
  const Scalar with = mean_energy(true), without = mean_energy(false);
  EXPECT_LT(with, 4) << "J";
  EXPECT_GT(without, 3 * with);
}

// `cloth-on-sphere:n=16,sweep-speed=5` with the stiffness scaled by (200/16)², so that its steps
// have the ωh of the sweep at n = 200 (as the pile above). The sweeping sphere hits the skirt at
// frame ~58. With the contacts only pushed out after the steps the cloth runs away from the
// impact (1,191 J at frame 64, 1.7e4 J at 70; it diverges at 78), as the sweep at n = 200 did
// from frame ~130; with the contacts as forces of the projective step it comes back from the
// impact (at most 36 J over frames 70-100). Intersection-free both ways.
TEST(PerFrame, ContactForcesKeepAStiffSweepCalm) {
  // The largest energy over frames 70-100; a run past 1e4 J stops there (it ran away).
  const auto late_energy = [](bool forces) {
    Simulation sim =
        one_thread_simulation("cloth-on-sphere:n=16,sweep-speed=5,stretch=62500,contact-forces=on", forces);
    Scalar most = 0;
    for (int f = 0; f < 100; ++f) {
      FrameStats st;
      try {
        st = sim.advance_frame();
      } catch (const DivergenceError&) {
        return std::numeric_limits<Scalar>::infinity();
      }
      EXPECT_EQ(st.intersecting_pairs, 0) << "frame " << st.frame;
      if (st.energy > 1e4) return st.energy;
      if (f >= 69) most = std::max(most, st.energy);
    }
    return most;
  };
  const Scalar with = late_energy(true), without = late_energy(false);
  EXPECT_LT(with, 100) << "J";
  EXPECT_GT(without, 1e4) << "J";
}

}  // namespace
}  // namespace crumple::sim

#include <crumple/core/error.hpp>
#include <crumple/core/spec_text.hpp>
#include <crumple/mesh/shapes.hpp>
#include <crumple/sim/scene.hpp>

#include <algorithm>
#include <array>
#include <charconv>
#include <limits>
#include <cmath>
#include <numbers>
#include <random>

namespace crumple::sim {

namespace {

// Keys shared by every cloth scene.
#define CRUMPLE_CLOTH_KEYS(density, stiffness, damping, bending, gravity, air, thickness)          \
  {"density", density, "cloth mass per area (kg/m^2), lumped on the vertices"},                    \
      {"stiffness", stiffness, "structural spring stiffness on every mesh edge (N/m)"},           \
      {"damping", damping, "damping ratio of every spring"},                                      \
      {"bending", bending, "stiffness of the bending springs across interior edges (N/m, 0 = none)"}, \
      {"gravity", gravity, "gravity (m/s^2, downwards along -y)"},                                \
      {"air", air, "air damping (1/s): force -air * m * v"},                                      \
      {"thickness", thickness, "contact thickness, as a fraction of the mean edge length"}

// Keys of a material given per unit area and length (`Material`): resolution independent.
#define CRUMPLE_MATERIAL_KEYS(density, stretch, shear, bend, tau, gravity, air, thickness)              \
  {"density", density, "cloth mass per area (kg/m^2), lumped on the vertices"},                        \
      {"stretch", stretch, "in-plane stretch stiffness per unit width (N/m); springs derived per edge"}, \
      {"shear", shear, "shear stiffness (N/m) of the springs across interior edges (0 = none)"},        \
      {"bend", bend, "bending rigidity (N*m) of the hinges on interior edges (0 = none)"},               \
      {"tau", tau, "damping: Kelvin-Voigt relaxation time (s), damping = tau x stiffness"},            \
      {"gravity", gravity, "gravity (m/s^2, downwards along -y)"},                                      \
      {"air", air, "air damping (1/s): force -air * m * v"},                                            \
      {"thickness", thickness, "contact thickness, as a fraction of the mean edge length"}

// The key of `Settings::contact_forces` and its rule (`contact_forces_key`: auto = on above 100
// quads, counted by the scene's key `count`), shared by the scenes whose finest cloths ran warm on
// the push-outs alone.
#define CRUMPLE_CONTACT_FORCES_KEY(count, what)                                                             \
  {"contact-forces", "auto",                                                                               \
   "on | off | auto: the contacts also act as forces inside the projective step, so the springs and the " \
   "contacts reach a compromise within the step (auto: on above " count " = 100, where the push-outs "    \
   "after the steps alone let " what " heat up; at " count " <= 100 they keep it calm, and the forces' "  \
   "second solve per iteration costs more)"}

constexpr std::array<SceneParamInfo, 17> kHanging{{
    {"nx", "10", "quads along x"},
    {"ny", "10", "quads along z"},
    {"size", "1", "side of the cloth along x (m)"},
    {"depth", "0", "side of the cloth along z (m); 0 = size (a square cloth)"},
    {"jitter", "0.01", "seeded random displacement of the initial vertices, fraction of an edge"},
    CRUMPLE_CLOTH_KEYS("0.1", "50", "0.02", "0", "9.81", "0.2", "0.4"),
    {"material", "off",
     "on: the cloth from the per-area material keys below (stretch, shear, bend, tau) instead of the "
     "thesis' per-spring stiffness, damping and bending"},
    {"stretch", "50", "with material=on: in-plane stretch stiffness per unit width (N/m)"},
    {"shear", "0", "with material=on: shear stiffness (N/m)"},
    {"bend", "1e-4", "with material=on: bending rigidity (N*m)"},
    {"tau", "0.01", "with material=on: Kelvin-Voigt relaxation time (s)"},
}};

constexpr std::array<SceneParamInfo, 20> kSphere{{
    {"n", "16", "quads along each side"},
    {"size", "1.5", "side of the square cloth (m)"},
    {"height", "0.7", "initial height of the cloth (m)"},
    {"radius", "0.25", "sphere radius (m); the sphere's centre is under the cloth's centre at y = 0.3"},
    {"friction", "0.3", "Coulomb friction on the sphere and the floor"},
    {"jitter", "0.01", "seeded random displacement of the initial vertices, fraction of an edge"},
    {"sphere-speed", "0", "speed of the sphere along +x (m/s): a kinematic, moving obstacle"},
    {"sweep-speed", "0",
     "speed (m/s) of a second sphere (radius 0.1 x size, lowest point r/3 above the floor, z = size/6) "
     "sweeping along +x through the cloth's skirt, reaching the cloth's side at t = 0.8 s; 0 = none"},
    CRUMPLE_MATERIAL_KEYS("0.1", "400", "0", "2e-4", "0.01", "9.81", "0.2", "0.3"),
    {"self-friction", "0.2", "Coulomb friction between touching parts of the cloth"},
    {"search", "0.01",
     "radius (m) of the frame's proximity search, at least 2 thicknesses: it must cover the relative "
     "motion of a frame, which does not shrink with the edges (2 thicknesses up to n = 100, 3.9 at 200)"},
    CRUMPLE_CONTACT_FORCES_KEY("n", "the cloth"),
    {"motion-retries", "auto",
     "auto or a count: how many times a frame may run again with the pairs that its own motion brings together "
     "from beyond the search radius among its contacts (auto: 1 above n = 100, where the fail-safe's stops of "
     "the landing's folds at the frame's end stretched springs up to 20x their rest length; 0 at n <= 100)"},
}};

constexpr std::array<SceneParamInfo, 21> kRibbon{{
    {"nx", "48", "quads along the ribbon"},
    {"ny", "3", "quads across the ribbon"},
    {"length", "2", "ribbon length along x (m)"},
    {"width", "0.15", "ribbon width (m)"},
    {"turns", "6", "turns of the driven end about the ribbon's axis over twist-time"},
    {"approach", "0.7", "fraction of the length the driven end moves towards the other over twist-time"},
    {"twist-time", "6", "duration of the twist (s); the end is held afterwards"},
    {"settle", "0.005",
     "the projective step iterates (up to 40 times) until no particle moves more than this fraction of the "
     "thickness in an iteration; 0 = a fixed 5 iterations (the coiling ribbon then heats up and diverges)"},
    {"steps", "auto",
     "auto or a count: projective steps per frame of 1/60 s (auto: 4 x ceil(nx / 200), so that the steps' "
     "omega h, which grows as nx, stays at most that of nx = 200 with 4 steps; 400 x 25 with 4 steps ran away "
     "under its coils' contacts)"},
    {"jitter", "0.01", "seeded random displacement of the initial vertices, fraction of an edge"},
    CRUMPLE_MATERIAL_KEYS("0.1", "400", "0", "2e-4", "0.01", "0", "0.5", "0.3"),
    {"self-friction", "0.2", "Coulomb friction between touching parts of the cloth"},
    CRUMPLE_CONTACT_FORCES_KEY("nx", "the coils"),
    {"motion-retries", "auto",
     "auto or a count: how many times a frame may run again with the pairs that its own motion brings together "
     "from beyond the search radius among its contacts (auto: 3 above nx = 100, where the fail-safe's stops of the "
     "first coils to touch at the frame's end started the runaway; 0 at nx <= 100)"},
}};

constexpr std::array<SceneParamInfo, 19> kCrumple{{
    {"n", "20", "quads along each side"},
    {"size", "1", "side of the square cloth (m)"},
    {"final", "0.3", "final gap between the two walls, fraction of size"},
    {"push-time", "5", "time the walls take to close (s)"},
    {"friction", "0.2", "Coulomb friction on the floor and the walls"},
    {"jitter", "0.05", "seeded random displacement of the initial vertices, fraction of an edge"},
    {"wall-height", "0.5", "height of the walls (m)"},
    {"ridge", "2",
     "height of a low ridge across the floor under the cloth's middle (parallel to the walls), in "
     "thicknesses: the out-of-plane cue that starts the folds; 0 = a flat floor"},
    CRUMPLE_MATERIAL_KEYS("0.1", "400", "0", "2e-4", "0.01", "9.81", "0.5", "0.3"),
    {"self-friction", "0.2", "Coulomb friction between touching parts of the cloth"},
    {"search", "0.0068",
     "radius (m) of the frame's proximity search, at least 2 thicknesses: it must cover the relative "
     "motion of a frame, which does not shrink with the edges (2 thicknesses up to n = 100, 4 at 200)"},
    CRUMPLE_CONTACT_FORCES_KEY("n", "the pile"),
}};

constexpr std::array<SceneParamInfo, 8> kFile{{
    {"pins", "", "pinned vertex ids separated by ';' (masses from X3D files: 0 pins)"},
    CRUMPLE_CLOTH_KEYS("0.1", "1000", "0.05", "0", "9.81", "0.1", "0.3"),
}};
#undef CRUMPLE_CLOTH_KEYS
#undef CRUMPLE_MATERIAL_KEYS
#undef CRUMPLE_CONTACT_FORCES_KEY

constexpr std::array<SceneInfo, 5> kScenes{{
    {"hanging-cloth",
     "the thesis scene: a square cloth lattice, initially horizontal, hanging from one "
     "corner under gravity, no collision response: it falls through itself and collapses into a "
     "hanging bundle",
     kHanging},
    {"cloth-on-sphere", "a square cloth dropped on a sphere resting on the floor, response on", kSphere},
    {"twisted-ribbon",
     "a strip pinned at both ends, one end rotated about the strip's axis and moved towards the "
     "other so the ribbon coils and folds onto itself, response on",
     kRibbon},
    {"crumple", "a square cloth on the floor pushed into a pile of folds by two closing walls, response on",
     kCrumple},
    {"file", "a mesh or MassSpring model read from a file (keys apply to `crumple simulate FILE`)", kFile},
}};

std::string join_names() {
  return join_list(kScenes, [](const SceneInfo& s) { return std::string(s.name); });
}

const SceneParamInfo* find_param(const SceneInfo& info, std::string_view key) {
  for (const auto& p : info.params) {
    if (p.key == key) return &p;
  }
  return nullptr;
}

/// Portable uniform double in [-1, 1) from a 64-bit engine (not the implementation-defined
/// std distributions), so scenes are the same on every standard library.
Scalar uniform_pm1(std::mt19937_64& rng) {
  return static_cast<Scalar>(rng() >> 11) * 0x1.0p-52 - 1;
}

void jitter(Positions& x, Scalar amplitude, std::uint64_t seed) {
  if (amplitude == 0) return;
  std::mt19937_64 rng(seed);
  for (Vec3& p : x) {
    const Scalar a = uniform_pm1(rng), b = uniform_pm1(rng), c = uniform_pm1(rng);
    p += amplitude * Vec3(a, b, c);
  }
}

Scalar mean_edge_length(const Topology& topo, PositionsView x) {
  return topo.num_edges() > 0 ? edge_length_stats(topo, x).mean : 1;
}

ClothParams cloth_params(const SceneSpec& spec) {
  ClothParams p;
  p.density = spec.get_double("density");
  p.stiffness = spec.get_double("stiffness");
  p.damping_ratio = spec.get_double("damping");
  p.bending_stiffness = spec.get_double("bending");
  p.bending_damping_ratio = p.damping_ratio;
  if (!(p.density > 0)) throw InputError("scene key 'density' must be > 0");
  return p;
}

Material material(const SceneSpec& spec) {
  Material m;
  m.density = spec.get_double("density");
  m.stretch = spec.get_double("stretch");
  m.shear = spec.get_double("shear");
  m.bending = spec.get_double("bend");
  m.damping = spec.get_double("tau");
  return m;
}

ForceField force_field(const SceneSpec& spec) {
  ForceField f;
  f.gravity = Vec3(0, -spec.get_double("gravity"), 0);
  f.air_damping = spec.get_double("air");
  return f;
}

/// A lattice resolution key of a scene: an integer in 1..kMaxLatticeSide.
constexpr long long kMaxLatticeSide = 100'000;
/// Most particles of a scene lattice: a simulation needs about 1 KB per particle.
constexpr long long kMaxLatticeVertices = 4'000'000;

Index lattice_count(const SceneSpec& spec, std::string_view key) {
  const long long v = spec.get_int(key);
  if (v < 1 || v > kMaxLatticeSide) {
    throw InputError("scene '" + spec.name() + "': key '" + std::string(key) + "' must be between 1 and " +
                     std::to_string(kMaxLatticeSide) + ", got " + std::to_string(v));
  }
  return static_cast<Index>(v);
}

/// Lattice nx × ny of size w × d lying horizontally at height y: lattice vertex (i, j) at
/// (i w/nx, y, j d/ny).
TriMesh horizontal_lattice(Index nx, Index ny, Scalar w, Scalar d, Scalar y) {
  if (nx < 1 || ny < 1) throw InputError("scene lattice needs at least 1 x 1 quads");
  const long long vertices = (static_cast<long long>(nx) + 1) * (static_cast<long long>(ny) + 1);
  if (vertices > kMaxLatticeVertices) {
    throw InputError("scene lattice of " + std::to_string(nx) + " x " + std::to_string(ny) + " quads has " +
                     std::to_string(vertices) + " vertices, more than " + std::to_string(kMaxLatticeVertices));
  }
  TriMesh flat = shapes::lattice(nx, ny, w, d);
  Positions x = flat.positions();
  for (Vec3& p : x) p = Vec3(p.x(), y, p.y());
  return TriMesh::create(std::move(x), std::vector<Face>(flat.topology().faces().begin(),
                                                         flat.topology().faces().end()));
}

response::Obstacle make_obstacle(response::Shape shape, Vec3 velocity, Scalar stop_time, Scalar friction,
                                 Scalar margin) {
  response::Obstacle o;
  o.shape = std::move(shape);
  o.velocity = velocity;
  o.stop_time = stop_time;
  o.friction = friction;
  o.margin = margin;
  return o;
}

constexpr Scalar kForever = std::numeric_limits<Scalar>::infinity();

Scene finish(const SceneSpec& spec, Cloth cloth, Scalar jitter_rel, std::uint64_t seed) {
  Scene s{spec.to_string(), std::move(cloth.model), std::move(cloth.state), force_field(spec), {}, {}, {}, 0};
  s.edge_length = mean_edge_length(s.model.topology(), s.state.x);
  const Positions before = s.state.x;
  jitter(s.state.x, jitter_rel * s.edge_length, seed);
  for (Index i = 0; i < s.model.num_particles(); ++i) {
    if (s.model.pinned(i)) s.state.x[static_cast<std::size_t>(i)] = before[static_cast<std::size_t>(i)];
  }
  s.settings.detector.thickness = spec.get_double("thickness") * s.edge_length;
  return s;
}

/// The frame's proximity search radius from the scene key `search` (m), at least 2 thicknesses.
void search_radius(Scene& s, const SceneSpec& spec) {
  const Scalar search = spec.get_double("search");
  if (!(search >= 0) || !std::isfinite(search)) throw InputError("scene key 'search' must be finite and >= 0");
  s.settings.search_factor = std::max<Scalar>(2, search / s.settings.detector.thickness);
}

/// The scene key `contact-forces` (`CRUMPLE_CONTACT_FORCES_KEY`): on, off, or auto = on above
/// n = 100 quads a side. The push-outs after the steps store energy that grows with the steps'
/// ωh (√(k/m) h: a vertex's mass falls as the edge squared), and at n = 200 it ran the pile and
/// the sweep away; at n <= 100 the push-outs alone stay calm, and the forces' second solve per
/// iteration costs about a third more per frame (docs/simulation.md, "Contacts in the projective
/// step").
bool contact_forces_key(const SceneSpec& spec, Index n) {
  const std::string value = spec.get_string("contact-forces");
  if (value == "auto") return n > 100;
  if (const auto on = parse_switch(value)) return *on;
  throw InputError("scene '" + spec.name() + "': key 'contact-forces' expects on, off or auto, got '" + value + "'");
}

/// The scene key `motion-retries`: a count, or auto = `above` retries above 100 quads (`n`, as
/// `contact-forces` counts them: a side, or the ribbon's length), 0 otherwise. `cloth-on-sphere`
/// (auto 1): its landing brings folds onto the cloth on the floor from farther than the search
/// radius within a frame (~3 m/s, 5 cm a frame); left to the fail-safe, they are stopped at the
/// frame's end against springs the steps did not see, and at n = 200 (ωh twice n = 100's) the
/// next frame's release of that stretch moved the cloth farther still (a spring 20x its rest
/// length, 94 J); a retried frame answers them with proximity contacts at every step
/// (docs/simulation.md, "Energy under contact"). At n <= 100 the landing cools without them, and
/// a retried frame pays its steps twice.
int motion_retries_key(const SceneSpec& spec, Index n, int above) {
  const std::string value = spec.get_string("motion-retries");
  if (value == "auto") return n > 100 ? above : 0;
  const auto count = parse_integer(value);
  if (!count || *count < 0 || *count > 100) {
    throw InputError("scene '" + spec.name() + "': key 'motion-retries' expects auto or an integer in [0, 100], got '" +
                     value + "'");
  }
  return static_cast<int>(*count);
}

/// The fast default of the scenes with a per-area material: detection once per frame with
/// proximity impulses and friction (`ResponseModel::Proximity`), projective dynamics, 4 steps of
/// 1/240 s per frame of 1/60 s, 5 local/global iterations each, Chebyshev-accelerated with
/// ρ = 0.8 (docs/simulation.md).
void fast_settings(Scene& s, const SceneSpec& spec) {
  s.settings.response_model = ResponseModel::Proximity;
  if (const auto& keys = scene_info(spec.name()).params;
      std::any_of(keys.begin(), keys.end(), [](const SceneParamInfo& p) { return p.key == "self-friction"; })) {
    s.settings.self_friction = spec.get_double("self-friction");
    if (!(s.settings.self_friction >= 0)) throw InputError("scene key 'self-friction' must be >= 0");
  }
  s.settings.integrator = IntegratorKind::Projective;
  s.settings.dt = 1.0 / 240;
  s.settings.substeps = 4;
  s.settings.integrator_options.projective_iterations = 5;
  s.settings.integrator_options.projective_rho = 0.8;
}

Scene hanging_cloth(const SceneSpec& spec, std::uint64_t seed) {
  const Index nx = lattice_count(spec, "nx"), ny = lattice_count(spec, "ny");
  const Scalar size = spec.get_double("size");
  Scalar depth = spec.get_double("depth");
  if (!(depth >= 0)) throw InputError("scene key 'depth' must be >= 0 (0 = size)");
  if (depth == 0) depth = size;
  const TriMesh mesh = horizontal_lattice(nx, ny, size, depth, 0);
  Cloth cloth;
  if (spec.get_bool("material")) {
    Material m = material(spec);
    m.pins = {0};  // the corner at the origin
    cloth = make_cloth(mesh, m);
  } else {
    ClothParams params = cloth_params(spec);
    params.pins = {0};
    cloth = make_cloth(mesh, params);
  }
  Scene s = finish(spec, std::move(cloth), spec.get_double("jitter"), seed);
  s.settings.response = false;
  if (spec.get_bool("material")) fast_settings(s, spec);
  return s;
}

Scene cloth_on_sphere(const SceneSpec& spec, std::uint64_t seed) {
  const Index n = lattice_count(spec, "n");
  const Scalar size = spec.get_double("size");
  const TriMesh mesh = horizontal_lattice(n, n, size, size, spec.get_double("height"));
  Scene s = finish(spec, make_cloth(mesh, material(spec)), spec.get_double("jitter"), seed);
  const Scalar friction = spec.get_double("friction");
  const Scalar margin = 0.5 * s.settings.detector.thickness;
  s.obstacles.push_back(make_obstacle(response::Sphere{Vec3(0.5 * size, 0.3, 0.5 * size), spec.get_double("radius")},
                                      Vec3(spec.get_double("sphere-speed"), 0, 0), kForever, friction, margin));
  s.obstacles.push_back(make_obstacle(response::Plane{Vec3::Zero(), Vec3::UnitY()}, Vec3::Zero(), kForever,
                                      friction, margin));
  if (const Scalar sweep = spec.get_double("sweep-speed"); sweep != 0) {
    if (!(sweep > 0) || !std::isfinite(sweep)) throw InputError("scene key 'sweep-speed' must be >= 0");
    const Scalar r = 0.1 * size;
    s.obstacles.push_back(make_obstacle(response::Sphere{Vec3(-r - 0.8 * sweep, 4 * r / 3, size / 6), r},
                                        Vec3(sweep, 0, 0), kForever, friction, margin));
  }
  s.settings.response = true;
  fast_settings(s, spec);
  // The thickness shrinks with the edges, a frame's relative motion (the falling skirt landing
  // on the floor, ~3 m/s) does not: at n = 200 a radius of 2 thicknesses (4.5 mm) left the
  // landing to the fail-safe, whose corrections stored more energy than the step dissipated
  // (energy +10-20 % a frame, 150,000 live impacts by frame 56; docs/simulation.md, "Energy
  // under contact"). A radius fixed in metres keeps n = 200 as calm as n = 100.
  search_radius(s, spec);
  // As in `crumple` (below): at n = 200 the push-outs after the steps alone let the 5 m/s sweep
  // run away (3,210 J by frame 227; docs/simulation.md, "Contacts in the projective step").
  s.settings.contact_forces = contact_forces_key(spec, n);
  // The landing's folds that close in from beyond the radius within a frame: at n = 200 the
  // fail-safe's stops of them stretched springs 20x (94 J at frame 31); one retry keeps the
  // landing near 1 J (docs/simulation.md, "Energy under contact").
  s.settings.motion_retries = motion_retries_key(spec, n, 1);
  return s;
}

Scene twisted_ribbon(const SceneSpec& spec, std::uint64_t seed) {
  const Index nx = lattice_count(spec, "nx"), ny = lattice_count(spec, "ny");
  const Scalar length = spec.get_double("length"), width = spec.get_double("width");
  const TriMesh mesh = horizontal_lattice(nx, ny, length, width, 1);
  Material params = material(spec);
  std::vector<Index> fixed, driven;
  for (Index j = 0; j <= ny; ++j) {
    fixed.push_back(j * (nx + 1));
    driven.push_back(j * (nx + 1) + nx);
  }
  params.pins = fixed;
  params.pins.insert(params.pins.end(), driven.begin(), driven.end());
  Scene s = finish(spec, make_cloth(mesh, params), spec.get_double("jitter"), seed);
  const Scalar twist_time = spec.get_double("twist-time");
  if (!(twist_time > 0)) throw InputError("scene key 'twist-time' must be > 0");
  const Scalar omega = 2 * std::numbers::pi * spec.get_double("turns") / twist_time;
  const Scalar speed = spec.get_double("approach") * length / twist_time;
  const Vec3 axis_point(length, 1, 0.5 * width);
  std::vector<Vec3> rest;
  for (Index v : driven) rest.push_back(mesh.positions()[static_cast<std::size_t>(v)]);
  s.kinematics = [driven, rest, omega, speed, twist_time, axis_point](State& st) {
    const Scalar t = std::min(st.time, twist_time);
    const bool moving = st.time < twist_time;
    const Scalar angle = omega * t;
    const Eigen::AngleAxis<Scalar> rot(angle, Vec3::UnitX());
    const Vec3 shift(-speed * t, 0, 0);
    for (std::size_t k = 0; k < driven.size(); ++k) {
      const Vec3 r = rot * (rest[k] - axis_point);
      const auto i = static_cast<std::size_t>(driven[k]);
      st.x[i] = axis_point + shift + r;
      st.v[i] = moving ? Vec3(Vec3(omega, 0, 0).cross(r) + Vec3(-speed, 0, 0)) : Vec3::Zero();
    }
  };
  s.settings.response = true;
  fast_settings(s, spec);
  const Scalar settle = spec.get_double("settle");
  if (!(settle >= 0) || !std::isfinite(settle)) throw InputError("scene key 'settle' must be finite and >= 0");
  s.settings.integrator_options.projective_tolerance = settle * s.settings.detector.thickness;
  // Refined, the ribbon's ωh grows as 1 / edge (a spring's stiffness stays `stretch`, a vertex's
  // mass falls as the edge squared) and its radius 2 h_c shrinks while the coils' closing speed
  // (~1 m/s, 1.7 cm a frame) does not. At 200 × 12 and 400 × 25 the first coils to touch came in
  // from beyond the radius: the fail-safe stopped them at the frame's end against springs the
  // steps did not see (400 × 25: a spring 2.17x its rest length at the first touch), the next
  // frames' push-outs and the springs traded more energy at every step than the steps took out,
  // and both loops ran the ribbon away (101 J by frame 144 at 400 × 25; 200 × 12 diverged at frame
  // 219). Each cure alone leaves the other loop (docs/simulation.md, "Energy under contact").
  s.settings.contact_forces = contact_forces_key(spec, nx);
  s.settings.motion_retries = motion_retries_key(spec, nx, 3);
  // Three reruns: with one, 400 × 25 ran away at frame 200 (a rerun's changed motion brought in
  // further pairs from beyond the radius, 169 live impacts). With both cures it still had frames
  // whose fold closed in faster than three reruns could gather its pairs (frame 218: 2,095 live
  // impacts, 7.5x, then 418 J); at half its ωh, with 8 steps a frame, it ran without a live
  // impact. `steps=auto` keeps ωh at most that of 200 × 12 with 4 steps (docs/simulation.md,
  // "Energy under contact"); the frame stays 1/60 s, and at nx <= 200 the step 1/240 s, bit for
  // bit as before.
  const std::string steps = spec.get_string("steps");
  int count = static_cast<int>(4 * ((nx + 199) / 200));
  if (steps != "auto") {
    const auto n = parse_integer(steps);
    if (!n || *n < 1 || *n > 1000) {
      throw InputError("scene 'twisted-ribbon': key 'steps' expects auto or an integer in [1, 1000], got '" + steps + "'");
    }
    count = static_cast<int>(*n);
  }
  s.settings.substeps = count;
  s.settings.dt = 1.0 / (60 * count);
  return s;
}

Scene crumple_scene(const SceneSpec& spec, std::uint64_t seed) {
  const Index n = lattice_count(spec, "n");
  const Scalar size = spec.get_double("size");
  const Scalar thickness_guess = spec.get_double("thickness") * size / static_cast<Scalar>(n);
  // Above the ridge (below) and its margin.
  const TriMesh mesh = horizontal_lattice(n, n, size, size, (1 + spec.get_double("ridge")) * thickness_guess);
  Scene s = finish(spec, make_cloth(mesh, material(spec)), spec.get_double("jitter"), seed);
  const Scalar friction = spec.get_double("friction");
  const Scalar margin = 0.5 * s.settings.detector.thickness;
  const Scalar push_time = spec.get_double("push-time");
  if (!(push_time > 0)) throw InputError("scene key 'push-time' must be > 0");
  const Scalar travel = 0.5 * size * (1 - spec.get_double("final"));
  const Scalar speed = travel / push_time;
  const Scalar h = spec.get_double("wall-height");
  const Scalar half = 0.05 * size;  // wall half thickness
  const Scalar gap = 2 * margin;    // initial clearance between a wall and the cloth's border
  // Walls reach below the floor so that no vertex is pushed out through a wall's bottom face.
  const Scalar below = 0.2 * size;
  const Vec3 c(0.5 * size, 0.5 * (h - below), 0.5 * size);
  const Scalar off = 0.5 * size + half + gap;
  for (const Scalar side : {-1.0, 1.0}) {
    s.obstacles.push_back(make_obstacle(response::Box{c + side * Vec3(off, 0, 0), Vec3(half, 0.5 * (h + below), size)},
                                        Vec3(-side * speed, 0, 0), push_time, friction, margin));
  }
  s.obstacles.push_back(make_obstacle(response::Plane{Vec3::Zero(), Vec3::UnitY()}, Vec3::Zero(), kForever,
                                      friction, margin));
  // A flat cloth pressed in its plane on a flat floor has no reason to leave it: without a cue it
  // stays flat under compression (the fail-safe forbids the in-plane pass-throughs that used to
  // start the folds). The ridge lifts the middle a little, and the folds start there.
  if (const Scalar ridge = spec.get_double("ridge"); ridge != 0) {
    if (!(ridge > 0) || !std::isfinite(ridge)) throw InputError("scene key 'ridge' must be >= 0");
    const Scalar top = ridge * s.settings.detector.thickness;
    s.obstacles.push_back(make_obstacle(response::Box{Vec3(0.5 * size, top - below, 0.5 * size),
                                                      Vec3(0.5 * s.edge_length, below, size)},
                                        Vec3::Zero(), kForever, friction, margin));
  }
  s.settings.response = true;
  fast_settings(s, spec);
  // The closing walls squeeze the pile: twice the steps keep its layers apart (tested).
  s.settings.dt = 1.0 / 480;
  s.settings.substeps = 8;
  s.settings.integrator_options.projective_iterations = 3;
  // Unaccelerated: three Chebyshev-accelerated iterations overshoot the stiff modes that the
  // push-outs of the squeezed pile excite, and the 100×100 pile heats up (docs/simulation.md).
  s.settings.integrator_options.projective_rho = 0;
  // As on the sphere (above): at n = 200 a radius of 2 thicknesses (3.4 mm) left the folds that
  // fall onto the pile (1-2 m/s) to the fail-safe, and its corrections heated the pile from its
  // first impacts (frame 248: longest spring 7x, 52x at 279, 774 J and 1.1 million live impacts
  // at 293). 6.8 mm is the radius of n = 100 (2 thicknesses).
  search_radius(s, spec);
  // The squeezed pile's steps release what its springs store into motions longer than the
  // radius's slack; left to the fail-safe, the pairs they bring together are stopped at the
  // frame's end against the springs, which store more for the next frame: at n = 100 that loop
  // ran away from frame ~560 (docs/simulation.md, "Energy under contact"). A frame whose motion
  // brings such pairs runs again with them among its contacts. Twice: the rerun's own motion can
  // bring more such pairs (in the formed pile at n = 100, one knot that kept running every frame
  // twice for ~80 frames with one retry), and a second rerun answers them too: over 1,000 frames
  // at n = 100, 46 frames run again instead of 125 and the longest spring is 2.31x instead of
  // 3.7x (n <= 64: the same figures). Not more: three let that knot heat up (docs/simulation.md,
  // "Motion retries"). Above n = 100 once: the 1,000-frame run at n = 200 was measured with one
  // (clean, with the contact forces below); two are not measured there.
  s.settings.motion_retries = n <= 100 ? 2 : 1;
  // Half pushes: with full ones the layers pressed on each other from both sides (the pile the
  // walls squeeze) exchange the push-outs with the springs at every step, an exchange that grew
  // at n = 100 from frame ~850 until the fail-safe's loop above took over (docs/simulation.md).
  s.settings.proximity_relaxation = 0.5;
  // The contacts as forces inside the projective step: the springs see them and the two reach a
  // compromise within the step, where the push-outs after it traded energy with the springs at
  // every step. At n = 200 that exchange kept the pile at 2-7 J with springs stretched up to 17x
  // (docs/simulation.md, "Contacts in the projective step"). Up to n = 100 the half pushes keep
  // the pile calm over 1,000 frames without them, and their second solve per iteration costs
  // about a third more per landing frame: `auto` keeps them for the finer cloths.
  s.settings.contact_forces = contact_forces_key(spec, n);
  return s;
}

std::vector<Index> parse_pins(const std::string& text) {
  std::vector<Index> pins;
  std::string_view rest = text;
  while (!rest.empty()) {
    const auto semi = rest.find(';');
    const std::string_view item = trim_blanks(rest.substr(0, semi));
    rest = semi == std::string_view::npos ? std::string_view() : rest.substr(semi + 1);
    if (item.empty()) continue;
    Index v = 0;
    const auto [ptr, ec] = std::from_chars(item.data(), item.data() + item.size(), v);
    if (ec != std::errc() || ptr != item.data() + item.size() || v < 0) {
      throw InputError("scene key 'pins': expected vertex ids separated by ';', got '" + text + "'");
    }
    pins.push_back(v);
  }
  return pins;
}

}  // namespace

std::span<const SceneInfo> all_scenes() { return kScenes; }

const SceneInfo& scene_info(std::string_view name) {
  for (const auto& s : kScenes) {
    if (s.name == name) return s;
  }
  throw InputError("unknown scene '" + std::string(name) + "' (valid: " + join_names() + ")");
}

SceneSpec SceneSpec::parse(std::string_view text) {
  const SpecText split = SpecText::split(text, "scene");
  SceneSpec spec;
  spec.name_ = split.name;
  scene_info(spec.name_);
  for (const auto& [key, value] : split.items) spec.set(key, value);
  return spec;
}

SceneSpec& SceneSpec::set(std::string key, std::string value) {
  set_spec_key(params_, scene_info(name_).params, std::move(key), std::move(value), "scene '" + name_ + "'");
  return *this;
}

std::string SceneSpec::get_string(std::string_view key) const {
  if (const std::string* value = find_spec_value(params_, key)) return *value;
  const SceneParamInfo* p = find_param(scene_info(name_), key);
  CRUMPLE_CHECK(p != nullptr, "scene key not in the scene's table");
  return std::string(p->default_value);
}

Scalar SceneSpec::get_double(std::string_view key) const {
  const std::string value = get_string(key);
  const auto out = parse_number(value);
  if (!out) throw InputError("scene '" + name_ + "': key '" + std::string(key) + "' expects a number, got '" + value + "'");
  return *out;
}

long long SceneSpec::get_int(std::string_view key) const {
  const std::string value = get_string(key);
  const auto out = parse_integer(value);
  if (!out) {
    throw InputError("scene '" + name_ + "': key '" + std::string(key) + "' expects an integer, got '" + value + "'");
  }
  return *out;
}

bool SceneSpec::get_bool(std::string_view key) const {
  const std::string value = get_string(key);
  const auto out = parse_switch(value);
  if (!out) throw InputError("scene '" + name_ + "': key '" + std::string(key) + "' expects on or off, got '" + value + "'");
  return *out;
}

std::string SceneSpec::to_string() const { return format_spec(name_, params_); }

Scene make_scene(const SceneSpec& spec, std::uint64_t seed) {
  if (spec.name() == "hanging-cloth") return hanging_cloth(spec, seed);
  if (spec.name() == "cloth-on-sphere") return cloth_on_sphere(spec, seed);
  if (spec.name() == "twisted-ribbon") return twisted_ribbon(spec, seed);
  if (spec.name() == "crumple") return crumple_scene(spec, seed);
  throw InputError("scene '" + spec.name() + "' is made from a file: give the file instead");
}

Scene make_scene_from_mesh(const TriMesh& mesh, const SceneSpec& params) {
  CRUMPLE_CHECK(params.name() == "file", "mesh scenes take the 'file' keys");
  ClothParams p = cloth_params(params);
  p.pins = parse_pins(params.get_string("pins"));
  return finish(params, make_cloth(mesh, p), 0, 0);
}

Scene make_scene_from_model(Model model, State state, const SceneSpec& params) {
  CRUMPLE_CHECK(params.name() == "file", "model scenes take the 'file' keys");
  CRUMPLE_CHECK(state.x.size() == static_cast<std::size_t>(model.num_particles()) &&
                    state.v.size() == state.x.size(),
                "state must have #V positions and velocities");
  Scene s{params.to_string(), std::move(model), std::move(state), force_field(params), {}, {}, {}, 0};
  s.edge_length = mean_edge_length(s.model.topology(), s.state.x);
  s.settings.detector.thickness = params.get_double("thickness") * s.edge_length;
  return s;
}

Recording record_scene(const std::string& spec, std::int64_t frames, std::uint64_t seed,
                       const std::function<void(std::int64_t)>& on_frame) {
  Scene scene = make_scene(SceneSpec::parse(spec), seed);
  Settings settings = scene.settings;
  settings.method = MethodSpec::parse("kdop");
  settings.detector.threads = 1;
  Recording r;
  r.spec = scene.spec;
  r.thickness = settings.detector.thickness;
  const auto faces = scene.model.topology().faces();
  r.mesh = TriMesh::create(scene.state.x, std::vector<Face>(faces.begin(), faces.end()));
  Simulation simulation(std::move(scene.model), std::move(scene.state), scene.field,
                        std::move(scene.obstacles), std::move(scene.kinematics), settings);
  r.frames.push_back(simulation.state().x);
  r.share.push_back(simulation.current_stats().collision_share);
  for (std::int64_t k = 0; k < frames; ++k) {
    const FrameStats stats = simulation.advance_frame();
    r.frames.push_back(simulation.state().x);
    r.share.push_back(stats.collision_share);
    if (on_frame) on_frame(k + 1);
  }
  return r;
}

}  // namespace crumple::sim

#pragma once
/// \file
/// The simulation loop: integrate → kinematic pins → obstacles → self-collision response, with
/// a detector from `detect/` (the thesis' loop, docs/simulation.md: display → input → deform → handle collisions).
///
/// One step of length h, contacts C detected at the step's start positions x₀ (thickness h_c):
///  1. integrate (x₀, v₀) → (x₁, v₁) with the chosen integrator;
///  2. the scene's kinematics set the driven (pinned) particles at the new time;
///  3. every obstacle projects vertices out and corrects their velocity (`response/obstacle.hpp`);
///  4. with response on: every VF/EE contact of C — its normal and barycentric weights taken at
///     x₀, so a pair that crossed during the step is pushed back to the side it came from — is
///     corrected at (x₁, v₁) by `response::resolve` (velocity, then push-out to h_c), for up to
///     `passes` Gauss–Seidel sweeps until no contact approaches; then obstacles again (3).
/// Contacts are detected once per step with response on (the detection at a frame's end serves
/// the next step), once per frame with it off. Deterministic: the same inputs give the same bits.
///
/// With response on and `Settings::fail_safe` (the default), every frame ends with the
/// continuous fail-safe (`response::CcdFailSafe`) over the frame's motion, from its start
/// positions to the proposed end: **a frame that starts intersection-free ends
/// intersection-free** (no two triangles sharing no vertex intersect), whatever the speed.
/// With the Proximity model and a detector that reports every pair (exact, uncut), the frame's
/// start detection restricts the fail-safe's first query (`response::StartProximity`).
///
/// With response on and `Settings::untangle` (the default), a frame that starts with
/// intersecting triangles is untangled (`response/untangle.hpp`: Global Intersection Analysis,
/// then pushes after every step that pull the inside regions back through); the regular
/// response and the fail-safe leave the tangle's own pairs alone meanwhile. Once a frame starts
/// intersection-free with the built-in fail-safe, every later one does too, and the check stops.
///
/// After every step the state is checked (`DivergenceError`): a diverging run stops at once
/// instead of producing frames of huge or NaN coordinates.

#include <crumple/core/error.hpp>
#include <crumple/detect/continuous.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/response/contact_response.hpp>
#include <crumple/response/fail_safe.hpp>
#include <crumple/response/obstacle.hpp>
#include <crumple/response/untangle.hpp>
#include <crumple/sim/integrator.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <string_view>
#include <vector>

namespace crumple::sim {

/// Sets the driven (pinned) particles' positions and velocities for time `state.time`.
using Kinematics = std::function<void(State& state)>;

/// Thrown by `Simulation::advance_frame` when a step leaves a non-finite position or velocity, a
/// particle moving farther than the initial spread in one step, or a spread (bounding-box
/// diagonal of the particles) beyond `Settings::max_spread_growth` times the initial one. The
/// simulation is then back at the start of the frame (the last good state, frame `frame - 1`).
class DivergenceError : public Error {
 public:
  DivergenceError(const std::string& what, std::int64_t frame, int step)
      : Error(what), frame_(frame), step_(step) {}
  /// The frame being computed when the state went bad.
  std::int64_t frame() const { return frame_; }
  /// Its step (1-based) that went bad.
  int step() const { return step_; }

 private:
  std::int64_t frame_;
  int step_;
};

/// How self-collisions are answered (with `Settings::response` on).
///  - AnnexB: the thesis' loop above: detection at every step's start, Annex B velocity and
///    position corrections (`response::resolve`) after it.
///  - Proximity: detection once per frame, at the frame's start, with the search radius
///    `search_factor` × h_c (pairs up to h_c apart plus a slack for the frame's relative
///    motion); the
///    frame's contacts (normals and weights from the frame's start) serve every step of the
///    frame: after each, the pairs whose gap fell below h_c get proximity impulses with
///    friction (`response::resolve_proximity`). A pair that was farther than 2 h_c at the
///    frame's start and closes in within the frame is not seen: the continuous (CCD) fail-safe
///    (`Settings::fail_safe`) is what catches it, unless the frame's predicted motion
///    brought it into the frame's contacts (`Settings::motion_search`) or the frame ran again
///    with it there (`Settings::motion_retries`). Frame statistics
///    count the contacts closer than h_c at the frame's end (the same detection serves the
///    next frame).
enum class ResponseModel { AnnexB, Proximity };

/// Called at the end of every frame with the positions at the frame's start and the state at
/// its end (after the response), before the frame's closing detection: a custom replacement
/// for the built-in continuous fail-safe. It may change positions and velocities.
using FailSafe = std::function<void(PositionsView frame_start, State& state)>;

/// The proximity radius, in thicknesses, of the pairs of one flat patch of the cloth
/// (`Settings::flat_neighbour_rings`).
inline constexpr Scalar kFlatNeighbourSearch = 2;

/// How a simulation steps, detects and responds.
struct Settings {
  Scalar dt = 1.0 / 600;  ///< step length h (s)
  int substeps = 10;      ///< steps per frame
  IntegratorKind integrator = IntegratorKind::ImplicitEuler;
  IntegratorOptions integrator_options;
  MethodSpec method{Method::Kdop};
  DetectorOptions detector;  ///< thickness h_c, contact kinds, threads
  bool response = false;     ///< self-collision response on/off
  int passes = 4;            ///< Gauss–Seidel sweeps per step (>= 1)
  ResponseModel response_model = ResponseModel::AnnexB;
  Scalar self_friction = 0;  ///< Coulomb coefficient between touching parts (Proximity model)
  /// Proximity model: the frame's detection radius as a multiple of the thickness (> 1); the
  /// slack beyond h_c is the relative motion a frame may bring without being missed.
  Scalar search_factor = 2;
  /// Proximity model: the frame's contacts also hold the pairs that the frame's predicted
  /// motion (x + H v, H the frame's length, then projected out of the obstacles) brings within
  /// h_c although they are farther than the detection radius at the start, found by a
  /// continuous query over the pairs with a vertex whose predicted displacement differs from
  /// the mass-weighted mean one by more than half the radius' slack — the only pairs the fixed
  /// radius can miss under that motion (see `ResponseModel`). The proximity impulses then keep
  /// those fast pairs apart instead of leaving them to the fail-safe. Off by default: the query
  /// costs more than the fail-safe work it saves (docs/simulation.md, "Motion search").
  bool motion_search = false;
  /// Proximity model, with `search_factor` above `kFlatNeighbourSearch`: the frame's detected
  /// pairs of one flat patch of the cloth — sides at most this many edges apart on the mesh,
  /// facing alike, the pair's normal along the cloth — keep the radius `kFlatNeighbourSearch` ×
  /// h_c: those farther apart are left out of the frame's proximity impulses
  /// (`response::drop_flat_neighbours`; 1 or 2; 0 keeps every pair). Such a gap closes only as
  /// fast as the few edges between its sides shorten; the larger radius is for layers falling
  /// onto each other (docs/simulation.md, "Flat neighbours").
  int flat_neighbour_rings = 2;
  /// Proximity model, with the built-in fail-safe: how many times a frame may be run again when
  /// its proposed motion brings pairs within the fail-safe's δ that were farther than the
  /// detection radius at its start (found by a continuous query over the pairs with a vertex
  /// whose displacement differs from the mass-weighted mean one by more than half of R − δ,
  /// as `motion_search` does for the predicted motion). Those pairs join the frame's contacts
  /// and the frame restarts from its start: the proximity impulses then keep them apart at
  /// every step, where the implicit step sees the correction, instead of leaving them to the
  /// fail-safe, whose end-of-frame corrections the springs store and the next frame releases
  /// (docs/simulation.md, "Energy under contact"). 0: never (the frame's motion is the first).
  int motion_retries = 0;
  /// Proximity model: the push-outs' relaxation ω in (0, 1] (`response::ProximityOptions::
  /// relaxation`; 0.5 in the `crumple` scene, 1 elsewhere). Where the layers of a squeezed pile
  /// press on each other from both sides, full pushes (ω = 1) alternate at every step between
  /// the ends of conflicting pairs and store the moves in the springs, which the next step
  /// returns into the contacts: at n = 100 that exchange grew from frame ~850 until the pile
  /// heated up (docs/simulation.md, "Energy under contact").
  Scalar proximity_relaxation = 1;
  /// Proximity model with the projective integrator: the frame's contacts also act inside every
  /// step, as forces of the local step (`response::update_contact_forces`, relaxation
  /// `proximity_relaxation`; their multipliers kept through the frame's steps), so the springs
  /// and the contacts reach a compromise within the step instead of trading the push-outs that
  /// follow it (docs/simulation.md, "Contacts in the projective step"). The push-outs still run
  /// after each step. On in the `crumple` scene above n = 100 (its key `contact-forces`).
  bool contact_forces = false;
  /// Largest spread of the particles, as a multiple of the initial one, before the run counts
  /// as diverged (see `DivergenceError`). A cloth's springs keep it near its own size.
  Scalar max_spread_growth = 10;
  /// With `response` on: the continuous fail-safe (`response/fail_safe.hpp`) at every frame's
  /// end, so that a frame that starts intersection-free ends intersection-free.
  bool fail_safe = true;
  /// The fail-safe's minimum separation δ as a fraction of the thickness h_c (>= 0).
  Scalar fail_safe_separation = 0.1;
  /// With `response` on: analyse the intersecting triangle pairs at every frame's start and
  /// untangle them (see the file comment). Costs one exact intersection query per frame until
  /// a frame is found intersection-free with the built-in fail-safe on.
  bool untangle = true;
  /// Largest pull-through position impulse of one crossing per step, as a fraction of h_c (> 0).
  Scalar untangle_step = 0.25;
  /// Contour-minimisation displacement per step (contours bounding no region), fraction of h_c.
  Scalar contour_step = 0.1;
  /// The same for the border end of a curve from the cloth's border to a pinch, fraction of h_c
  /// (>= 0; `response::UntangleOptions::border_step`).
  Scalar border_step = 0.5;
  /// With an integrator that `takes_anchors` (implicit Euler): the pulls act inside the step, as
  /// springs drawing each pulled vertex along its pulls' net move (`Anchor`, one per vertex),
  /// instead of moving the vertices after it, where the next step takes most of a move back
  /// on a stiff cloth. Off by default: measured on the tangled hanging cloth it untangles
  /// 80×80 sooner but 100×100 not at all, and 32×32 and 64×64 a few frames later
  /// (docs/simulation.md, "Untangling").
  bool untangle_in_solve = false;
  /// Those springs' stiffness relative to each vertex's own diagonal of the step's matrix (> 0;
  /// `Anchor`). Stiffer (10) made the early, large tangles grow.
  Scalar untangle_pull_stiffness = 1;
};

/// Figures of one frame (timings summed over its steps).
struct FrameStats {
  std::int64_t frame = 0;
  Scalar time = 0;
  double integrate_ms = 0;
  double detect_ms = 0;
  double response_ms = 0;  ///< obstacles and self-collision response
  double ccd_ms = 0;       ///< the continuous fail-safe (its queries and corrections)
  std::size_t ccd_impacts = 0;  ///< live impacts of the frame's proposed motion (fail-safe)
  int ccd_queries = 0;          ///< continuous queries run by the fail-safe
  std::size_t ccd_zone_vertices = 0;  ///< vertices the fail-safe put in impact zones
  std::size_t ccd_frozen = 0;   ///< vertices the fail-safe's fallback kept at their start
  /// The fail-safe's first query was restricted by the frame's start detection
  /// (`response::StartProximity`) instead of sweeping the mesh.
  bool ccd_first_restricted = false;
  /// Contacts added to the frame's proximity contacts by `Settings::motion_search`, and the
  /// vertices whose predicted motion was fast enough to be searched.
  std::size_t motion_pairs = 0;
  std::size_t motion_vertices = 0;
  /// Detected pairs left out of the frame's proximity impulses as flat neighbours
  /// (`Settings::flat_neighbour_rings`).
  std::size_t flat_pairs = 0;
  /// Pairs the frame's proximity impulses served (the detection's and the motion search's, less
  /// the flat neighbours and the tangle's own).
  std::size_t proximity_pairs = 0;
  int retries = 0;  ///< times the frame ran again (`Settings::motion_retries`)
  std::size_t vf = 0, ee = 0, tt = 0;  ///< contacts at the frame's end positions
  Scalar collision_share = 0;          ///< see `collision_share`
  /// Smallest VF/EE distance at the frame's end (infinity when there is no contact).
  Scalar min_distance = 0;
  Scalar obstacle_penetration = 0;  ///< deepest vertex inside an obstacle at the frame's end (m)
  int cg_iterations = 0;            ///< summed over the frame's steps (implicit Euler)
  int detections = 0;               ///< detector updates run for this frame
  std::size_t corrections = 0;      ///< response corrections applied over the frame's steps
  Scalar energy = 0;     ///< total mechanical energy at the frame's end (`compute_energy`, J)
  Scalar max_speed = 0;  ///< largest particle speed at the frame's end (m/s)
  /// Longest spring at the frame's end, as a multiple of its rest length (`longest_spring_ratio`).
  Scalar longest_spring = 0;
  Bounds bounds{Vec3::Zero(), Vec3::Zero()};  ///< box of the particles at the frame's end
  /// Intersecting triangle pairs (sharing no vertex) at the frame's end, by the exact `kdop`
  /// detector; -1 when not measured (response or `Settings::untangle` off). After a frame that
  /// started intersection-free (no such pair and no pinch pair, measured) with the built-in
  /// fail-safe it is 0 by the fail-safe's guarantee, without a query.
  std::int64_t intersecting_pairs = -1;
  /// Intersecting triangle pairs sharing exactly one vertex (a vertex's star passing through
  /// itself, a *pinch*), which `intersecting_pairs` leaves out; measured and inferred with it
  /// (-1 when it is). The mesh is intersection-free when both are 0.
  std::int64_t pinches = -1;
  std::size_t contours = 0;        ///< intersection contours at the frame's end
  std::size_t untangle_pulls = 0;  ///< pull-through and contour pushes over the frame's steps
  double untangle_ms = 0;          ///< intersection analysis and pushes
};

/// Share of mesh edges (0..1) in at least one contact: both edges of every EE contact and the
/// three sides of the face of every VF contact. 0 for a mesh without edges.
Scalar collision_share(const Topology& topology, const ContactSet& contacts);

class Simulation {
 public:
  Simulation(Model model, State state, ForceField field, std::vector<response::Obstacle> obstacles,
             Kinematics kinematics, Settings settings, std::int64_t first_frame = 0);

  /// Stats of the current state (the frame not yet advanced): contacts detected now, zero times
  /// except detection.
  FrameStats current_stats();
  /// Runs `substeps` steps, then detects at the new positions; returns the new frame's stats.
  /// Throws `DivergenceError` after restoring the frame's starting state when a step diverges.
  FrameStats advance_frame();
  /// One step (see the file comment).
  void step();

  const Model& model() const { return model_; }
  const State& state() const { return state_; }
  ForceField& field() { return field_; }
  const Settings& settings() const { return settings_; }
  std::int64_t frame() const { return frame_; }
  const std::vector<response::Obstacle>& obstacles() const { return obstacles_; }
  /// Contacts at the current positions (detected on demand).
  const ContactSet& contacts();

  /// The detector (read-only: its statistics, and for the stochastic one its kept pairs).
  const Detector& detector() const { return *detector_; }
  /// The detector's state across frames (`Detector::save_state`: empty for exact methods),
  /// saved with the simulation state so a resumed run detects bit for bit as the original.
  std::string detector_state() const { return detector_->save_state(); }
  /// Restores it; the next detection, on the same positions, replays the last one.
  void restore_detector_state(std::string_view text);
  /// Installs a custom end-of-frame fail-safe (see `FailSafe`) in place of the built-in one
  /// (`Settings::fail_safe`); empty = back to the built-in one, if on.
  void set_fail_safe(FailSafe fail_safe) { fail_safe_ = std::move(fail_safe); }

 private:
  void detect_now();
  bool per_frame() const {
    return settings_.response && settings_.response_model == ResponseModel::Proximity;
  }
  /// One frame of the Proximity model (see `ResponseModel`).
  void proximity_frame();
  /// The frame's steps, each followed by the obstacles and the proximity impulses of `stencils_`.
  void proximity_steps(const response::ProximityOptions& options);
  /// The contacts closer than h_c among the (wider) detected ones.
  void filter_contacts();
  /// `Settings::motion_search`: appends to `stencils_` the pairs that the frame's predicted
  /// motion brings within the detection radius and that were farther at the frame's start.
  void motion_search();
  /// `Settings::motion_retries`: appends to `stencils` the pairs of the motion from
  /// `frame_start` to the current positions that come within δ and were farther than the
  /// detection radius at the start, leaving out those in `retried_` (and adding them to it);
  /// returns how many it appended.
  std::size_t retry_search(PositionsView frame_start, std::vector<response::Stencil>& stencils);
  void obstacles_pass();
  /// One integration step of `settings_.dt` and the kinematics, timed as integration, with the
  /// untangler's pulls inside it when they act there; returns whether they did.
  bool integrate_step();
  /// Zeroes the figures accumulated over the current frame (times, fail-safe, motion, response
  /// and untangling counts; not `detections_`, which a frame undone by a divergence keeps).
  void clear_frame_figures();
  /// The custom or built-in fail-safe from `frame_start` to the current state (`proximity`:
  /// the frame's start detection, for the built-in one's first query).
  void run_fail_safe(PositionsView frame_start, const response::StartProximity* proximity = nullptr);
  /// Analyses the intersections at the current positions once (see `Settings::untangle`).
  void untangle_check();
  /// Installs the untangler's pulls as anchors of the next step when they act inside it;
  /// returns whether it did (`Settings::untangle_in_solve`).
  bool untangle_anchor();
  /// Pushes of the untangler after a step (no-op when clean or off); `pulls_moved`: the step
  /// held the pulls (`untangle_anchor`).
  void untangle_push(bool pulls_moved);
  /// Throws `DivergenceError` (frame being computed, step) when the state is not sane.
  void check_state(int step) const;
  FrameStats frame_stats();

  Model model_;
  State state_;
  ForceField field_;
  std::vector<response::Obstacle> obstacles_;
  Kinematics kinematics_;
  Settings settings_;
  std::int64_t frame_;
  Scalar initial_spread_ = 0;  ///< bounding-box diagonal of the particles at construction
  std::unique_ptr<Integrator> integrator_;
  std::unique_ptr<Detector> detector_;
  ContactSet contacts_;
  ContactSet close_;  ///< Proximity model: the detected contacts closer than h_c
  bool contacts_valid_ = false;
  /// The detector reports every VF and EE pair within its radius (Proximity model): the frame's
  /// start detection then restricts the fail-safe's first query (`response::StartProximity`).
  bool complete_detection_ = false;
  FailSafe fail_safe_;
  std::unique_ptr<response::CcdFailSafe> ccd_;  ///< built-in fail-safe (response and fail_safe on)
  response::FailSafeStats ccd_stats_;           ///< summed over the current frame
  std::unique_ptr<response::Untangler> untangler_;  ///< response and untangle on
  bool untangle_valid_ = false;  ///< the untangler's analysis is of the current positions
  bool known_clean_ = false;     ///< a frame started intersection-free with the built-in fail-safe
  std::int64_t intersecting_ = -1;
  std::int64_t pinches_ = -1;
  std::size_t untangle_pulls_ = 0;
  std::vector<response::PullMove> pull_moves_;
  std::vector<Anchor> anchors_;
  std::vector<Vec3> net_move_;         ///< per vertex, zero between calls
  std::vector<Scalar> longest_move_;   ///< per vertex, zero between calls
  std::vector<Index> touched_;
  double untangle_ms_ = 0;
  std::vector<response::Stencil> stencils_;
  std::vector<Scalar> contact_lambda_;  ///< `Settings::contact_forces`: one per stencil
  response::ContactForceScratch contact_scratch_;  ///< `update_contact_forces`' buffers
  /// `Settings::motion_search` (Proximity model with response on): its query over the
  /// predicted motion, its scratch, and its counts of the current frame.
  std::unique_ptr<ContinuousQuery> motion_query_;
  Positions predicted_, predicted_velocity_;
  std::vector<char> fast_;
  ImpactSet motion_impacts_;
  std::size_t motion_pairs_ = 0, motion_vertices_ = 0, flat_pairs_ = 0, proximity_pairs_ = 0;
  /// `Settings::motion_retries`: its query (min separation δ), and the pairs it added this frame.
  std::unique_ptr<ContinuousQuery> retry_query_;
  std::set<std::array<Index, 5>> retried_;
  int retries_ = 0;  ///< of the current frame
  // Accumulated over the current frame.
  double integrate_ms_ = 0, detect_ms_ = 0, response_ms_ = 0, ccd_ms_ = 0;
  int cg_iterations_ = 0;
  int detections_ = 0;
  std::size_t corrections_ = 0;
};

}  // namespace crumple::sim

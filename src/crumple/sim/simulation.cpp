#include <crumple/core/error.hpp>
#include <crumple/sim/simulation.hpp>

#include <crumple/core/parallel.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/exact_detector.hpp>
#include <crumple/geometry/distance.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>

namespace crumple::sim {

namespace {
using Clock = std::chrono::steady_clock;

Scalar mean_edge(const Topology& topology, PositionsView x) {
  return topology.num_edges() > 0 ? edge_length_stats(topology, x).mean : 0;
}

/// Drops the stencils of pairs inside the tangle being untangled (both sides in it).
void drop_tangled(std::vector<response::Stencil>& stencils, const response::Untangler* untangler) {
  if (!untangler || !untangler->tangled()) return;
  const auto tangle = untangler->tangle();
  std::erase_if(stencils, [&](const response::Stencil& s) { return response::touches_tangle_on_both_sides(s, tangle); });
}

/// Whether a detector of `method` with `options` reports every VF and EE pair closer than its
/// thickness at every update (the fail-safe's `StartProximity`): an exact method with both kinds
/// on, neither cut off by a time or pair budget nor truncated at `max_contacts`.
bool reports_every_pair(const MethodSpec& method, const DetectorOptions& options) {
  if (!method_info(method.method()).capabilities.exact || !options.kinds.vf || !options.kinds.ee) return false;
  if (method.method() == Method::Naive) return true;
  const ExactParams p = ExactParams::from_spec(method);
  return !p.cut_off() && (p.max_contacts == 0 || p.overflow_error);
}

/// Flags (`fast`) the vertices whose displacement `to` − `from` lies farther than `far` from the
/// mass-weighted mean displacement of the free vertices, and returns how many. Two points of a
/// pair with no flagged vertex move relative to each other by at most 2 `far` (their relative
/// motion is a convex combination of differences of displacements within `far` of the mean).
std::size_t flag_far_vertices(PositionsView from, PositionsView to, std::span<const Scalar> inv_mass, Scalar far,
                              std::vector<char>& fast) {
  const std::size_t n = from.size();
  Vec3 mean = Vec3::Zero();
  Scalar mass = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!(inv_mass[i] > 0)) continue;
    mean += (to[i] - from[i]) / inv_mass[i];
    mass += 1 / inv_mass[i];
  }
  if (mass > 0) mean /= mass;
  fast.assign(n, 0);
  std::size_t count = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if ((to[i] - from[i] - mean).squaredNorm() > far * far) {
      fast[i] = 1;
      ++count;
    }
  }
  return count;
}

/// Queries `query` for the motion `from` → `to` over the pairs holding a vertex flagged in
/// `fast` (`count` of them; the whole mesh when they are more than a quarter, whose swept k-DOP
/// tree is then cheaper than the one-sided query), into `impacts`, and calls `add` with the
/// stencil of each impact whose pair was `radius` or farther apart at `from` (a closer one is
/// the frame's detection's already): at its time of impact, its normal pointing from the side
/// the pair comes from (the proximity response refreshes weights and normal at every step,
/// keeping that side).
template <class Add>
void add_far_impacts(ContinuousQuery& query, PositionsView from, PositionsView to, const std::vector<char>& fast,
                     std::size_t count, std::span<const Face> faces, Scalar radius, ImpactSet& impacts, Add&& add) {
  if (4 * count > from.size()) {
    query.query(from, to, impacts);
  } else {
    query.query_moved(from, to, fast, impacts);
  }
  const Scalar radius2 = radius * radius;
  const auto p0 = [&](Index v) { return from[static_cast<std::size_t>(v)]; };
  for (const VertexFaceImpact& c : impacts.vf) {
    const Face& f = faces[static_cast<std::size_t>(c.face)];
    if (!(c.normal.squaredNorm() > 0) ||
        geometry::point_triangle(p0(c.vertex), p0(f[0]), p0(f[1]), p0(f[2])).sqr_distance < radius2) {
      continue;
    }
    add(response::vertex_face_stencil(c.vertex, f, c.barycentric, c.normal));
  }
  for (const EdgeEdgeImpact& c : impacts.ee) {
    if (!(c.normal.squaredNorm() > 0) ||
        geometry::segment_segment(p0(c.a[0]), p0(c.a[1]), p0(c.b[0]), p0(c.b[1])).sqr_distance < radius2) {
      continue;
    }
    add(response::edge_edge_stencil(c.a, c.b, c.s, c.t, c.normal));
  }
}

std::string number(Scalar v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}
}  // namespace

Scalar collision_share(const Topology& topo, const ContactSet& contacts) {
  const Index ne = topo.num_edges();
  if (ne == 0) return 0;
  std::vector<char> hit(static_cast<std::size_t>(ne), 0);
  for (const auto& c : contacts.ee) {
    hit[static_cast<std::size_t>(c.edge0)] = 1;
    hit[static_cast<std::size_t>(c.edge1)] = 1;
  }
  for (const auto& c : contacts.vf) {
    for (Index e : topo.face_edges(c.face)) hit[static_cast<std::size_t>(e)] = 1;
  }
  const auto count = std::count(hit.begin(), hit.end(), 1);
  return static_cast<Scalar>(count) / static_cast<Scalar>(ne);
}

Simulation::Simulation(Model model, State state, ForceField field,
                       std::vector<response::Obstacle> obstacles, Kinematics kinematics,
                       Settings settings, std::int64_t first_frame)
    : model_(std::move(model)),
      state_(std::move(state)),
      field_(field),
      obstacles_(std::move(obstacles)),
      kinematics_(std::move(kinematics)),
      settings_(std::move(settings)),
      frame_(first_frame) {
  CRUMPLE_CHECK(settings_.dt > 0, "time step must be > 0");
  CRUMPLE_CHECK(settings_.substeps >= 1, "substeps must be >= 1");
  CRUMPLE_CHECK(settings_.passes >= 1, "response passes must be >= 1");
  CRUMPLE_CHECK(state_.x.size() == static_cast<std::size_t>(model_.num_particles()) &&
                    state_.v.size() == state_.x.size(),
                "state must have #V positions and velocities");
  CRUMPLE_CHECK(settings_.max_spread_growth > 1, "max_spread_growth must be > 1");
  for (std::size_t i = 0; i < state_.x.size(); ++i) {
    if (!state_.x[i].allFinite() || !state_.v[i].allFinite()) {
      throw InputError("particle " + std::to_string(i) +
                       " starts with a non-finite position or velocity");
    }
  }
  integrator_ = make_integrator(settings_.integrator, settings_.integrator_options);
  if (!state_.x.empty()) initial_spread_ = compute_bounds(state_.x).diagonal();
  DetectorOptions detection = settings_.detector;
  CRUMPLE_CHECK(settings_.search_factor > 1, "search_factor must be > 1");
  CRUMPLE_CHECK(settings_.flat_neighbour_rings >= 0 && settings_.flat_neighbour_rings <= 2,
                "flat_neighbour_rings must be 0, 1 or 2");
  if (per_frame()) detection.thickness *= settings_.search_factor;  // see `ResponseModel`
  detector_ = make_detector(settings_.method, detection);
  detector_->set_topology(model_.topology_ptr());
  complete_detection_ = per_frame() && reports_every_pair(settings_.method, detection);
  if (per_frame() && settings_.motion_search) {
    ContinuousOptions options;
    options.min_separation = settings_.detector.thickness;
    options.threads = settings_.detector.threads;
    motion_query_ = std::make_unique<ContinuousQuery>(model_.topology_ptr(), options);
  }
  CRUMPLE_CHECK(settings_.fail_safe_separation >= 0 && std::isfinite(settings_.fail_safe_separation),
                "fail_safe_separation must be finite and >= 0");
  CRUMPLE_CHECK(settings_.motion_retries >= 0, "motion_retries must be >= 0");
  CRUMPLE_CHECK(settings_.proximity_relaxation > 0 && settings_.proximity_relaxation <= 1,
                "proximity_relaxation must be in (0, 1]");
  if (per_frame() && settings_.fail_safe && settings_.motion_retries > 0) {
    ContinuousOptions options;
    options.min_separation = settings_.fail_safe_separation * settings_.detector.thickness;
    options.threads = settings_.detector.threads;
    retry_query_ = std::make_unique<ContinuousQuery>(model_.topology_ptr(), options);
  }
  if (settings_.response && settings_.fail_safe) {
    response::FailSafeOptions options;
    options.min_separation = settings_.fail_safe_separation * settings_.detector.thickness;
    options.query.threads = settings_.detector.threads;
    ccd_ = std::make_unique<response::CcdFailSafe>(model_.topology_ptr(), options);
  }
  CRUMPLE_CHECK(settings_.untangle_step > 0 && std::isfinite(settings_.untangle_step),
                "untangle_step must be finite and > 0");
  CRUMPLE_CHECK(settings_.contour_step >= 0 && std::isfinite(settings_.contour_step),
                "contour_step must be finite and >= 0");
  CRUMPLE_CHECK(settings_.border_step >= 0 && std::isfinite(settings_.border_step),
                "border_step must be finite and >= 0");
  CRUMPLE_CHECK(settings_.untangle_pull_stiffness > 0 && std::isfinite(settings_.untangle_pull_stiffness),
                "untangle_pull_stiffness must be finite and > 0");
  if (settings_.response && settings_.untangle) {
    response::UntangleOptions options;
    const Scalar h = settings_.detector.thickness;
    options.thickness = h;
    // A zero thickness still needs a step: a tenth of the mean edge length stands in for h.
    const Scalar unit = h > 0 ? h : 0.1 * mean_edge(model_.topology(), state_.x);
    options.max_step = settings_.untangle_step * unit;
    options.contour_step = settings_.contour_step * unit;
    options.border_step = settings_.border_step * unit;
    options.threads = settings_.detector.threads;
    if (options.max_step > 0) untangler_ = std::make_unique<response::Untangler>(model_.topology_ptr(), options);
  }
}

void Simulation::untangle_check() {
  if (!untangler_ || untangle_valid_) return;
  untangle_valid_ = true;
  if (known_clean_ && ccd_ && !fail_safe_) {
    intersecting_ = pinches_ = 0;
    return;
  }
  const auto start = Clock::now();
  intersecting_ = static_cast<std::int64_t>(untangler_->analyse(state_.x, model_.inv_mass()));
  pinches_ = static_cast<std::int64_t>(untangler_->pinch_pairs());
  if (ccd_) ccd_->set_tangle(untangler_->tangled() ? untangler_->tangle() : std::span<const char>{});
  known_clean_ = !untangler_->tangled() && ccd_ && !fail_safe_;
  untangle_ms_ += ms_since(start);
}

bool Simulation::untangle_anchor() {
  if (!untangler_ || !untangler_->tangled() || !settings_.untangle_in_solve || !integrator_->takes_anchors()) {
    return false;
  }
  const auto start = Clock::now();
  pull_moves_.clear();
  untangle_pulls_ += untangler_->pull_moves(model_.inv_mass(), state_.x, pull_moves_);
  anchors_.clear();
  // One anchor per vertex, along its pulls' net move (their sum, no longer than the longest):
  // opposed pulls of one vertex cancel as they do when applied one after the other, instead of
  // holding it between their targets.
  const std::size_t n = state_.x.size();
  net_move_.resize(n, Vec3::Zero());
  longest_move_.resize(n, 0);
  touched_.clear();
  for (const response::PullMove& m : pull_moves_) {
    const auto i = static_cast<std::size_t>(m.vertex);
    if (longest_move_[i] == 0) touched_.push_back(m.vertex);
    net_move_[i] += m.offset * m.direction;
    longest_move_[i] = std::max(longest_move_[i], std::abs(m.offset));
  }
  for (Index v : touched_) {
    const auto i = static_cast<std::size_t>(v);
    const Scalar length = net_move_[i].norm();
    if (length > 0) anchors_.push_back({v, net_move_[i] / length, std::min(length, longest_move_[i])});
    net_move_[i] = Vec3::Zero();
    longest_move_[i] = 0;
  }
  integrator_->set_anchors(anchors_, settings_.untangle_pull_stiffness);
  untangle_ms_ += ms_since(start);
  return true;
}

void Simulation::untangle_push(bool pulls_moved) {
  if (!untangler_ || !untangler_->tangled()) return;
  const auto start = Clock::now();
  const response::UntangleStats stats = untangler_->apply(model_.inv_mass(), state_.x, state_.v, pulls_moved);
  untangle_pulls_ += stats.pulls + stats.contour_moves;
  untangle_ms_ += ms_since(start);
}

void Simulation::run_fail_safe(PositionsView frame_start, const response::StartProximity* proximity) {
  const auto start = Clock::now();
  if (fail_safe_) {
    fail_safe_(frame_start, state_);
  } else if (ccd_) {
    const Scalar duration = settings_.dt * settings_.substeps;
    // The fail-safe may leave a vertex inside an obstacle: the obstacles then get their turn
    // and the fail-safe checks their moves, up to kObstacleRounds times; the fail-safe always
    // has the last word (self-intersection first, obstacle penetration second).
    constexpr int kObstacleRounds = 3;
    for (int round = 0; round < kObstacleRounds; ++round) {
      const response::FailSafeStats s =
          ccd_->apply(frame_start, model_.inv_mass(), duration, state_.x, state_.v, round == 0 ? proximity : nullptr);
      ccd_stats_.queries += s.queries;
      if (round == 0) {
        ccd_stats_.impacts += s.impacts;
        ccd_stats_.first_restricted = s.first_restricted;
      }
      ccd_stats_.zone_vertices += s.zone_vertices;
      ccd_stats_.frozen += s.frozen;
      if (s.impacts == 0 || obstacles_.empty() || round + 1 == kObstacleRounds) break;
      bool inside = false;
      for (const auto& o : obstacles_) {
        inside = inside || response::max_penetration(o, state_.time, state_.x) > 0;
      }
      if (!inside) break;
      obstacles_pass();
    }
  }
  ccd_ms_ += ms_since(start);
}

void Simulation::detect_now() {
  const auto start = Clock::now();
  detector_->update(state_.x, contacts_);
  ++detections_;
  if (per_frame()) filter_contacts();
  contacts_valid_ = true;
  detect_ms_ += ms_since(start);
}

void Simulation::filter_contacts() {
  const Scalar h = settings_.detector.thickness;
  close_.vf.clear();
  close_.ee.clear();
  close_.tt = contacts_.tt;
  for (const auto& c : contacts_.vf) {
    if (c.distance < h) close_.vf.push_back(c);
  }
  for (const auto& c : contacts_.ee) {
    if (c.distance < h) close_.ee.push_back(c);
  }
}

void Simulation::motion_search() {
  if (!motion_query_) return;
  const auto start = Clock::now();
  // The predicted motion: x + H v, projected out of the obstacles, which stop what they would
  // stop (a layer landing on the floor is predicted to stay there, so a layer falling onto it is
  // predicted to close in). A pair whose vertices' predicted displacements uᵢ all lie within
  // s/2 of a common ū (s = R − h_c, the detection radius R's slack) changes its distance by at
  // most s over that motion (the relative motion of two of its points is a convex combination
  // of differences uᵢ − uⱼ), so if it comes within h_c it was within R at the start: the
  // detection has it. Only the pairs with a vertex farther than s/2 from ū (the mass-weighted
  // mean, which a cloth moving as one leaves alone) can be missed.
  const Scalar duration = settings_.dt * settings_.substeps;
  const Scalar h = settings_.detector.thickness;
  const Scalar radius = settings_.search_factor * h;
  const auto inv_mass = model_.inv_mass();
  const std::size_t n = state_.x.size();
  predicted_.resize(n);
  for (std::size_t i = 0; i < n; ++i) predicted_[i] = state_.x[i] + duration * state_.v[i];
  if (!obstacles_.empty()) {
    predicted_velocity_.assign(state_.v.begin(), state_.v.end());
    response::resolve_obstacles(obstacles_, state_.time + duration, inv_mass, predicted_, predicted_velocity_,
                                settings_.detector.threads);
  }
  const std::size_t count = flag_far_vertices(PositionsView(state_.x.data(), n), PositionsView(predicted_.data(), n),
                                              inv_mass, 0.5 * (radius - h), fast_);
  motion_vertices_ += count;
  if (count == 0) {
    detect_ms_ += ms_since(start);
    return;
  }
  // The pairs with a fast vertex that come within h_c over the predicted motion; those it adds
  // with no fast vertex (the whole-mesh query) were within R at the start (above) and are
  // dropped with the detection's own.
  const std::size_t before = stencils_.size();
  add_far_impacts(*motion_query_, state_.x, predicted_, fast_, count, model_.topology().faces(), radius,
                  motion_impacts_, [&](const response::Stencil& st) { stencils_.push_back(st); });
  motion_pairs_ += stencils_.size() - before;
  detect_ms_ += ms_since(start);
}

std::size_t Simulation::retry_search(PositionsView frame_start, std::vector<response::Stencil>& stencils) {
  const auto start = Clock::now();
  // As `motion_search`, with the frame's proposed motion itself: a pair whose vertices'
  // displacements all lie within s/2 of the mean ū (s = R − δ) changes its distance by at most
  // s, so if it comes within δ it was within R at the start, and the frame's detection has it.
  const Scalar delta = retry_query_->options().min_separation;
  const Scalar radius = settings_.search_factor * settings_.detector.thickness;
  const auto inv_mass = model_.inv_mass();
  const auto& x = state_.x;
  const std::size_t n = x.size();
  const std::size_t count =
      flag_far_vertices(frame_start, PositionsView(x.data(), n), inv_mass, 0.5 * (radius - delta), fast_);
  std::size_t added = 0;
  if (count > 0) {
    add_far_impacts(*retry_query_, frame_start, PositionsView(x.data(), n), fast_, count, model_.topology().faces(),
                    radius, motion_impacts_, [&](const response::Stencil& st) {
                      const std::array<Index, 5> key{st.vertex[0], st.vertex[1], st.vertex[2], st.vertex[3],
                                                     st.edge_edge ? 1 : 0};
                      if (!retried_.insert(key).second) return;
                      stencils.push_back(st);
                      ++added;
                    });
  }
  motion_pairs_ += added;
  detect_ms_ += ms_since(start);
  return added;
}

void Simulation::proximity_steps(const response::ProximityOptions& options) {
  const bool forces = settings_.contact_forces && integrator_->takes_contact_forces();
  if (forces) {
    // The multipliers start at 0 with the frame's contacts and carry over its steps.
    contact_lambda_.assign(stencils_.size(), 0);
    response::ContactForceOptions force_options;
    force_options.thickness = options.thickness;
    force_options.relaxation = options.relaxation;
    integrator_->set_contact_forces([this, force_options](std::span<const Vec3> x, std::span<const Scalar> diagonal,
                                                          const ContactSolve& solve, std::span<Vec3> force) {
      response::update_contact_forces(stencils_, x, diagonal, solve, force_options, contact_lambda_, force,
                                      contact_scratch_);
    });
  }
  // The integrator keeps no reference to this frame's stencils once the steps are done (or one
  // of them threw).
  struct Unset {
    Integrator* integrator;
    bool on;
    ~Unset() {
      if (on) integrator->set_contact_forces({});
    }
  } unset{integrator_.get(), forces};
  for (int k = 0; k < settings_.substeps; ++k) {
    const bool anchored = integrate_step();
    const auto start = Clock::now();
    obstacles_pass();
    // Each stencil's refresh reads positions only: the same bits on any number of threads.
    parallel_for_chunks(stencils_.size(), settings_.detector.threads,
                        balanced_grain(stencils_.size(), resolve_threads(settings_.detector.threads), 256, 4096),
                        [&](std::size_t begin, std::size_t end) {
                          response::refresh_stencils(std::span(stencils_).subspan(begin, end - begin), state_.x);
                        });
    const response::ResponseStats stats =
        response::resolve_proximity(stencils_, model_.inv_mass(), state_.x, state_.v, options);
    corrections_ += stats.corrections;
    if (!obstacles_.empty() && stats.corrections > 0) obstacles_pass();
    response_ms_ += ms_since(start);
    untangle_push(anchored);
    check_state(k + 1);
  }
}

void Simulation::proximity_frame() {
  if (!contacts_valid_) detect_now();
  untangle_check();
  const Positions frame_start = state_.x;
  retried_.clear();
  auto start = Clock::now();
  stencils_ = response::make_stencils(contacts_, model_.topology().faces());
  // The flat neighbours keep the radius 2 h_c; with no larger radius there is nothing to drop.
  if (settings_.flat_neighbour_rings > 0 && settings_.search_factor > kFlatNeighbourSearch) {
    response::FlatNeighbourOptions flat;
    flat.rings = settings_.flat_neighbour_rings;
    flat.keep_within = kFlatNeighbourSearch * settings_.detector.thickness;
    flat.threads = settings_.detector.threads;
    flat_pairs_ += response::drop_flat_neighbours(stencils_, model_.topology(), state_.x, flat);
  }
  response_ms_ += ms_since(start);
  motion_search();
  start = Clock::now();
  drop_tangled(stencils_, untangler_.get());
  proximity_pairs_ += stencils_.size();
  response_ms_ += ms_since(start);
  response::ProximityOptions options;
  options.thickness = settings_.detector.thickness;
  options.friction = settings_.self_friction;
  options.passes = settings_.passes;
  options.relaxation = settings_.proximity_relaxation;
  if (!retry_query_ || (untangler_ && untangler_->tangled())) {
    proximity_steps(options);
  } else {
    // `Settings::motion_retries` (not while untangling: the untangler's pushes follow its
    // analysis of the frame's start, which a rerun would not repeat).
    const State frame_state = state_;
    for (int attempt = 0;; ++attempt) {
      std::vector<response::Stencil> next = stencils_;  // the steps refresh the stencils
      proximity_steps(options);
      if (attempt >= settings_.motion_retries || retry_search(frame_start, next) == 0) break;
      ++retries_;
      state_ = frame_state;
      stencils_ = std::move(next);
    }
  }
  // The frame's detection, at its start, is the fail-safe's proximity when it is complete.
  response::StartProximity proximity;
  proximity.radius = detector_->options().thickness;
  proximity.pairs = &contacts_;
  run_fail_safe(frame_start, ccd_ && complete_detection_ ? &proximity : nullptr);
  contacts_valid_ = false;
  untangle_valid_ = false;
}

void Simulation::restore_detector_state(std::string_view text) {
  detector_->load_state(text);
  contacts_valid_ = false;
}

const ContactSet& Simulation::contacts() {
  if (!contacts_valid_) detect_now();
  return per_frame() ? close_ : contacts_;
}

void Simulation::obstacles_pass() {
  response::resolve_obstacles(obstacles_, state_.time, model_.inv_mass(), state_.x, state_.v,
                              settings_.detector.threads);
}

bool Simulation::integrate_step() {
  const bool anchored = untangle_anchor();
  // The integrator keeps no anchor past this step (nor past a step that threw).
  struct Unset {
    Integrator* integrator;
    bool on;
    ~Unset() {
      if (on) integrator->set_anchors({}, 0);
    }
  } unset{integrator_.get(), anchored};
  const auto start = Clock::now();
  integrator_->step(model_, field_, state_, settings_.dt);
  cg_iterations_ += integrator_->last_iterations();
  if (kinematics_) kinematics_(state_);
  integrate_ms_ += ms_since(start);
  return anchored;
}

void Simulation::step() {
  if (settings_.response && !contacts_valid_) detect_now();
  const bool anchored = integrate_step();

  auto start = Clock::now();
  obstacles_pass();
  if (settings_.response) {
    stencils_ = response::make_stencils(contacts_, model_.topology().faces());
    drop_tangled(stencils_, untangler_.get());
    response::ResponseOptions options;
    options.thickness = settings_.detector.thickness;
    options.passes = settings_.passes;
    const response::ResponseStats stats =
        response::resolve(stencils_, model_.inv_mass(), state_.x, state_.v, options);
    corrections_ += stats.corrections;
    if (!obstacles_.empty() && stats.corrections > 0) obstacles_pass();
  }
  response_ms_ += ms_since(start);
  if (settings_.response) untangle_push(anchored);
  contacts_valid_ = false;
  untangle_valid_ = false;
}

void Simulation::check_state(int step) const {
  const std::int64_t frame = frame_ + 1;
  const auto fail = [&](const std::string& what) {
    throw DivergenceError("the simulation diverged at frame " + std::to_string(frame) + " (step " +
                              std::to_string(step) + " of " + std::to_string(settings_.substeps) +
                              "): " + what,
                          frame, step);
  };
  Scalar max_speed2 = 0;
  for (std::size_t i = 0; i < state_.x.size(); ++i) {
    if (!state_.x[i].allFinite() || !state_.v[i].allFinite()) {
      fail("particle " + std::to_string(i) + " has a non-finite position or velocity");
    }
    max_speed2 = std::max(max_speed2, state_.v[i].squaredNorm());
  }
  if (!(initial_spread_ > 0)) return;
  const Scalar step_length = std::sqrt(max_speed2) * settings_.dt;
  if (step_length > initial_spread_) {
    fail("a particle moves " + number(step_length) + " m in one step, more than the mesh's size (" +
         number(initial_spread_) + " m)");
  }
  const Scalar spread = compute_bounds(state_.x).diagonal();
  if (spread > settings_.max_spread_growth * initial_spread_) {
    fail("the particles spread over " + number(spread) + " m, " +
         number(spread / initial_spread_) + " times their initial extent");
  }
}

FrameStats Simulation::frame_stats() {
  if (!contacts_valid_) detect_now();
  FrameStats s;
  s.frame = frame_;
  s.time = state_.time;
  s.integrate_ms = integrate_ms_;
  s.detect_ms = detect_ms_;
  s.response_ms = response_ms_;
  s.ccd_ms = ccd_ms_;
  s.ccd_impacts = ccd_stats_.impacts;
  s.ccd_queries = ccd_stats_.queries;
  s.ccd_zone_vertices = ccd_stats_.zone_vertices;
  s.ccd_frozen = ccd_stats_.frozen;
  s.ccd_first_restricted = ccd_stats_.first_restricted;
  s.motion_pairs = motion_pairs_;
  s.motion_vertices = motion_vertices_;
  s.flat_pairs = flat_pairs_;
  s.proximity_pairs = proximity_pairs_;
  s.retries = retries_;
  const ContactSet& seen = per_frame() ? close_ : contacts_;
  s.vf = seen.vf.size();
  s.ee = seen.ee.size();
  s.tt = seen.tt.size();
  s.collision_share = collision_share(model_.topology(), seen);
  s.min_distance = std::numeric_limits<Scalar>::infinity();
  for (const auto& c : seen.vf) s.min_distance = std::min(s.min_distance, c.distance);
  for (const auto& c : seen.ee) s.min_distance = std::min(s.min_distance, c.distance);
  for (const auto& o : obstacles_) {
    s.obstacle_penetration = std::max(s.obstacle_penetration, response::max_penetration(o, state_.time, state_.x));
  }
  untangle_check();
  s.intersecting_pairs = intersecting_;
  s.pinches = pinches_;
  if (untangler_ && !known_clean_) s.contours = untangler_->analysis().contours.size();
  s.untangle_pulls = untangle_pulls_;
  s.untangle_ms = untangle_ms_;
  s.cg_iterations = cg_iterations_;
  s.detections = detections_;
  s.corrections = corrections_;
  s.energy = compute_energy(model_, field_, state_).total();
  for (const Vec3& v : state_.v) s.max_speed = std::max(s.max_speed, v.norm());
  s.longest_spring = longest_spring_ratio(model_, state_.x);
  if (!state_.x.empty()) s.bounds = compute_bounds(state_.x);
  clear_frame_figures();
  detections_ = 0;
  return s;
}

void Simulation::clear_frame_figures() {
  integrate_ms_ = detect_ms_ = response_ms_ = ccd_ms_ = untangle_ms_ = 0;
  ccd_stats_ = {};
  motion_pairs_ = motion_vertices_ = flat_pairs_ = proximity_pairs_ = 0;
  retries_ = 0;
  cg_iterations_ = 0;
  corrections_ = 0;
  untangle_pulls_ = 0;
}

FrameStats Simulation::current_stats() { return frame_stats(); }

FrameStats Simulation::advance_frame() {
  const State start = state_;
  try {
    if (per_frame()) {
      proximity_frame();
    } else {
      if (settings_.response) untangle_check();
      for (int k = 0; k < settings_.substeps; ++k) {
        step();
        check_state(k + 1);
      }
      if (settings_.response) {
        run_fail_safe(start.x);
        contacts_valid_ = false;
      }
    }
  } catch (const DivergenceError&) {  // the frame is undone: the state stays the last good one
    state_ = start;
    contacts_valid_ = false;
    clear_frame_figures();
    throw;
  }
  ++frame_;
  return frame_stats();
}

}  // namespace crumple::sim

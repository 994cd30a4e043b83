#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/detect/budget_spec_detail.hpp>
#include <crumple/detect/narrow_phase.hpp>
#include <crumple/detect/stochastic.hpp>
#include <crumple/detect/stochastic_engine.hpp>
#include <crumple/detect/stochastic_pairs_detail.hpp>
#include <crumple/geometry/distance.hpp>
#include <crumple/geometry/kdop.hpp>
#include <crumple/geometry/triangle_intersection.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <string>

namespace crumple {

// ---------------------------------------------------------------------------------------------
// Names and parameters

std::string_view to_string(StochasticVariant variant) {
  switch (variant) {
    case StochasticVariant::Simple: return "simple";
    case StochasticVariant::PropagateByConvergence: return "propagate-by-convergence";
    case StochasticVariant::Direct: return "direct";
    case StochasticVariant::Vertex: return "vertex";
  }
  return "?";
}

std::string_view to_string(Propagation propagation) {
  switch (propagation) {
    case Propagation::None: return "none";
    case Propagation::Linear: return "linear";
    case Propagation::Full: return "full";
  }
  return "?";
}

std::string_view to_string(PairType type) {
  switch (type) {
    case PairType::VV: return "vv";
    case PairType::EE: return "ee";
    case PairType::VF: return "vf";
    case PairType::EF: return "ef";
  }
  return "?";
}

Propagation default_propagation(StochasticVariant variant) {
  return variant == StochasticVariant::Simple ? Propagation::Full : Propagation::Linear;
}

StochasticParams StochasticParams::from_spec(const MethodSpec& spec) {
  const auto fail = [&](const std::string& message) {
    throw InputError("method " + spec.to_string() + ": " + message);
  };
  StochasticParams p;
  const long long setting = spec.get_int("setting", 0);
  if (setting < 0 || setting > 2) fail("setting must be 0 (none), 1 or 2, got " + std::to_string(setting));

  static constexpr std::array<std::string_view, 4> kVariants{"simple", "propagate-by-convergence",
                                                             "direct", "vertex"};
  const std::string variant = spec.get_choice("variant", "direct", kVariants);
  if (variant == "simple") p.variant = StochasticVariant::Simple;
  if (variant == "propagate-by-convergence") p.variant = StochasticVariant::PropagateByConvergence;
  if (variant == "direct") p.variant = StochasticVariant::Direct;
  if (variant == "vertex") p.variant = StochasticVariant::Vertex;

  static constexpr std::array<std::string_view, 4> kPropagation{"auto", "none", "linear", "full"};
  const std::string prop = spec.get_choice("propagation", "auto", kPropagation);
  if (prop == "auto") {
    p.propagation = setting == 2 ? Propagation::None : default_propagation(p.variant);
  } else if (prop == "none") {
    p.propagation = Propagation::None;
  } else if (prop == "linear") {
    p.propagation = Propagation::Linear;
  } else {
    p.propagation = Propagation::Full;
  }

  const long long active = spec.get_int("active", setting == 1 ? 10 : 100);
  if (active < 1 || active > 100'000'000) fail("active must be in [1, 1e8], got " + std::to_string(active));
  p.active = static_cast<int>(active);
  const long long draw = spec.get_int("draw", 0);
  if (draw < 0 || draw > 100'000'000) fail("draw must be in [0, 1e8] (0 = active), got " + std::to_string(draw));
  p.draw = draw == 0 ? p.active : static_cast<int>(draw);
  p.near = spec.get_double("near", 2.0);
  if (!(std::isfinite(p.near) && p.near >= 1)) fail("near must be a finite multiple >= 1 of the thickness");
  const long long steps = spec.get_int("steps", 16);
  if (steps < 1 || steps > 100'000'000) fail("steps must be in [1, 1e8], got " + std::to_string(steps));
  p.steps = static_cast<int>(steps);
  p.ef = spec.get_bool("ef", false);
  const long long seed = spec.get_int("seed", 1);
  if (seed < 0) fail("seed must be >= 0");
  p.seed = static_cast<std::uint64_t>(seed);
  const BudgetSpec budget = budget_from_spec(spec);
  p.budget_ms = budget.budget_ms;
  p.clock = budget.clock;
  return p;
}

std::string StochasticParams::to_string() const {
  char near_text[32];
  std::snprintf(near_text, sizeof near_text, "%g", near);
  return "stochastic:variant=" + std::string(crumple::to_string(variant)) +
         ",active=" + std::to_string(active) + ",draw=" + std::to_string(draw) +
         ",propagation=" + std::string(crumple::to_string(propagation)) + ",near=" + near_text +
         ",steps=" + std::to_string(steps) + ",ef=" + (ef ? "on" : "off") +
         ",seed=" + std::to_string(seed) + (budget_ms > 0 ? ",budget=" + json_number(budget_ms) : "") +
         (clock == BudgetClock::cpu ? ",clock=cpu" : "");
}

// ---------------------------------------------------------------------------------------------
// Zone tests of the vertex variant; the pair traits are in stochastic_pairs_detail.hpp.

namespace {

using stochastic_detail::EngineConfig;
using stochastic_detail::EngineStats;
using stochastic_detail::PairEngine;
using stochastic_detail::PairTable;
using stochastic_detail::pair_key;
using stochastic_detail::Verdict;

using stochastic_detail::Context;
using stochastic_detail::EETraits;
using stochastic_detail::EFTraits;
using stochastic_detail::Sink;
using stochastic_detail::VFTraits;
using stochastic_detail::VVTraits;
using stochastic_detail::ZoneTester;

}  // namespace

namespace stochastic_detail {

const geometry::Kdop<18>& ZoneTester::kdop(const Context& ctx, Index f) {
  const auto i = static_cast<std::size_t>(f);
  if (kdop_gen_[i] != gen_) {
    const Face& t = ctx.topo.face(f);
    kdops_[i] = Kdop::from_triangle(at(ctx.x, t[0]), at(ctx.x, t[1]), at(ctx.x, t[2]));
    kdop_gen_[i] = gen_;
  }
  return kdops_[i];
}

/// Smallest squared distance among the enabled sub-pairs of faces fa, fb (0 when they
/// intersect and TT is asked), +inf when the k-DOP pre-test shows they are farther than near.
Scalar ZoneTester::face_pair(Context& ctx, Index fa, Index fb) {
  const std::uint64_t k = pair_key(std::min(fa, fb), std::max(fa, fb));
  if (const double* d = face_pairs_.find(k)) {
    ++ctx.zone_stats.cache_hits;
    return *d;
  }
  ++ctx.zone_stats.face_pairs;
  constexpr Scalar kInf = std::numeric_limits<Scalar>::infinity();
  Scalar best = kInf;
  Kdop grown = kdop(ctx, fa);
  grown.inflate(ctx.near);
  if (!grown.overlaps(kdop(ctx, fb))) {
    ++ctx.zone_stats.kdop_rejects;
    face_pairs_.insert(k, best);
    return best;
  }
  const Topology& topo = ctx.topo;
  const Face& A = topo.face(fa);
  const Face& B = topo.face(fb);
  const ContactKinds& kinds = ctx.sink.kinds();
  const auto vf = [&](Index v, Index f) {
    if (topo.face_has_vertex(f, v)) return;
    const std::uint64_t key = pair_key(v, f);
    Scalar d;
    if (const double* cached = vf_.find(key)) {
      ++ctx.zone_stats.cache_hits;
      d = *cached;
    } else {
      ++ctx.zone_stats.distance_evals;
      d = vertex_face_sqr(ctx, v, f);
      vf_.insert(key, d);
      if (d < ctx.h2) ctx.sink.add_vf(v, f);
    }
    best = std::min(best, d);
  };
  const auto ee = [&](Index e0, Index e1) {
    if (topo.edges_adjacent(e0, e1)) return;
    if (e1 < e0) std::swap(e0, e1);
    const std::uint64_t key = pair_key(e0, e1);
    Scalar d;
    if (const double* cached = ee_.find(key)) {
      ++ctx.zone_stats.cache_hits;
      d = *cached;
    } else {
      ++ctx.zone_stats.distance_evals;
      d = segment_sqr(ctx, e0, e1);
      ee_.insert(key, d);
      if (d < ctx.h2) ctx.sink.add_ee(e0, e1);
    }
    best = std::min(best, d);
  };
  if (kinds.vf) {
    for (const Index v : A) vf(v, fb);
    for (const Index v : B) vf(v, fa);
  }
  if (kinds.ee) {
    for (const Index e0 : topo.face_edges(fa)) {
      for (const Index e1 : topo.face_edges(fb)) ee(e0, e1);
    }
  }
  if (kinds.tt && !topo.faces_adjacent(fa, fb) && kdop(ctx, fa).overlaps(kdop(ctx, fb)) &&
      ctx.sink.add_tt(fa, fb)) {
    best = 0;
  }
  face_pairs_.insert(k, best);
  return best;
}

Verdict ZoneTester::zone(Context& ctx, Index a, Index b) {
  ++ctx.zone_stats.zone_tests;
  Scalar best = std::numeric_limits<Scalar>::infinity();
  for (const Index fa : ctx.topo.vertex_faces()[a]) {
    for (const Index fb : ctx.topo.vertex_faces()[b]) {
      if (fa != fb) best = std::min(best, face_pair(ctx, fa, fb));
    }
  }
  return {best < ctx.h2, best <= ctx.near2};
}

}  // namespace stochastic_detail

namespace {

void add_stats(DetectorStats& out, std::string_view prefix, const EngineStats& s, bool zone) {
  const auto put = [&](std::string_view name, double value) {
    out.add(std::string(prefix) + std::string(name), value);
  };
  put("drawn", s.drawn);
  put("kept", s.kept);
  put("deleted", s.deleted);
  put("duplicates", s.duplicates);
  put("converge_steps", s.converge_steps);
  put("distance_evals", s.distance_evals);
  put("cache_hits", s.cache_hits);
  put("propagation_visits", s.propagation_visits);
  put("colliding", s.colliding);
  put("walking", s.walking);
  if (s.carried > 0) put("carried", s.carried);
  if (zone) {
    put("zone_tests", s.zone_tests);
    put("face_pairs", s.face_pairs);
    put("kdop_rejects", s.kdop_rejects);
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// The detector

struct StochasticDetector::Impl {
  PairEngine<VVTraits, Context> vv;
  PairEngine<EETraits, Context> ee;
  PairEngine<VFTraits, Context> vf;
  PairEngine<EFTraits, Context> ef;
  Sink sink;
  ZoneTester zone;
  std::mt19937_64 rng;
  /// The state before the last update (`save_state`).
  std::mt19937_64 saved_rng;
  std::array<std::vector<PrimitivePair>, 4> saved_near, saved_walking;
  bool saved = false;

  /// `get(engine)` of the engine of `type`: one of its pair lists.
  template <class Get>
  std::span<const PrimitivePair> list(PairType type, Get get) const {
    switch (type) {
      case PairType::VV: return get(vv);
      case PairType::EE: return get(ee);
      case PairType::VF: return get(vf);
      case PairType::EF: return get(ef);
    }
    return {};
  }
};

StochasticDetector::StochasticDetector(DetectorOptions options, StochasticParams params)
    : Detector(options), params_(params), impl_(std::make_unique<Impl>()) {
  if (params_.active < 1 || params_.draw < 0 || params_.steps < 1 ||
      !(std::isfinite(params_.near) && params_.near >= 1) || !(params_.budget_ms >= 0)) {
    throw InputError("stochastic: invalid parameters " + params_.to_string() +
                     " (active >= 1, draw >= 0, steps >= 1, near >= 1, budget >= 0)");
  }
}

StochasticDetector::~StochasticDetector() = default;

bool StochasticDetector::runs(PairType type) const {
  const ContactKinds& k = options().kinds;
  const bool vertex = params_.variant == StochasticVariant::Vertex;
  switch (type) {
    case PairType::VV: return vertex && (k.vf || k.ee || k.tt);
    case PairType::EE: return !vertex && k.ee;
    case PairType::VF: return !vertex && k.vf;
    case PairType::EF: return !vertex && (params_.ef || k.tt);
  }
  return false;
}

std::span<const PrimitivePair> StochasticDetector::near_pairs(PairType type) const {
  return impl_->list(type, [](const auto& engine) { return std::span(engine.near_pairs()); });
}

std::span<const PrimitivePair> StochasticDetector::walking_pairs(PairType type) const {
  return impl_->list(type, [](const auto& engine) { return std::span(engine.walking_pairs()); });
}

std::span<const PrimitivePair> StochasticDetector::colliding_pairs(PairType type) const {
  return impl_->list(type, [](const auto& engine) { return std::span(engine.colliding_pairs()); });
}

void StochasticDetector::on_topology() {
  impl_->vv.reset();
  impl_->ee.reset();
  impl_->vf.reset();
  impl_->ef.reset();
  impl_->zone.reset(topology().num_faces());
  impl_->rng.seed(params_.seed);
  impl_->saved = false;
}

namespace {

constexpr std::array<PairType, 4> kPairTypes{PairType::VV, PairType::EE, PairType::VF, PairType::EF};

/// Number of elements of each side of a pair type.
std::pair<Index, Index> pair_counts(const Topology& t, PairType type) {
  switch (type) {
    case PairType::VV: return {t.num_vertices(), t.num_vertices()};
    case PairType::EE: return {t.num_edges(), t.num_edges()};
    case PairType::VF: return {t.num_vertices(), t.num_faces()};
    case PairType::EF: return {t.num_edges(), t.num_faces()};
  }
  return {0, 0};
}

}  // namespace

std::string StochasticDetector::save_state() const {
  const Impl& m = *impl_;
  std::ostringstream out;
  out << "stochastic-state-2 " << params_.to_string() << " rng " << (m.saved ? m.saved_rng : m.rng);
  const auto put = [&](std::span<const PrimitivePair> pairs) {
    out << " " << pairs.size();
    for (const PrimitivePair& p : pairs) out << " " << p.a << " " << p.b;
  };
  for (std::size_t i = 0; i < kPairTypes.size(); ++i) {
    out << " " << to_string(kPairTypes[i]);
    put(m.saved ? std::span<const PrimitivePair>(m.saved_near[i]) : near_pairs(kPairTypes[i]));
    put(m.saved ? std::span<const PrimitivePair>(m.saved_walking[i]) : walking_pairs(kPairTypes[i]));
  }
  return out.str();
}

void StochasticDetector::load_state(std::string_view text) {
  if (text.find_first_not_of(" \t\r\n") == std::string_view::npos) return;
  const Topology& topo = topology();
  std::istringstream in{std::string(text)};
  const auto fail = [](const std::string& what) {
    throw InputError("stochastic detector state: " + what);
  };
  std::string word, params, rng_word;
  in >> word >> params >> rng_word;
  if (word != "stochastic-state-2") fail("expected 'stochastic-state-2', got '" + word + "'");
  if (params != params_.to_string()) {
    fail("saved with " + params + " but the detector is " + params_.to_string());
  }
  if (rng_word != "rng") fail("expected 'rng'");
  std::mt19937_64 rng;
  if (!(in >> rng)) fail("bad generator state");
  std::array<std::vector<PrimitivePair>, 4> near, walking;
  for (std::size_t i = 0; i < kPairTypes.size(); ++i) {
    if (!(in >> word) || word != to_string(kPairTypes[i])) {
      fail("expected the '" + std::string(to_string(kPairTypes[i])) + "' pair lists");
    }
    const auto counts = pair_counts(topo, kPairTypes[i]);  // no binding: clang 14 cannot capture one
    const auto na = std::get<0>(counts);
    const auto nb = std::get<1>(counts);
    const auto read = [&](std::vector<PrimitivePair>& pairs) {
      std::size_t n = 0;
      if (!(in >> n)) fail("expected a pair count");
      if (n > static_cast<std::size_t>(params_.active) + static_cast<std::size_t>(na)) fail("too many pairs");
      for (std::size_t k = 0; k < n; ++k) {
        PrimitivePair p;
        if (!(in >> p.a >> p.b)) fail("truncated pair list");
        if (p.a < 0 || p.a >= na || p.b < 0 || p.b >= nb) fail("pair out of range for this mesh");
        pairs.push_back(p);
      }
    };
    read(near[i]);
    read(walking[i]);
  }
  if (in >> word) fail("unexpected '" + word + "' after the pair lists");
  Impl& m = *impl_;
  m.rng = rng;
  m.vv.restore(std::move(near[0]), std::move(walking[0]));
  m.ee.restore(std::move(near[1]), std::move(walking[1]));
  m.vf.restore(std::move(near[2]), std::move(walking[2]));
  m.ef.restore(std::move(near[3]), std::move(walking[3]));
  m.saved = false;
}

void StochasticDetector::detect(PositionsView /*previous*/, PositionsView x, ContactSet& out) {
  out.clear();
  const FrameDeadline& deadline = frame_deadline();  // from the entry of `update`
  const Topology& topo = topology();
  const Scalar h = thickness();
  const Scalar near = params_.near * h;  // near_distance() in the scaled coordinates
  Impl& m = *impl_;
  m.saved_rng = m.rng;
  for (std::size_t i = 0; i < kPairTypes.size(); ++i) {
    const auto near_now = near_pairs(kPairTypes[i]);
    const auto walking_now = walking_pairs(kPairTypes[i]);
    m.saved_near[i].assign(near_now.begin(), near_now.end());
    m.saved_walking[i].assign(walking_now.begin(), walking_now.end());
  }
  m.saved = true;
  m.sink.begin(topo, x, narrow::sqr_thickness(h), options().kinds, out);
  m.zone.begin_frame();
  EngineStats zone_stats;
  Context ctx{topo, x, narrow::sqr_thickness(h), near, near * near, m.sink, m.zone, zone_stats};

  EngineConfig config;
  config.propagation = params_.propagation;
  config.active = params_.active;
  config.draw = params_.draw;
  config.steps = params_.steps;
  config.deadline = deadline;
  switch (params_.variant) {
    case StochasticVariant::Simple:
      break;
    case StochasticVariant::PropagateByConvergence:
      config.by_convergence = true;
      break;
    case StochasticVariant::Direct:
    case StochasticVariant::Vertex:
      config.direct = true;
      config.by_convergence = params_.variant == StochasticVariant::Direct;
      config.cache = true;
      break;
  }

  EngineStats total;
  const auto accumulate = [&](const EngineStats& s) {
    total.drawn += s.drawn;
    total.kept += s.kept;
    total.deleted += s.deleted;
    total.duplicates += s.duplicates;
    total.converge_steps += s.converge_steps;
    total.distance_evals += s.distance_evals;
    total.cache_hits += s.cache_hits;
    total.propagation_visits += s.propagation_visits;
    total.colliding += s.colliding;
    total.zone_tests += s.zone_tests;
    total.face_pairs += s.face_pairs;
    total.kdop_rejects += s.kdop_rejects;
    total.carried += s.carried;
    total.walking += s.walking;
  };

  // Algorithm 3, phase by phase across the pair types (kept pairs, then draws, then
  // propagation), so that a time budget serves temporal coherence first. The engines share one
  // seeded generator; only draws use it, always in this type order.
  const auto each = [&](const auto& phase) {
    if (runs(PairType::VV)) phase(m.vv);
    if (runs(PairType::EE)) phase(m.ee);
    if (runs(PairType::VF)) phase(m.vf);
    if (runs(PairType::EF)) phase(m.ef);
  };
  each([&](auto& engine) { engine.begin_frame(ctx, config); });
  each([&](auto& engine) { engine.draw(ctx, m.rng); });
  each([&](auto& engine) { engine.propagate_all(ctx); });

  EngineStats vv_stats;
  if (runs(PairType::VV)) {
    vv_stats = m.vv.stats();
    // Precise sub-pair work done by the zone tests belongs to the VV engine.
    vv_stats.distance_evals += zone_stats.distance_evals;
    vv_stats.cache_hits += zone_stats.cache_hits;
    vv_stats.zone_tests = zone_stats.zone_tests;
    vv_stats.face_pairs = zone_stats.face_pairs;
    vv_stats.kdop_rejects = zone_stats.kdop_rejects;
    accumulate(vv_stats);
  }
  if (runs(PairType::EE)) accumulate(m.ee.stats());
  if (runs(PairType::VF)) accumulate(m.vf.stats());
  if (runs(PairType::EF)) accumulate(m.ef.stats());

  const bool vertex = params_.variant == StochasticVariant::Vertex;
  add_stats(stats_, "", total, vertex);
  if (runs(PairType::VV)) add_stats(stats_, "vv_", vv_stats, true);
  if (runs(PairType::EE)) add_stats(stats_, "ee_", m.ee.stats(), false);
  if (runs(PairType::VF)) add_stats(stats_, "vf_", m.vf.stats(), false);
  if (runs(PairType::EF)) add_stats(stats_, "ef_", m.ef.stats(), false);
}

}  // namespace crumple

// The hybrid detector (hybrid.hpp): names and parameters, construction, saved state, and a
// frame's steps in order; the steps themselves are in hybrid_zones.cpp and hybrid_search.cpp
// (hybrid_detail.hpp).

#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/detect/budget_spec_detail.hpp>
#include <crumple/detect/hybrid.hpp>
#include <crumple/detect/hybrid_detail.hpp>
#include <crumple/detect/narrow_phase.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>

namespace crumple {


// ---------------------------------------------------------------------------------------------
// Names and parameters

std::string_view to_string(ZoneSearch search) {
  switch (search) {
    case ZoneSearch::Stochastic: return "stochastic";
    case ZoneSearch::Exact: return "exact";
  }
  return "?";
}

HybridParams HybridParams::from_spec(const MethodSpec& spec) {
  const auto fail = [&](const std::string& message) {
    throw InputError("method " + spec.to_string() + ": " + message);
  };
  HybridParams p;
  const long long leaf = spec.get_int("leaf", 64);
  if (leaf < 4 || leaf > 4096) fail("leaf must be in [4, 4096], got " + std::to_string(leaf));
  p.leaf = static_cast<int>(leaf);
  const long long every = spec.get_int("every", 1);
  if (every < 1 || every > 1'000'000) fail("every must be in [1, 1e6], got " + std::to_string(every));
  p.every = static_cast<int>(every);
  const BudgetSpec budget = budget_from_spec(spec);
  p.budget_ms = budget.budget_ms;
  p.clock = budget.clock;
  const long long zones = spec.get_int("zones", 0);
  if (zones < 0 || zones > 100'000'000) fail("zones must be in [0, 1e8] (0 = all), got " + std::to_string(zones));
  p.zones = static_cast<int>(zones);
  static constexpr std::array<std::string_view, 2> kSearch{"stochastic", "exact"};
  p.search = spec.get_choice("search", "stochastic", kSearch) == "exact" ? ZoneSearch::Exact : ZoneSearch::Stochastic;
  const long long draw = spec.get_int("draw", 0);
  if (draw < 0 || draw > 100'000'000) fail("draw must be in [0, 1e8] (0 = adaptive), got " + std::to_string(draw));
  p.draw = static_cast<int>(draw);
  static constexpr std::array<std::string_view, 4> kPropagation{"auto", "none", "linear", "full"};
  const std::string prop = spec.get_choice("propagation", "linear", kPropagation);
  p.auto_propagation = prop == "auto";
  if (prop == "none") p.propagation = Propagation::None;
  if (prop == "full") p.propagation = Propagation::Full;
  p.near = spec.get_double("near", 0);
  if (!(std::isfinite(p.near) && (p.near == 0 || p.near >= 1))) {
    fail("near must be 0 (adaptive) or a finite multiple >= 1 of the thickness");
  }
  const long long steps = spec.get_int("steps", 8);
  if (steps < 1 || steps > 100'000'000) fail("steps must be in [1, 1e8], got " + std::to_string(steps));
  p.steps = static_cast<int>(steps);
  const long long seed = spec.get_int("seed", 1);
  if (seed < 0) fail("seed must be >= 0");
  p.seed = static_cast<std::uint64_t>(seed);
  return p;
}

std::string HybridParams::to_string() const {
  char near_text[32];
  std::snprintf(near_text, sizeof near_text, "%g", near);
  return "hybrid:leaf=" + std::to_string(leaf) + ",every=" + std::to_string(every) +
         ",budget=" + json_number(budget_ms) + ",zones=" + std::to_string(zones) +
         ",search=" + std::string(crumple::to_string(search)) + ",draw=" + std::to_string(draw) +
         ",propagation=" + (auto_propagation ? std::string("auto") : std::string(crumple::to_string(propagation))) +
         ",near=" + near_text + ",steps=" + std::to_string(steps) + ",seed=" + std::to_string(seed) +
         (clock == BudgetClock::cpu ? ",clock=cpu" : "");
}

// ---------------------------------------------------------------------------------------------
// The detector

using hybrid_detail::Clock;
using hybrid_detail::Context;
using hybrid_detail::EngineConfig;
using hybrid_detail::EngineStats;
using hybrid_detail::kEE;
using hybrid_detail::Kept;
using hybrid_detail::kTypes;
using hybrid_detail::kVF;
using hybrid_detail::Zone;
using hybrid_detail::ZoneSearchFrame;

HybridDetector::HybridDetector(DetectorOptions options, HybridParams params)
    : Detector(options), params_(params), impl_(std::make_unique<Impl>()) {
  if (params_.leaf < 4 || params_.every < 1 || params_.zones < 0 || params_.draw < 0 || params_.steps < 1 ||
      !(params_.budget_ms >= 0) || !(std::isfinite(params_.near) && (params_.near == 0 || params_.near >= 1))) {
    throw InputError("hybrid: invalid parameters " + params_.to_string() +
                     " (leaf >= 4, every >= 1, zones >= 0, draw >= 0, steps >= 1, budget >= 0, near 0 or >= 1)");
  }
}

HybridDetector::~HybridDetector() = default;

Index HybridDetector::num_leaves() const { return static_cast<Index>(impl_->leaf_faces.offsets.size() - 1); }

std::span<const Index> HybridDetector::leaf_faces(Index leaf) const {
  CRUMPLE_CHECK(leaf >= 0 && leaf < num_leaves(), "leaf_faces: leaf out of range");
  return impl_->leaf_faces[leaf];
}

std::span<const ZoneInfo> HybridDetector::zones() const { return impl_->infos; }

void HybridDetector::on_topology() {
  Impl& m = *impl_;
  m.build(topology(), params_.leaf);
  m.zones.clear();
  m.infos.clear();
  m.kept.clear();
  m.ee.reset();
  m.vf.reset();
  m.ef.reset();
  m.zone_tester.reset(0);
  m.rng.seed(params_.seed);
  m.saved = false;
}

std::string HybridDetector::save_state() const {
  const Impl& m = *impl_;
  const std::vector<Zone>& zones = m.saved ? m.saved_zones : m.zones;
  const std::vector<Kept>& kept = m.saved ? m.saved_kept : m.kept;
  std::ostringstream out;
  out << "hybrid-state-1 " << params_.to_string() << " rng " << (m.saved ? m.saved_rng : m.rng) << " zones "
      << zones.size();
  for (const Zone& z : zones) {
    out << " " << z.a << " " << z.b << " " << z.age << " " << (z.never ? 1 : 0) << " " << z.contacts;
  }
  out << " kept " << kept.size();
  for (const Kept& k : kept) out << " " << int(k.type) << " " << k.pair.a << " " << k.pair.b;
  return out.str();
}

void HybridDetector::load_state(std::string_view text) {
  if (text.find_first_not_of(" \t\r\n") == std::string_view::npos) return;
  const Topology& topo = topology();
  Impl& m = *impl_;
  std::istringstream in{std::string(text)};
  const auto fail = [](const std::string& what) { throw InputError("hybrid detector state: " + what); };
  std::string word, params;
  in >> word >> params;
  if (word != "hybrid-state-1") fail("expected 'hybrid-state-1', got '" + word + "'");
  if (params != params_.to_string()) fail("saved with " + params + " but the detector is " + params_.to_string());
  if (!(in >> word) || word != "rng") fail("expected 'rng'");
  std::mt19937_64 rng;
  if (!(in >> rng)) fail("bad generator state");
  if (!(in >> word) || word != "zones") fail("expected 'zones'");
  std::size_t n = 0;
  if (!(in >> n)) fail("expected a zone count");
  const auto leaves = static_cast<std::size_t>(num_leaves());
  if (n > leaves * (leaves + 1) / 2) fail("more zones than leaf pairs");
  std::vector<Zone> zones(n);
  for (Zone& z : zones) {
    int never = 0;
    if (!(in >> z.a >> z.b >> z.age >> never >> z.contacts)) fail("truncated zone list");
    if (z.a < 0 || z.b < z.a || z.b >= num_leaves()) fail("zone leaves out of range for this mesh");
    if (z.age < 0 || (never != 0 && never != 1) || z.contacts < 0) fail("bad zone age, flag or contact count");
    z.never = never == 1;
  }
  for (std::size_t i = 1; i < zones.size(); ++i) {
    if (!(zones[i - 1].key() < zones[i].key())) fail("zones not in order");
  }
  if (!(in >> word) || word != "kept") fail("expected 'kept'");
  if (!(in >> n)) fail("expected a kept pair count");
  std::vector<Kept> kept;
  for (std::size_t i = 0; i < n; ++i) {
    int type = 0;
    Kept k;
    if (!(in >> type >> k.pair.a >> k.pair.b)) fail("truncated kept pair list");
    if (type < 0 || type >= kTypes) fail("bad pair type");
    const Index na = type == kVF ? topo.num_vertices() : topo.num_edges();
    const Index nb = type == kEE ? topo.num_edges() : topo.num_faces();
    if (k.pair.a < 0 || k.pair.a >= na || k.pair.b < 0 || k.pair.b >= nb) fail("pair out of range for this mesh");
    k.type = static_cast<std::uint8_t>(type);
    k.zone = m.zone_of(type, k.pair);
    kept.push_back(k);
  }
  if (in >> word) fail("unexpected '" + word + "' after the kept pairs");
  std::sort(kept.begin(), kept.end());
  m.rng = rng;
  m.zones = std::move(zones);
  m.kept = std::move(kept);
  m.saved = false;
}

void HybridDetector::detect(PositionsView previous, PositionsView x, ContactSet& out) {
  out.clear();
  const auto start = Clock::now();
  const Topology& topo = topology();
  Impl& m = *impl_;
  const Scalar h = thickness();
  const ContactKinds& kinds = options().kinds;
  const bool has_previous = !previous.empty();
  // The budget covers the whole call (`frame_deadline`, from the entry of `update`). The search
  // stops early enough for the work after it (kept pairs, risk report, the sort of the
  // contacts) at that work's cost on the last frame: its deadline is the frame's, shortened.
  const FrameDeadline& frame_clock = frame_deadline();
  const double reserve_ms = frame_clock.active() ? m.post_cost.ms() : 0;
  const FrameDeadline deadline = frame_clock.shortened(reserve_ms);
  const auto ms_since = [](Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
  };

  m.saved_zones = m.zones;
  m.saved_kept = m.kept;
  m.saved_rng = m.rng;
  m.saved = true;

  // 1. Refit the leaves.
  m.refit_leaves(previous, x, h, params_.near);
  const double refit_ms = ms_since(start);

  // 2. Zones: overlapping leaf pairs, merged with last frame's, in the order of examination.
  const auto zones_start = Clock::now();
  const std::vector<Kept> old_kept = m.merge_zones();
  const int every = params_.every;
  const std::vector<std::size_t> order = m.schedule(h, has_previous, every);
  const double zones_ms = ms_since(zones_start);

  // 3. Examine the zones in order.
  const auto search_start = Clock::now();
  m.sink.begin(topo, x, narrow::sqr_thickness(h), kinds, out);
  EngineStats zone_stats;
  Context ctx{topo, x, narrow::sqr_thickness(h), 2 * h, 4 * h * h, m.sink, m.zone_tester, zone_stats};
  EngineConfig base;
  base.direct = true;
  base.by_convergence = true;
  // No distance cache: a walk's neighbour pairs are scattered over a table of tens of thousands
  // of pairs, and a probe that misses the processor cache costs more than the distance kernel.
  // Same contacts either way (distances are deterministic); only `distance_evals` grows.
  base.cache = false;
  base.steps = params_.steps;
  base.deadline = deadline;
  m.ee.start_frame(base);
  m.vf.start_frame(base);
  m.ef.start_frame(base);
  ZoneSearchFrame search{topo, x, h, kinds.ee, kinds.vf, kinds.tt, deadline, ctx, old_kept, {}};
  std::size_t zones_due = 0;
  for (const Zone& z : m.zones) zones_due += hybrid_detail::due(z, every) ? 1 : 0;
  m.examine_zones(search, order, base, params_);
  const double search_ms = ms_since(search_start);

  // 4. Kept pairs for the next frame.
  const double post_start = frame_clock.now_ms();
  m.keep_pairs(search.carried);

  // 5. The risk report: contacts per zone, ages, estimated misses.
  const Impl::Risk risk = m.report(out, every);

  EngineStats total;
  for (const EngineStats* s : {&m.ee.stats(), &m.vf.stats(), &m.ef.stats()}) {
    total.kept += s->kept + s->walking;
    total.converge_steps += s->converge_steps;
    total.distance_evals += s->distance_evals;
    total.propagation_visits += s->propagation_visits;
    total.colliding += s->colliding;
  }
  stats_.set("leaves", num_leaves());
  stats_.set("zones", static_cast<double>(m.zones.size()));
  stats_.set("zones_examined", static_cast<double>(search.examined));
  stats_.set("zones_due", static_cast<double>(zones_due));
  stats_.set("zones_due_left", static_cast<double>(risk.due_left));
  stats_.set("oldest_zone_age", risk.oldest);
  stats_.set("est_missed", risk.est_missed);
  stats_.set("drawn", search.drawn);
  stats_.set("kept", static_cast<double>(m.kept.size()));
  stats_.set("carried", static_cast<double>(search.carried.size()));
  stats_.set("converge_steps", total.converge_steps);
  stats_.set("distance_evals", total.distance_evals);
  stats_.set("propagation_visits", total.propagation_visits);
  stats_.set("colliding", total.colliding);
  stats_.set("exact_pairs", search.exact_pairs);
  stats_.set("refit_ms", refit_ms);
  stats_.set("zones_ms", zones_ms);
  stats_.set("search_ms", search_ms);
  stats_.set("reserve_ms", reserve_ms);
  out.sort();
  m.post_cost.measured(frame_clock.now_ms() - post_start);
}

}  // namespace crumple

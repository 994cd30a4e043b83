#include <crumple/core/parallel.hpp>
#include <crumple/core/timing.hpp>
#include <crumple/detect/budget_spec_detail.hpp>
#include <crumple/detect/exact/narrow_frame.hpp>
#include <crumple/detect/exact/orphans.hpp>
#include <crumple/detect/exact/ownership.hpp>
#include <crumple/detect/exact_detector.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <iterator>
#include <mutex>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace crumple {

/// What the pipeline keeps per topology and across frames.
struct ExactDetector::State {
  CandidateBuffer candidates;
  exact::FeatureOwnership own;
  exact::Orphans orphans;
  exact::OrphanSleep sleep;
  std::vector<std::uint8_t> face_owns;  ///< per face: bit 0 owns a vertex, bit 1 an edge
  std::vector<Index> edge_rank;         ///< each edge's rank in (first, second vertex) order
  std::vector<Index> edge_by_rank;      ///< the edge of each rank
  std::vector<exact::PackedFace> packed;
  std::vector<std::array<Vec3, 3>> face_corners;  ///< per face, its corners (frames asking for TT)
  std::vector<std::array<float, 4>> coarse_x;     ///< per vertex, rounded to float (frames asking for VF or EE)
  Spares<exact::KeyedContacts> spare_sets;        ///< per-chunk contacts and their keys, for reuse
  exact::GatherBuffers gather;
  /// The last frame's contacts (`ExactParams::track`): (vertex, face) and (edge, edge).
  std::vector<std::array<Index, 2>> seed_vf, seed_ee;
  int orphans_waited = 0;  ///< cut-off frames since the orphan stages last ran whole (`track`)
  /// Cut-off frames, on the budget's clock: the cost of the work after the cut-off point (from
  /// the moment the budget stopped the candidates, or when it did not the start of the gather,
  /// to the end of the call: the rest of the traversal's task, the gather, the merge of the
  /// tracked contacts), and of each orphan stage when it ran. A frame reserves the former from
  /// its budget and starts a stage only when its cost fits in what is left (`priced`).
  StageCost tail_cost;
  double gather_start_ms = 0;  ///< this frame's, on the budget's clock
  std::array<StageCost, 3> stage_cost;
  /// The orphan stages have run whole and been measured since the topology (or the scale) was
  /// set: the first frame, which builds the tree and keeps no budget, runs them whole.
  bool priced = false;
  /// This frame: the time the orphan stages ran after the budget was spent (only when pricing
  /// them), which is not part of the work after the cut-off point (`tail_cost`).
  double stages_after_spent_ms = 0;
};

namespace {

/// The last frame's contacts tested again (`ExactParams::track`) into `tracked`, in canonical
/// order, until the budget is spent: by the kernels, arguments and batches with which the
/// gather makes a contact's record again from its key (the same bits as the narrow phase's).
void test_seeds(const exact::NarrowFrame& frame, const std::vector<std::array<Index, 2>>& vf,
                const std::vector<std::array<Index, 2>>& ee, exact::Cutoff& cut, ContactSet& tracked) {
  const Topology& topo = frame.topo;
  const PositionsView x = frame.x;
  const Scalar sqr_thickness = frame.sqr_thickness;
  constexpr std::size_t kCheck = 64;  // seeds between looks at the budget
  if (frame.kinds.vf) {
    narrow::VertexFaceBatch batch;
    for (std::size_t i = 0; i < vf.size() && (i % kCheck != 0 || !cut.spent()); ++i) {
      const auto [v, f] = vf[i];
      const Face& t = topo.face(f);
      batch.push(v, narrow::at(x, v), f, narrow::at(x, t[0]), narrow::at(x, t[1]), narrow::at(x, t[2]), sqr_thickness,
                 tracked.vf);
    }
    batch.flush(sqr_thickness, tracked.vf);
  }
  if (frame.kinds.ee) {
    narrow::EdgeEdgeBatch batch;
    for (std::size_t i = 0; i < ee.size() && (i % kCheck != 0 || !cut.spent()); ++i) {
      const auto [e0, e1] = ee[i];
      const Edge &a = topo.edge(e0), &b = topo.edge(e1);
      batch.push(e0, a[0], a[1], narrow::at(x, a[0]), narrow::at(x, a[1]), e1, b[0], b[1], narrow::at(x, b[0]),
                 narrow::at(x, b[1]), sqr_thickness, tracked.ee);
    }
    batch.flush(sqr_thickness, tracked.ee);
  }
  std::sort(tracked.vf.begin(), tracked.vf.end(), CanonicalLess{});
  std::sort(tracked.ee.begin(), tracked.ee.end(), CanonicalLess{});
}

/// `out` and `more`, both in canonical order without repeats, merged into `out` (a contact in
/// both is the same record: kept once).
template <class T>
void merge_unique(std::vector<T>& out, const std::vector<T>& more) {
  if (more.empty()) return;
  std::vector<T> merged;
  merged.reserve(out.size() + more.size());
  std::set_union(out.begin(), out.end(), more.begin(), more.end(), std::back_inserter(merged), CanonicalLess{});
  out = std::move(merged);
}

}  // namespace

/// The broad phase's hierarchy as `update`'s caller sees it: node boxes scaled by 2^-k from the
/// scaled coordinates the detector computes in (k = the last frame's `scale_exponent`).
class ExactDetector::Unscaled final : public BoundingHierarchy {
 public:
  Unscaled(const BoundingHierarchy& inner, const ExactDetector& owner) : inner_(inner), owner_(owner) {}
  int levels() const override { return inner_.levels(); }
  std::vector<Bounds> node_boxes(int depth) const override {
    std::vector<Bounds> boxes = inner_.node_boxes(depth);
    const int k = owner_.scale_exponent();
    if (k == 0) return boxes;
    for (Bounds& b : boxes) {
      for (int a = 0; a < 3; ++a) {
        b.min[a] = std::scalbn(b.min[a], -k);
        b.max[a] = std::scalbn(b.max[a], -k);
      }
    }
    return boxes;
  }
  std::vector<std::vector<Index>> leaf_faces() const override { return inner_.leaf_faces(); }

 private:
  const BoundingHierarchy& inner_;
  const ExactDetector& owner_;
};

ExactParams ExactParams::from_spec(const MethodSpec& spec) {
  ExactParams p;
  const long long cap = spec.get_int("max_contacts", 0);
  if (cap < 0) throw InputError("method " + spec.to_string() + ": max_contacts must be >= 0");
  p.max_contacts = static_cast<std::size_t>(cap);
  static constexpr std::array<std::string_view, 2> kOverflow{"error", "truncate"};
  p.overflow_error = spec.get_choice("overflow", "error", kOverflow) == "error";
  const BudgetSpec budget = budget_from_spec(spec);
  p.budget_ms = budget.budget_ms;
  p.clock = budget.clock;
  const long long pairs = spec.get_int("pairs", 0);
  if (pairs < 0) throw InputError("method " + spec.to_string() + ": pairs must be >= 0");
  p.pairs = static_cast<std::size_t>(pairs);
  p.track = spec.get_bool("track", false);
  return p;
}

ExactDetector::ExactDetector(DetectorOptions options, ExactParams params, std::unique_ptr<BroadPhase> broad_phase)
    : Detector(options), params_(params), broad_phase_(std::move(broad_phase)), state_(std::make_unique<State>()) {
  CRUMPLE_CHECK(broad_phase_ != nullptr, "ExactDetector: null broad phase");
  if (params_.budget_ms > 0) check_budget(params_.budget_ms);
  if (const BoundingHierarchy* inner = broad_phase_->hierarchy()) unscaled_ = std::make_unique<Unscaled>(*inner, *this);
}

ExactDetector::~ExactDetector() = default;

void ExactDetector::check_budget(double ms) const {
  if (params_.clock == BudgetClock::cpu && ms > 0 && resolve_threads(options().threads) != 1) {
    throw InputError("exact detector: clock=cpu counts one thread's processor time: it needs threads = 1");
  }
}

const BoundingHierarchy* ExactDetector::hierarchy() const {
  return unscaled_.get();
}

void ExactDetector::on_rescale() {
  state_->sleep = {};
  state_->priced = false;
  broad_phase_->build(topology());
}

void ExactDetector::on_topology() {
  const Topology& topo = topology();
  State& s = *state_;
  s.own = exact::own_features(topo);
  const exact::FeatureOwnership& own = s.own;
  s.orphans = exact::list_orphans(topo, own);
  s.seed_vf.clear();
  s.seed_ee.clear();
  s.orphans_waited = 0;
  s.tail_cost = {};
  s.stage_cost = {};
  s.priced = false;
  s.sleep = {};
  s.face_owns = own.face_owns();
  s.edge_rank = exact::edge_ranks(topo);
  s.edge_by_rank.assign(s.edge_rank.size(), 0);
  for (std::size_t e = 0; e < s.edge_rank.size(); ++e) {
    s.edge_by_rank[static_cast<std::size_t>(s.edge_rank[e])] = static_cast<Index>(e);
  }
  s.packed.assign(static_cast<std::size_t>(topo.num_faces()), exact::PackedFace{});
  for (Index f = 0; f < topo.num_faces(); ++f) {
    exact::PackedFace& pf = s.packed[static_cast<std::size_t>(f)];
    pf.v = topo.face(f);
    pf.e = topo.face_edges(f);
    pf.vertex_mask = own.vertex_mask[static_cast<std::size_t>(f)];
    pf.edge_mask = own.edge_mask[static_cast<std::size_t>(f)];
  }
  broad_phase_->build(topo);
}

Scalar ExactDetector::prepare_frame(PositionsView previous, PositionsView x) {
  // One parallel pass over the positions finds the frame's largest coordinate magnitude and,
  // when proximity is asked, rounds the positions to float for the narrow phase's box tests.
  const bool proximity = options().kinds.vf || options().kinds.ee;
  std::vector<std::array<float, 4>>& coarse_x = state_->coarse_x;
  if (proximity) coarse_x.resize(x.size());
  Scalar magnitude = 0;
  std::mutex mutex;
  parallel_for_chunks(x.size(), options().threads, 4096, [&](std::size_t begin, std::size_t end) {
    Scalar m = 0;  // std::max keeps m for a NaN
    for (std::size_t v = begin; v < end; ++v) {
      m = std::max(m, x[v].cwiseAbs().maxCoeff());
      if (!previous.empty()) m = std::max(m, previous[v].cwiseAbs().maxCoeff());
      if (proximity) {
        for (std::size_t a = 0; a < 3; ++a) coarse_x[v][a] = exact::coarse_coordinate(x[v][a]);
        coarse_x[v][3] = 0;
      }
    }
    const std::lock_guard lock(mutex);
    magnitude = std::max(magnitude, m);
  });
  return magnitude;
}

void ExactDetector::detect(PositionsView previous, PositionsView x, ContactSet& out) {
  State& s = *state_;
  const int threads = options().threads;
  const ContactKinds kinds = options().kinds;
  overflowed_ = false;
  s.candidates.clear();

  // Broad phase, with each face inflated by half the padded thickness (file comment).
  const auto t0 = std::chrono::steady_clock::now();
  // A budget counts from the entry of `update` (`frame_deadline`): refit and gather included
  // (the measured cost of the work after the cut-off point is reserved: the candidates stop
  // that much earlier).
  const double budget_ms = frame_budget(params_.budget_ms);
  const FrameDeadline& deadline = frame_deadline();
  const Scalar magnitude = prepare_frame(previous, x);
  const bool proximity = kinds.vf || kinds.ee;
  const Scalar h = thickness();
  const Scalar pad = (proximity ? h * (1 + 1e-6) : 0) + 1e-9 * magnitude;
  FrameInput in{previous, x, pad / 2, threads, !proximity, {}};
  if (!kinds.tt) in.owns = s.face_owns;
  broad_phase_->update(in, stats_);
  // The one length among the broad phases' counters, in the caller's units.
  if (const double cell = stats_.get("cell_size"); cell != 0 && scale_exponent() != 0) {
    stats_.set("cell_size", std::scalbn(cell, -scale_exponent()));
  }
  if (budget_ms > 0 || params_.pairs > 0) {
    const double reserve_ms = budget_ms > 0 ? s.tail_cost.ms() : 0;
    exact::Cutoff cut(params_.pairs, deadline, reserve_ms);
    stats_.set("reserve_ms", reserve_ms);
    stats_.set("broad_ms", ms_since(t0));
    narrow_phase(x, pad, magnitude, out, &cut);
    s.candidates.clear();
    cap_contacts(out);
    keep_seeds(out);
    const double spent_at = cut.spent_at_ms();
    s.tail_cost.measured(deadline.now_ms() - (spent_at >= 0 ? spent_at : s.gather_start_ms) -
                         s.stages_after_spent_ms);
    return;
  }
  // Triangle intersections alone: each candidate may be a contact, and is as large as one, so
  // the candidates are not all held: the broad phase streams them to the narrow phase, whose
  // memory then follows the contacts.
  const bool stream = !proximity;
  if (!stream) {
    broad_phase_->self_pairs(s.candidates, stats_);
    stats_.set("candidates", static_cast<double>(s.candidates.total()));
  }
  stats_.set("broad_ms", ms_since(t0));
  narrow_phase(x, pad, magnitude, out, nullptr, stream);
  s.candidates.clear();
  cap_contacts(out);
  keep_seeds(out);
}

void ExactDetector::keep_seeds(const ContactSet& out) {
  if (!params_.track) return;
  State& s = *state_;
  s.seed_vf.clear();
  s.seed_ee.clear();
  for (const VertexFaceContact& c : out.vf) s.seed_vf.push_back({c.vertex, c.face});
  for (const EdgeEdgeContact& c : out.ee) s.seed_ee.push_back({c.edge0, c.edge1});
}

void ExactDetector::narrow_phase(PositionsView x, Scalar pad, Scalar magnitude, ContactSet& out,
                                 exact::Cutoff* cut, bool stream) {
  State& s = *state_;
  const Topology& topo = topology();
  const int threads = options().threads;
  const ContactKinds kinds = options().kinds;
  const auto narrow_start = std::chrono::steady_clock::now();
  if (kinds.tt) {
    const std::size_t nf = s.packed.size();
    s.face_corners.resize(nf);
    parallel_for_chunks(nf, threads, balanced_grain(nf, threads, 512, 4096), [&](std::size_t begin, std::size_t end) {
      for (std::size_t f = begin; f < end; ++f) {
        for (std::size_t k = 0; k < 3; ++k) s.face_corners[f][k] = narrow::at(x, s.packed[f].v[k]);
      }
    });
  }
  exact::NarrowFrame frame(topo, x, kinds, threads, thickness(), pad, magnitude, s.packed, s.face_corners,
                           s.coarse_x, s.edge_rank, s.spare_sets);
  bool stopped = false;  // the budget left candidates untested
  ContactSet tracked;    // the last frame's contacts found again (`ExactParams::track`)
  // The orphan stages, each whole or, once a budget is spent, not at all (a skipped stage
  // leaves its sleep state as it was: the next frame wakes from the last refresh). Cut off, a
  // stage starts only when its cost (`StageCost`, or an estimate) fits in what is left.
  const auto clock_ms = [&] { return cut == nullptr ? 0.0 : cut->deadline().now_ms(); };
  // Under a time budget not yet priced (the first frame of a topology or scale, which builds
  // the tree and keeps no budget), every stage runs whole and is measured: an unpriced stage would run whatever it
  // costs on a later frame (a refresh of every orphan block: 0.35 ms on the 24x24 sheet, under
  // a budget of 0.06).
  const bool pricing = cut != nullptr && cut->deadline().active() && !s.priced;
  const auto go_on = [&](std::size_t stage) {
    if (cut == nullptr || pricing) return true;
    return cut->fits(s.stage_cost[stage].ms());
  };
  std::size_t tested_blocks = 0, star_pairs = 0;
  int skipped = 0;
  double orphan_ms = 0;
  s.stages_after_spent_ms = 0;
  const auto orphan_stages = [&] {
    const auto orphans_start = std::chrono::steady_clock::now();
    double t = clock_ms();
    const double stages_start = t;
    const bool after_spent = cut != nullptr && cut->spent_at_ms() >= 0;
    const auto measured = [&](std::size_t stage) {
      const double now = clock_ms();
      s.stage_cost[stage].measured(now - t);
      t = now;
    };
    if (go_on(0)) {
      const bool refresh = frame.proximity && exact::wake_orphan_blocks(s.orphans, s.sleep, x, pad, threads, stats_);
      stats_.set("orphan_wake_ms", ms_since(orphans_start));
      tested_blocks = exact::narrow_orphans(frame, s.orphans, refresh);
      if (refresh) s.sleep.ref.assign(x.begin(), x.end());
      stats_.set("orphan_refresh", refresh ? 1 : 0);
      measured(0);
    } else {
      ++skipped;
      stats_.set("orphan_wake_ms", 0);
      stats_.set("orphan_refresh", 0);
    }
    if (go_on(1)) {
      star_pairs = exact::narrow_stars(frame, s.orphans.stars, s.own);
      measured(1);
    } else {
      ++skipped;
    }
    if (go_on(2)) {
      exact::narrow_isolated(frame, s.own.isolated);
      measured(2);
    } else {
      ++skipped;
    }
    orphan_ms = ms_since(orphans_start);
    if (after_spent) s.stages_after_spent_ms = clock_ms() - stages_start;
  };
  // Tracking, the orphan stages come first when they have not run for kOrphanPeriod frames: a
  // traversal cut short every frame would never reach them, and the contacts they find are
  // tracked from then on. (Every frame would spend most of a small budget on them.)
  constexpr int kOrphanPeriod = 4;
  const bool orphans_first = cut != nullptr && params_.track && s.orphans_waited >= kOrphanPeriod;
  if (cut == nullptr && stream) {
    const StreamedPairs streamed = stream_self_pairs(
        *broad_phase_, s.candidates, stats_, [&frame](std::span<const FacePair> chunk) { exact::narrow_candidate_chunk(frame, chunk); });
    stats_.set("candidates", static_cast<double>(streamed.candidates));
  } else if (cut == nullptr) {
    exact::narrow_candidates(frame, s.candidates);
  } else {
    if (params_.track) test_seeds(frame, s.seed_vf, s.seed_ee, *cut, tracked);
    if (orphans_first) orphan_stages();
    // Each traversal task's candidates are tested as it ends (chunk size 1), until the budget
    // stops both.
    const StreamedPairs streamed = stream_self_pairs(
        *broad_phase_, s.candidates, stats_,
        [&](std::span<const FacePair> chunk) {
          if (!exact::narrow_candidates(frame, chunk, *cut)) s.candidates.stop();
        },
        1, params_.track, [cut] { return cut->spent(); });
    stopped = streamed.stopped || cut->tested() < streamed.candidates;
    stats_.set("candidates", static_cast<double>(streamed.candidates));
    stats_.set("pairs_tested", static_cast<double>(cut->tested()));
  }
  if (!orphans_first) orphan_stages();
  if (pricing) s.priced = true;
  s.orphans_waited = skipped == 0 ? 0 : s.orphans_waited + 1;

  if (cut != nullptr) {
    stats_.set("cut", stopped || skipped > 0 ? 1 : 0);
    stats_.set("stages_skipped", skipped);
  }
  stats_.set("orphan_ms", orphan_ms);
  stats_.set("orphan_blocks", static_cast<double>(s.orphans.vf_blocks.size() + s.orphans.ee_blocks.size()));
  stats_.set("orphan_blocks_tested", static_cast<double>(tested_blocks));
  stats_.set("orphan_stars", static_cast<double>(s.orphans.stars.size()));
  stats_.set("orphan_star_pairs", static_cast<double>(star_pairs));
  stats_.set("narrow_ms", ms_since(narrow_start));

  // The frame's set in canonical order (`sorted_output`: the base class does not sort it again).
  const auto gather_start = std::chrono::steady_clock::now();
  s.gather_start_ms = clock_ms();
  exact::gather_contacts(frame, s.edge_by_rank, s.gather, out);
  merge_unique(out.vf, tracked.vf);
  merge_unique(out.ee, tracked.ee);
  stats_.set("sort_ms", ms_since(gather_start));
  stats_.set("orphan_vf", static_cast<double>(s.orphans.vf.size()));
  stats_.set("orphan_ee", static_cast<double>(s.orphans.ee.size()));
  stats_.set("isolated_vertices", static_cast<double>(s.own.isolated.size()));
  stats_.set("vf_tests", static_cast<double>(frame.vf_tests));
  stats_.set("ee_tests", static_cast<double>(frame.ee_tests));
  if (kinds.tt) stats_.set("tt_tests", static_cast<double>(frame.tt_tests));
}

void ExactDetector::cap_contacts(ContactSet& out) {
  const std::size_t total = out.size();
  stats_.set("contacts", static_cast<double>(total));
  if (params_.max_contacts == 0 || total <= params_.max_contacts) {
    stats_.set("overflow", 0);
    return;
  }
  overflowed_ = true;
  stats_.set("overflow", 1);
  stats_.set("contacts_dropped", static_cast<double>(total - params_.max_contacts));
  if (params_.overflow_error) {
    throw ContactOverflowError("exact detector: " + std::to_string(total) + " contacts exceed max_contacts=" +
                               std::to_string(params_.max_contacts));
  }
  // Keep the first max_contacts in canonical order (VF, then EE, then TT; the gather's):
  // deterministic.
  std::size_t keep = params_.max_contacts;
  const auto cut = [&keep](auto& v) {
    if (v.size() > keep) v.resize(keep);
    keep -= v.size();
  };
  cut(out.vf);
  cut(out.ee);
  cut(out.tt);
}

}  // namespace crumple

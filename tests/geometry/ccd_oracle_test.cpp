// Narrow-phase CCD against the exact GMP oracle (tests/support/ccd_oracle.hpp) on generated
// queries concentrated on the hard cases. Every query is built on a dyadic grid so that exact
// contacts can be constructed in doubles: a contact at a dyadic time t* and dyadic parameters
// (u*, v*), verified exactly by the oracle. For each query:
//  - oracle kYes  => the narrow phase hits (no false negative), and its toi ≤ the oracle's
//                    witness time (and ≤ the exact toi when the oracle knows it);
//  - every kHitTolerance => the stated tolerance holds: within
//    [toi, toi + time_tolerance] the exact distance is ≤ δ (1 + σ) + ε + 2‖err‖, checked exactly at
//    33 times with the Lipschitz slack L · time_tolerance / 64;
//  - oracle kNo  => a narrow-phase hit is a false positive: counted and printed.
#include <crumple/geometry/ccd.hpp>

#include "support/ccd_oracle.hpp"

#include <gtest/gtest.h>

#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <optional>
#include <random>
#include <string>

namespace crumple::geometry {
namespace {

namespace co = crumple::ccd_oracle;

struct Case {
  CcdPair pair;
  CcdPoints start, end;
  Scalar delta = 0;
  bool constructed_contact = false;  // built to touch at `witness`
  std::optional<std::array<Scalar, 3>> witness;  // a candidate contact (t*, u*, v*), dyadic
};

std::string hex(const Case& c) {
  std::string s = c.pair == CcdPair::kVertexFace ? "vf" : "ee";
  char buf[64];
  for (const CcdPoints* x : {&c.start, &c.end}) {
    for (const Vec3& p : *x) {
      for (int k = 0; k < 3; ++k) {
        std::snprintf(buf, sizeof buf, " %a", p[k]);
        s += buf;
      }
    }
  }
  std::snprintf(buf, sizeof buf, "  (delta %a)", c.delta);
  return s + buf;
}

/// Grid points: integers in [-2^20, 2^20] times 2^-20 times a power-of-two scale, so sums and
/// dyadic multiples stay exact in binary64.
class Gen {
 public:
  Gen(std::uint64_t seed, Scalar scale) : rng_(seed), scale_(scale) {}
  Scalar scale() const { return scale_; }
  Scalar coord(int bits = 20) {
    const std::int64_t n = std::uniform_int_distribution<std::int64_t>(-(1 << bits), 1 << bits)(rng_);
    return std::ldexp(Scalar(n), -bits) * scale_;
  }
  Vec3 point() { return Vec3(coord(), coord(), coord()); }
  Vec3 small(int bits = 20) { return (Vec3(coord(bits), coord(bits), coord(bits)) / 8).eval(); }
  int integer(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }
  bool coin() { return integer(0, 1) == 1; }
  /// A dyadic time whose free trajectory end can be solved exactly.
  Scalar dyadic_time() {
    static const Scalar kTimes[] = {0, 0.0625, 0.125, 0.25, 0.5, 0.75, 0.875, 0.9375, 1};
    return kTimes[integer(0, 8)];
  }
  Scalar eighth() { return integer(0, 8) / 8.0; }
  /// Endpoints (x0, x1) of a linear trajectory that passes through `target` at t*.
  std::pair<Vec3, Vec3> through(const Vec3& target, Scalar t) {
    if (t == 0) return {target, target + small()};
    if (t == 1) return {target + small(), target};
    if (t <= 0.5) {
      const Vec3 x0 = target + small();
      return {x0, x0 + (target - x0) / t};
    }
    const Vec3 x1 = target + small();
    return {x1 + (target - x1) / (1 - t), x1};
  }
  std::mt19937_64& rng() { return rng_; }

 private:
  std::mt19937_64 rng_;
  Scalar scale_;
};

Vec3 at(const Vec3& x0, const Vec3& x1, Scalar t) { return x0 + t * (x1 - x0); }

Case vf_contact(Gen& g) {
  Case c;
  c.pair = CcdPair::kVertexFace;
  c.constructed_contact = true;
  for (int i = 1; i < 4; ++i) {
    c.start[i] = g.point();
    c.end[i] = g.coin() ? (c.start[i] + g.small()).eval() : g.point();
  }
  const Scalar t = g.dyadic_time();
  Scalar u = g.eighth(), v = g.eighth();
  if (u + v > 1) {
    u = 1 - u;
    v = 1 - v;
  }
  const Vec3 f0 = at(c.start[1], c.end[1], t), f1 = at(c.start[2], c.end[2], t), f2 = at(c.start[3], c.end[3], t);
  const Vec3 q = f0 + u * (f1 - f0) + v * (f2 - f0);
  std::tie(c.start[0], c.end[0]) = g.through(q, t);
  c.witness = {t, u, v};
  return c;
}

Case ee_contact(Gen& g) {
  Case c;
  c.pair = CcdPair::kEdgeEdge;
  c.constructed_contact = true;
  for (int i = 0; i < 3; ++i) {
    c.start[i] = g.point();
    c.end[i] = g.coin() ? (c.start[i] + g.small()).eval() : g.point();
  }
  const Scalar t = g.dyadic_time(), u = g.eighth();
  static const Scalar kV[] = {0, 0.25, 0.5, 1};
  const Scalar v = kV[g.integer(0, 3)];
  const Vec3 a0 = at(c.start[0], c.end[0], t), a1 = at(c.start[1], c.end[1], t);
  const Vec3 x = a0 + u * (a1 - a0);
  if (v == 0) {
    std::tie(c.start[2], c.end[2]) = g.through(x, t);
    c.start[3] = g.point();
    c.end[3] = g.point();
  } else {
    const Vec3 b0 = at(c.start[2], c.end[2], t);
    std::tie(c.start[3], c.end[3]) = g.through(b0 + (x - b0) / v, t);
  }
  c.witness = {t, u, v};
  return c;
}

/// Shifts one primitive's whole trajectory by `gap` × scale along a random axis direction.
Case shifted(Case c, Gen& g, Scalar gap) {
  const int axis = g.integer(0, 2);
  const Scalar d = (g.coin() ? gap : -gap) * g.scale();
  const int first = c.pair == CcdPair::kVertexFace ? 0 : 2, last = c.pair == CcdPair::kVertexFace ? 0 : 3;
  for (int i = first; i <= last; ++i) {
    c.start[i][axis] += d;
    c.end[i][axis] += d;
  }
  c.constructed_contact = false;
  c.witness.reset();
  return c;
}

/// Permutes the axes and flips signs (exact), so axis-aligned constructions cover all axes.
Case reoriented(Case c, Gen& g) {
  int perm[3] = {0, 1, 2};
  std::shuffle(perm, perm + 3, g.rng());
  const Vec3 sign(g.coin() ? 1 : -1, g.coin() ? 1 : -1, g.coin() ? 1 : -1);
  const Vec3 shift = g.point();
  for (CcdPoints* x : {&c.start, &c.end}) {
    for (Vec3& p : *x) {
      const Vec3 q = p;
      for (int k = 0; k < 3; ++k) p[k] = sign[k] * q[perm[k]] + shift[k];
    }
  }
  return c;
}

/// Vertex sliding parallel to a triangle in z = 0 at height h, over its interior or beside an edge.
Case vf_grazing(Gen& g, Scalar h) {
  Case c;
  c.pair = CcdPair::kVertexFace;
  const Scalar s = g.scale();
  c.start[1] = c.end[1] = Vec3(0, 0, 0);
  c.start[2] = c.end[2] = Vec3(s, 0, 0);
  c.start[3] = c.end[3] = Vec3(0, s, 0);
  // Passes along the line x + y = k (k ≤ 1 crosses the triangle; k > 1 misses by k - 1).
  const Scalar k = g.coin() ? 0.5 : (g.coin() ? 1 : 1 + 0x1p-30);
  c.start[0] = Vec3(-s, (k + 1) * s, h * s);
  c.end[0] = Vec3((k + 1) * s, -s, h * s);
  if (k <= 1) c.witness = {0.5, k / 2, k / 2};  // a contact when |h| s ≤ δ
  return reoriented(c, g);
}

/// Collinear or parallel edges sliding along their common direction, offset by h.
Case ee_parallel(Gen& g, Scalar h) {
  Case c;
  c.pair = CcdPair::kEdgeEdge;
  const Scalar s = g.scale();
  c.start[0] = c.end[0] = Vec3(0, 0, 0);
  c.start[1] = c.end[1] = Vec3(s, 0, 0);
  const Scalar from = g.coin() ? 2 * s : 1.5 * s, to = g.coin() ? 0.5 * s : 1.25 * s;
  c.start[2] = Vec3(from, h * s, 0);
  c.start[3] = Vec3(from + s, h * s, 0);
  c.end[2] = Vec3(to, h * s, 0);
  c.end[3] = Vec3(to + s, h * s, 0);
  if (to == 0.5 * s) c.witness = {1, 0.5, 0};  // a contact when |h| s ≤ δ
  return reoriented(c, g);
}

/// Degenerate primitives: a triangle collapsed to a segment or a point, or zero-length edges,
/// through which the other primitive is driven to a constructed contact.
Case degenerate(Gen& g) {
  Case c = g.coin() ? vf_contact(g) : ee_contact(g);
  if (c.pair == CcdPair::kVertexFace) {
    const bool point = g.coin();
    for (CcdPoints* x : {&c.start, &c.end}) {
      (*x)[3] = point ? (*x)[1] : ((*x)[1] + (*x)[2]) / 2;
      if (point) (*x)[2] = (*x)[1];
    }
    // Re-aim the vertex at the degenerate triangle's first corner at t* = 1/2.
    const Vec3 q = at(c.start[1], c.end[1], 0.5);
    std::tie(c.start[0], c.end[0]) = g.through(q, 0.5);
  } else {
    for (CcdPoints* x : {&c.start, &c.end}) (*x)[1] = (*x)[0];
    const Vec3 q = at(c.start[0], c.end[0], 0.5);
    std::tie(c.start[2], c.end[2]) = g.through(q, 0.5);
  }
  c.witness = {0.5, 0, 0};
  return c;
}

/// Zero motion: end = start, touching (t* = 0 construction) or not.
Case zero_motion(Gen& g) {
  Case c = g.coin() ? vf_contact(g) : ee_contact(g);
  c.end = c.start;
  c.constructed_contact = false;  // the construction's t* was for the moving version
  c.witness.reset();
  return c;
}

Case generic(Gen& g) {
  Case c;
  c.pair = g.coin() ? CcdPair::kVertexFace : CcdPair::kEdgeEdge;
  for (int i = 0; i < 4; ++i) {
    c.start[i] = g.point();
    c.end[i] = (c.start[i] + 4 * g.small()).eval();
  }
  return c;
}

/// Touching exactly at t = 0 or t = 1 at a shared point, with full 53-bit coordinates (not the
/// grid): the vertex on a triangle corner f1 or f2, or an endpoint of edge a on one of edge b.
/// Evaluating F at the contact rounds (e.g. (p - f0) + (f0 - f1)), so these exercise the
/// rounding bound: without it the bisection rejects some of them.
Case touching_shared_point(Gen& g) {
  Case c;
  c.pair = g.coin() ? CcdPair::kVertexFace : CcdPair::kEdgeEdge;
  std::uniform_real_distribution<Scalar> unit(-1, 1);
  const Scalar scale = g.scale() * (1 + unit(g.rng()) / 3);  // not a power of two
  for (int i = 0; i < 4; ++i) {
    c.start[i] = Vec3(unit(g.rng()), unit(g.rng()), unit(g.rng())) * scale;
    c.end[i] = (c.start[i] + Vec3(unit(g.rng()), unit(g.rng()), unit(g.rng())) * (scale / 4)).eval();
  }
  const Scalar t = g.coin() ? 0 : 1;
  CcdPoints& x = t == 0 ? c.start : c.end;
  const int which = g.integer(0, c.pair == CcdPair::kVertexFace ? 1 : 2);
  if (c.pair == CcdPair::kVertexFace) {
    x[0] = x[2 + which];  // p = f1 (u = 1) or f2 (v = 1)
    c.witness = {t, which == 0 ? 1.0 : 0.0, which == 0 ? 0.0 : 1.0};
  } else if (which == 0) {
    x[1] = x[2];  // a1 = b0
    c.witness = {t, 1.0, 0.0};
  } else if (which == 1) {
    x[0] = x[3];  // a0 = b1
    c.witness = {t, 0.0, 1.0};
  } else {
    x[1] = x[3];  // a1 = b1
    c.witness = {t, 1.0, 1.0};
  }
  c.constructed_contact = true;
  return c;
}

struct Tally {
  int queries = 0, yes = 0, no = 0, undecided = 0;
  int hits = 0, false_negatives = 0, false_positives = 0;
  int toi_late = 0, toi_certified = 0, toi_exact_checked = 0, tolerance_failures = 0;
  int constructed_not_yes = 0;
  int crossings = 0;  // "yes" certified by a coplanarity crossing
  std::map<std::string, int> outcomes;
};

Scalar lipschitz(const Case& c) {
  const auto disp = [&](int i) { return (c.end[i] - c.start[i]).norm(); };
  if (c.pair == CcdPair::kVertexFace) return disp(0) + std::max({disp(1), disp(2), disp(3)});
  return std::max(disp(0), disp(1)) + std::max(disp(2), disp(3));
}

/// The library's ε for this query (same formula: extent of the difference points).
Scalar epsilon(const Case& c, const CcdOptions& o) {
  Scalar extent = 0;
  for (const CcdPoints* x : {&c.start, &c.end}) {
    const CcdPoints& p = *x;
    if (c.pair == CcdPair::kVertexFace) {
      for (int i = 1; i < 4; ++i) extent = std::max(extent, (p[0] - p[i]).cwiseAbs().maxCoeff());
    } else {
      for (int i = 0; i < 2; ++i) {
        for (int j = 2; j < 4; ++j) extent = std::max(extent, (p[i] - p[j]).cwiseAbs().maxCoeff());
      }
    }
  }
  const Scalar err = ccd_rounding_bound(c.start, c.end).maxCoeff();
  return std::max(o.distance_tolerance * extent, 4 * err);
}

void check(const Case& c, const CcdOptions& base, Tally& tally, std::int64_t oracle_budget) {
  CcdOptions o = base;
  o.min_separation = c.delta;
  const CcdResult r = ccd(c.pair, c.start, c.end, o);
  const co::Query q = co::make_query(c.pair == CcdPair::kVertexFace, c.start, c.end, c.delta);
  // A verified witness decides "yes" by itself; the branch and bound then only certifies a
  // lower bound on the first contact, so it runs on every 8th such query.
  const bool witnessed =
      c.witness && co::contact_at(q, co::Q((*c.witness)[0]), co::Q((*c.witness)[1]), co::Q((*c.witness)[2]));
  co::Decision d;
  if (!witnessed || tally.queries % 8 == 0) d = co::decide(q, oracle_budget);
  if (witnessed && d.verdict != co::Verdict::kYes) {
    d.verdict = co::Verdict::kYes;
    d.exact_toi = false;
    d.toi_hi = co::Q((*c.witness)[0]);
  } else if (witnessed && co::Q((*c.witness)[0]) < d.toi_hi) {
    d.toi_hi = co::Q((*c.witness)[0]);
    d.exact_toi = d.toi_hi == d.toi_lo;
  }
  // δ = 0 and still open: a certified crossing of the coplanarity function inside the
  // triangle (between the edges) is a contact at an irrational time.
  co::Q crossing;
  if (d.verdict != co::Verdict::kYes && c.delta == 0 &&
      co::certified_crossing(co::make_points(c.pair == CcdPair::kVertexFace, c.start, c.end), crossing)) {
    if (d.verdict == co::Verdict::kNo) ADD_FAILURE() << "oracle: kNo but a certified crossing: " << hex(c);
    d.verdict = co::Verdict::kYes;
    d.exact_toi = false;
    d.toi_hi = crossing;
    ++tally.crossings;
  }
  ++tally.queries;
  ++tally.outcomes[std::string(to_string(r.outcome))];
  if (r.hit) ++tally.hits;
  if (c.constructed_contact && !witnessed) {
    ++tally.constructed_not_yes;
    ADD_FAILURE() << "generator: constructed contact not exact: " << hex(c);
  }
  switch (d.verdict) {
    case co::Verdict::kYes:
      ++tally.yes;
      if (!r.hit) {
        ++tally.false_negatives;
        ADD_FAILURE() << "FALSE NEGATIVE: " << hex(c);
        break;
      }
      if (co::Q(r.toi) > d.toi_hi) {
        ++tally.toi_late;
        ADD_FAILURE() << "toi " << r.toi << " later than a contact at " << d.toi_hi.get_d() << ": " << hex(c);
      }
      if (co::Q(r.toi) <= d.toi_lo) ++tally.toi_certified;
      if (d.exact_toi) ++tally.toi_exact_checked;
      break;
    case co::Verdict::kNo:
      ++tally.no;
      if (r.hit) ++tally.false_positives;
      break;
    case co::Verdict::kUndecided:
      ++tally.undecided;
      // No contact before toi_lo is certified: a reported toi is only wrong if it is later
      // than a contact, which the oracle could not exhibit.
      break;
  }
  if (r.hit && r.outcome == CcdOutcome::kHitTolerance) {
    const Scalar err = ccd_rounding_bound(c.start, c.end).norm();
    const Scalar tol = std::clamp(o.time_tolerance, 0x1p-40, 1.0);
    const Scalar reach = ((c.delta * (1 + o.separation_tolerance) + 2 * err + epsilon(c, o)) * (1 + 1e-9) +
                          lipschitz(c) * tol / 64);
    const co::Q reach2 = co::Q(reach) * co::Q(reach);
    bool ok = false;
    for (int k = 0; k <= 32 && !ok; ++k) {
      co::Q t = co::Q(r.toi) + co::Q(tol) * k / 32;
      if (t > 1) t = 1;
      ok = co::exact_distance2(q, t) <= reach2;
    }
    if (!ok) {
      ++tally.tolerance_failures;
      ADD_FAILURE() << "tolerance: no near-contact within [toi, toi + tol] for toi " << r.toi << ": " << hex(c);
    }
  }
}

void print(const char* name, const Tally& t) {
  std::printf("[ ccd      ] %-28s n=%5d oracle yes/no/undecided=%d/%d/%d hits=%d FN=%d FP=%d "
              "toi certified %d/%d (exact %d) late=%d tol-fail=%d crossings=%d |",
              name, t.queries, t.yes, t.no, t.undecided, t.hits, t.false_negatives, t.false_positives,
              t.toi_certified, t.yes, t.toi_exact_checked, t.toi_late, t.tolerance_failures, t.crossings);
  for (const auto& [k, v] : t.outcomes) std::printf(" %s:%d", k.c_str(), v);
  std::printf("\n");
}

void run(const char* name, int n, std::uint64_t seed, const std::function<Case(Gen&)>& make,
         Scalar delta_rel = 0, std::int64_t oracle_budget = 300) {
  Tally tally;
#ifdef CRUMPLE_SANITIZED
  n = (n + 2) / 3;  // the oracle dominates and gains nothing from the sanitizers: a third of the draws
#endif
  static const Scalar kScales[] = {1, 0x1p-66, 0x1p66, 0x1p-20, 0x1p30};
  std::printf("[ seed     ] %s: mt19937_64 seed = %" PRIu64 "\n", name, seed);
  Gen g(seed, 1);
  for (int i = 0; i < n; ++i) {
    Gen gi(g.rng()(), kScales[i % 5]);
    Case c = make(gi);
    c.delta = delta_rel * gi.scale();
    check(c, CcdOptions{}, tally, oracle_budget);
  }
  print(name, tally);
  EXPECT_EQ(tally.false_negatives, 0);
  EXPECT_EQ(tally.toi_late, 0);
  EXPECT_EQ(tally.tolerance_failures, 0);
  EXPECT_EQ(tally.constructed_not_yes, 0);
}

TEST(CcdOracle, VertexFaceContacts) { run("vf-contact", 600, 1, vf_contact); }
TEST(CcdOracle, EdgeEdgeContacts) { run("ee-contact", 600, 2, ee_contact); }
TEST(CcdOracle, TouchingAtASharedPointWithFullPrecision) {
  run("touching-shared-point", 1500, 5, touching_shared_point, 0, 50);
}
TEST(CcdOracle, ContactsWithMinimumSeparation) {
  run("vf-contact delta", 200, 3, vf_contact, 0x1p-10);
  run("ee-contact delta", 200, 4, ee_contact, 0x1p-10);
}

TEST(CcdOracle, NearMisses) {
  for (const Scalar gap : {1e-10, 1e-12, 1e-7}) {
    run("vf-near-miss", 60, 10, [gap](Gen& g) { return shifted(vf_contact(g), g, gap); }, 0, 100);
    run("ee-near-miss", 60, 11, [gap](Gen& g) { return shifted(ee_contact(g), g, gap); }, 0, 100);
  }
  // Within δ by a hair and outside δ by a hair.
  for (const Scalar gap : {0x1p-10 * (1 - 1e-10), 0x1p-10 * (1 + 1e-10)}) {
    run("vf-near-miss delta", 100, 12, [gap](Gen& g) { return shifted(vf_contact(g), g, gap); }, 0x1p-10);
    run("ee-near-miss delta", 100, 13, [gap](Gen& g) { return shifted(ee_contact(g), g, gap); }, 0x1p-10);
  }
}

TEST(CcdOracle, GrazingAndParallelSliding) {
  for (const Scalar h : {0.0, 1e-10, -1e-12}) {
    run("vf-grazing", 60, 20, [h](Gen& g) { return vf_grazing(g, h); });
    run("ee-parallel", 60, 21, [h](Gen& g) { return ee_parallel(g, h); });
  }
  for (const Scalar h : {0x1p-10, 0x1p-10 * (1 + 1e-10)}) {
    run("vf-grazing delta", 60, 22, [h](Gen& g) { return vf_grazing(g, h); }, 0x1p-10);
    run("ee-parallel delta", 60, 23, [h](Gen& g) { return ee_parallel(g, h); }, 0x1p-10);
  }
}

TEST(CcdOracle, DegenerateAndZeroMotion) {
  run("degenerate", 300, 30, degenerate);
  run("zero-motion", 300, 31, zero_motion);
  run("zero-motion delta", 200, 32, zero_motion, 0x1p-10);
}

TEST(CcdOracle, GenericSmallMotions) {
  run("generic", 400, 40, generic);
  run("generic delta", 200, 41, generic, 0x1p-6);
}

}  // namespace
}  // namespace crumple::geometry

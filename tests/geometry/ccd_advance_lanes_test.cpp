// The narrow phase after the batched filters with its conservative advancement in four lanes
// (geometry/ccd_detail.hpp, `ccd_after_direction` on a span) against the same narrow phase one
// query at a time: every query must get the scalar result field for field (hit, the TOI's bits,
// outcome, boxes, advancement steps). The queries advance from 1 to hundreds of steps (rotating
// and near-parallel edges, vertices sliding over and falling through triangles, degenerate
// triangles, queries outside the lanes' range mixed in), so that lanes end at different steps
// and are refilled mid-way; they run as one span, in pieces of every size from 1 to 9, and
// shuffled, at δ = 0 and δ > 0, with small step budgets and max_time < 1.
#include <crumple/geometry/ccd.hpp>
#include <crumple/geometry/ccd_detail.hpp>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

namespace crumple::geometry {
namespace {

using detail::CcdQuery;

/// Queries whose advancement takes few to many steps, for `pair`.
std::vector<CcdQuery> make_queries(CcdPair pair, std::uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<Scalar> unit(-1, 1);
  const auto rnd = [&] { return Vec3(unit(rng), unit(rng), unit(rng)); };
  const bool face = pair == CcdPair::kVertexFace;
  std::vector<CcdQuery> out;
  const auto add = [&](CcdQuery q, Scalar scale, const Vec3& origin) {
    for (std::size_t i = 0; i < 4; ++i) {
      q.start[i] = (q.start[i] + origin) * scale;
      q.end[i] = (q.end[i] + origin) * scale;
    }
    out.push_back(q);
  };
  const Scalar gaps[] = {0, 1e-9, 1e-6, 1e-4, 1e-3, 1e-2, 0.05, 0.2};
  for (const Scalar scale : {Scalar(1), Scalar(0x1p40), Scalar(0x1p-20), Scalar(0x1p-320), Scalar(0x1p310)}) {
    const int rounds = scale == 1 ? 12 : 3;
    for (int n = 0; n < rounds; ++n) {
      const Vec3 origin = n % 3 == 2 ? Vec3(1e3, -2e3, 5e2) : Vec3::Zero();
      const Eigen::Matrix3d turn =
          Eigen::Quaterniond(unit(rng), unit(rng), unit(rng), unit(rng)).normalized().toRotationMatrix();
      for (const Scalar gap : gaps) {
        // Rotation about an axis through the first feature: a twisting pair (many steps).
        const Scalar angle = 0.3 + unit(rng);
        const Eigen::Matrix3d spin = Eigen::AngleAxisd(angle, Vec3::UnitZ()).toRotationMatrix();
        const Eigen::Matrix3d tilt_spin =
            Eigen::AngleAxisd(angle, Vec3(1, 0.3 * unit(rng), 0.2 * unit(rng)).normalized()).toRotationMatrix();
        CcdQuery q;
        if (face) {
          q.start = {Vec3(0.3 * unit(rng), 0.3 * unit(rng), gap), Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(0, 1, 0)};
          q.end = q.start;
          for (std::size_t i = 1; i < 4; ++i) q.end[i] = (n % 2 == 0 ? spin : tilt_spin) * q.start[i];
          q.end[0] = q.start[0] + Vec3(0.5 * unit(rng), 0.5 * unit(rng), -gap * (n % 2 == 0 ? 2 : 0.5));
        } else {
          q.start = {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0.2 * unit(rng), -1, gap), Vec3(0.2 * unit(rng), 1, gap)};
          q.end = q.start;
          q.end[2] = spin * q.start[2] + Vec3(0, 0, n % 2 == 0 ? -2 * gap : 0);
          q.end[3] = spin * q.start[3] + Vec3(0, 0, n % 2 == 0 ? -2 * gap : 0);
        }
        for (std::size_t i = 0; i < 4; ++i) {
          q.start[i] = turn * q.start[i];
          q.end[i] = turn * q.end[i];
        }
        add(q, scale, origin);
        // Near-parallel sliding: the second feature just above the first, nearly parallel to it.
        CcdQuery slide;
        const Vec3 tilt = 1e-3 * rnd();
        if (face) {
          slide.start = {Vec3(-1.5, 0.1 * unit(rng), gap), Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(0, 1, 0)};
          slide.end = slide.start;
          slide.end[0] = Vec3(1.5, 0.1 * unit(rng), gap * 0.5) + tilt;
        } else {
          slide.start = {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(-1, 0, gap) + tilt, Vec3(1, 0, gap) - tilt};
          slide.end = slide.start;
          slide.end[2] += Vec3(0.5, 0.1 * unit(rng), -gap * 0.5);
          slide.end[3] += Vec3(0.5, 0.1 * unit(rng), -gap * 0.5);
        }
        for (std::size_t i = 0; i < 4; ++i) {
          slide.start[i] = turn * slide.start[i];
          slide.end[i] = turn * slide.end[i];
        }
        add(slide, scale, origin);
      }
      // Generic small motions near each other.
      for (int g = 0; g < 4; ++g) {
        CcdQuery q;
        for (std::size_t i = 0; i < 4; ++i) {
          q.start[i] = rnd() * (i == 0 ? 0.3 : 1.0);
          q.end[i] = q.start[i] + 0.4 * rnd();
        }
        add(q, scale, origin);
      }
      // A degenerate triangle (collinear corners) or a zero-length edge, no motion, and a
      // pair touching at t = 0.
      CcdQuery flat;
      flat.start = {Vec3(0, 0.2, 0.1), Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 0, 0)};
      if (!face) flat.start = {Vec3(0, 0.2, 0.1), Vec3(0, 0.2, 0.1), Vec3(-1, 0, 0), Vec3(1, 0, 0)};
      flat.end = flat.start;
      flat.end[0] += Vec3(0.3, -0.4, -0.2);
      if (!face) flat.end[1] = flat.end[0];
      add(flat, scale, origin);
      CcdQuery still;
      for (std::size_t i = 0; i < 4; ++i) still.start[i] = still.end[i] = rnd();
      add(still, scale, origin);
      CcdQuery touching;
      touching.start = {Vec3(0.1, 0.1, 0), Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(0, 1, 0)};
      if (!face) touching.start = {Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, -1, 0), Vec3(0, 1, 0)};
      touching.end = touching.start;
      touching.end[0] += Vec3(0.2, 0.1, 0.3);
      add(touching, scale, origin);
    }
  }
  return out;
}

bool same(const CcdResult& a, const CcdResult& b) {
  return a.hit == b.hit && std::signbit(a.toi) == std::signbit(b.toi) && a.toi == b.toi && a.outcome == b.outcome &&
         a.boxes == b.boxes && a.advance_steps == b.advance_steps;
}

/// The lanes on `queries` in pieces of `piece` queries (0: one span) against the scalar path.
void expect_scalar_results(CcdPair pair, const std::vector<CcdQuery>& queries, const CcdOptions& options,
                           std::size_t piece, const char* what) {
  std::vector<CcdResult> lanes(queries.size());
  const std::size_t step = piece == 0 ? queries.size() : piece;
  for (std::size_t begin = 0; begin < queries.size(); begin += step) {
    const std::size_t n = std::min(step, queries.size() - begin);
    detail::ccd_after_direction(pair, {queries.data() + begin, n}, options, lanes.data() + begin, true);
  }
  for (std::size_t i = 0; i < queries.size(); ++i) {
    const CcdResult scalar = detail::ccd_after_direction(pair, queries[i].start, queries[i].end, options);
    ASSERT_TRUE(same(lanes[i], scalar)) << what << " query " << i << " piece " << piece << ": lanes " << lanes[i].hit
                                        << " " << lanes[i].toi << " " << to_string(lanes[i].outcome) << " "
                                        << lanes[i].advance_steps << ", scalar " << scalar.hit << " " << scalar.toi
                                        << " " << to_string(scalar.outcome) << " " << scalar.advance_steps;
  }
}

TEST(CcdAdvanceLanes, EveryLaneGivesTheScalarResult) {
  if (!detail::ccd_has_avx2()) GTEST_SKIP() << "no AVX2: the lanes do not run";
  for (const CcdPair pair : {CcdPair::kVertexFace, CcdPair::kEdgeEdge}) {
    std::vector<CcdQuery> queries = make_queries(pair, pair == CcdPair::kVertexFace ? 11u : 12u);
    const char* what = pair == CcdPair::kVertexFace ? "vf" : "ee";
    for (const Scalar delta : {Scalar(0), Scalar(1e-3)}) {
      CcdOptions o;
      o.min_separation = delta;
      // The lanes must see queries ending at many different steps, hits and separations.
      std::vector<std::int64_t> steps;
      int hits = 0, advanced_apart = 0, bisected = 0;
      for (const CcdQuery& q : queries) {
        const CcdResult r = detail::ccd_after_direction(pair, q.start, q.end, o);
        steps.push_back(r.advance_steps);
        hits += r.outcome == CcdOutcome::kHitTolerance && r.boxes == 0;
        advanced_apart += r.outcome == CcdOutcome::kSeparatedAdvancement;
        bisected += r.boxes > 0;
      }
      std::sort(steps.begin(), steps.end());
      EXPECT_GT(hits, 20) << what;
      EXPECT_GT(advanced_apart, 20) << what;
      EXPECT_GE(steps.back(), 30) << what;
      EXPECT_GE(std::unique(steps.begin(), steps.end()) - steps.begin(), 10) << what << ": distinct step counts";
      std::printf("[ lanes ] %s delta %g: %zu queries, %d advancement hits, %d apart, %d bisected, up to %lld steps\n",
                  what, delta, queries.size(), hits, advanced_apart, bisected, static_cast<long long>(steps.back()));
      for (const std::size_t piece : {0, 1, 2, 3, 4, 5, 9}) expect_scalar_results(pair, queries, o, piece, what);
      // Budgets that stop the advancement early, and a running minimum below 1.
      CcdOptions budget = o;
      budget.max_advance_steps = 3;
      budget.max_boxes = 20;
      expect_scalar_results(pair, queries, budget, 0, what);
      budget.max_advance_steps = 0;
      expect_scalar_results(pair, queries, budget, 0, what);
      CcdOptions early = o;
      early.max_time = 0.3;
      expect_scalar_results(pair, queries, early, 0, what);
      // Another order: other neighbours in the lanes.
      std::vector<CcdQuery> shuffled = queries;
      std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937_64(5));
      expect_scalar_results(pair, shuffled, o, 0, what);
    }
  }
}

TEST(CcdAdvanceLanes, ANonFiniteCoordinateIsNeverAdvancedApart) {
  // Far apart at both times, so that the lanes' hull test would mark the query apart; with a
  // NaN or an infinity in any of its 24 coordinates it must leave the lanes for the scalar
  // path, which reports it a conservative hit (out of range). The finite query beside it in
  // the lanes keeps its own result.
  if (!detail::ccd_has_avx2()) GTEST_SKIP() << "no AVX2: the lanes do not run";
  for (const CcdPair pair : {CcdPair::kVertexFace, CcdPair::kEdgeEdge}) {
    CcdQuery apart;
    if (pair == CcdPair::kVertexFace) {
      apart.start = {Vec3(0.2, 0.2, 5), Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(0, 1, 0)};
      apart.end = {Vec3(0.3, 0.1, 5), Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(0, 1, 0)};
    } else {
      apart.start = {Vec3(-1, 0, 5), Vec3(1, 0, 5), Vec3(0, -1, 0), Vec3(0, 1, 0)};
      apart.end = {Vec3(-1, 0.1, 5), Vec3(1, 0.1, 5), Vec3(0, -1, 0), Vec3(0, 1, 0)};
    }
    CcdResult finite[1];
    detail::ccd_after_direction(pair, {&apart, 1}, CcdOptions{}, finite, true);
    ASSERT_EQ(finite[0].outcome, CcdOutcome::kSeparatedHull) << "the finite query is not a case for the hull test";
    for (const Scalar bad : {std::nan(""), Scalar(INFINITY), -Scalar(INFINITY)}) {
      for (int slot = 0; slot < 24; ++slot) {
        CcdQuery q = apart;
        (slot < 12 ? q.start : q.end)[(slot % 12) / 3][slot % 3] = bad;
        const CcdQuery batch[2] = {q, apart};
        CcdResult out[2];
        detail::ccd_after_direction(pair, batch, CcdOptions{}, out, true);
        EXPECT_TRUE(out[0].hit) << "slot " << slot << " value " << bad;
        EXPECT_EQ(out[0].outcome, CcdOutcome::kHitOutOfRange) << "slot " << slot << " value " << bad;
        EXPECT_EQ(out[1].outcome, CcdOutcome::kSeparatedHull) << "slot " << slot;
      }
    }
  }
}

}  // namespace
}  // namespace crumple::geometry

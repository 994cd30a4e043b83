// The batched coplanarity and separating-direction filters of the narrow phase
// (geometry/ccd_detail.hpp) against the narrow phase itself (`ccd`), on queries that make them
// decide both ways: a query a filter marks apart must get no hit from `ccd` (outcome that
// filter or one before it); every query whose filter `ccd` ran and rejected with must be
// marked apart; every other query must get from `ccd_after_coplanarity` / `ccd_after_direction`
// exactly `ccd`'s result. Both kernels (four AVX2 lanes
// where the processor has them, the portable one) give the same marks, for every batch size
// (partial batches repeat query 0 in the unused lanes).
#include <crumple/geometry/ccd.hpp>
#include <crumple/geometry/ccd_detail.hpp>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <random>
#include <span>
#include <vector>

namespace crumple::geometry {
namespace {

using detail::CcdQuery;

/// Queries around the coplanarity boundary: a vertex or edge crossing a plane (coplanar at some
/// t), the same lifted off the plane by 1e-16 .. 1e-3 of the scale (never coplanar, some within
/// the filters' rounding bands), the plane turned at random, generic motion, at scales 2^-320 (below
/// the unscaled range: `ccd` scales the query first), 1, 2^40 and 2^310 (above the range), and
/// off the origin.
std::vector<CcdQuery> make_queries(std::uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<Scalar> unit(-1, 1);
  const auto rnd = [&] { return Vec3(unit(rng), unit(rng), unit(rng)); };
  const Scalar scales[] = {0x1p-320, 1, 0x1p40, 0x1p310};
  const Scalar lifts[] = {0, 1e-16, 2e-16, 4e-16, 8e-16, 2e-15, 4e-15, 1e-14, 1e-12, 1e-8, 1e-3};
  std::vector<CcdQuery> out;
  for (const Scalar scale : scales) {
    for (int n = 0; n < 60; ++n) {
      const Vec3 origin = n % 3 == 0 ? Vec3(1e3, -2e3, 5e2) : Vec3::Zero();
      for (const Scalar lift : lifts) {
        // Three points in z = 0 (a triangle, or an edge and one endpoint of another), still;
        // the fourth crosses the plane (lift 0) or slides parallel to it at height `lift`.
        CcdQuery q;
        for (std::size_t i = 1; i < 4; ++i) {
          q.start[i] = Vec3(unit(rng), unit(rng), 0);
          q.end[i] = n % 2 == 0 ? q.start[i] : Vec3(unit(rng), unit(rng), 0);
        }
        if (lift == 0) {
          q.start[0] = Vec3(unit(rng) / 3, unit(rng) / 3, 0.5);
          q.end[0] = Vec3(unit(rng) / 3, unit(rng) / 3, -0.5);
        } else {
          q.start[0] = Vec3(unit(rng), unit(rng), lift);
          q.end[0] = Vec3(unit(rng), unit(rng), lift);
        }
        // Turned off the axes (on them the determinants' bounds shrink with the lift too).
        const Eigen::Matrix3d turn = n % 4 == 1 ? Eigen::Matrix3d::Identity().eval()
                                                : Eigen::Quaterniond(unit(rng), unit(rng), unit(rng), unit(rng))
                                                      .normalized()
                                                      .toRotationMatrix();
        for (std::size_t i = 0; i < 4; ++i) {
          q.start[i] = (turn * q.start[i] + origin) * scale;
          q.end[i] = (turn * q.end[i] + origin) * scale;
        }
        out.push_back(q);
      }
      CcdQuery generic;
      for (std::size_t i = 0; i < 4; ++i) {
        generic.start[i] = rnd() * scale;
        generic.end[i] = (generic.start[i] / scale + 0.3 * rnd()) * scale;
      }
      out.push_back(generic);
    }
  }
  return out;
}

bool same(const CcdResult& a, const CcdResult& b) {
  return a.hit == b.hit && std::signbit(a.toi) == std::signbit(b.toi) && a.toi == b.toi &&
         a.outcome == b.outcome && a.boxes == b.boxes && a.advance_steps == b.advance_steps;
}

Scalar largest(const CcdQuery& q) {
  Scalar m = 0;
  for (std::size_t i = 0; i < 4; ++i) m = std::max({m, q.start[i].cwiseAbs().maxCoeff(), q.end[i].cwiseAbs().maxCoeff()});
  return m;
}

TEST(CcdBatch, CoplanarityMarksAreTheNarrowPhasesRejections) {
  const std::vector<CcdQuery> queries = make_queries(42);
  std::vector<std::uint8_t> portable(queries.size()), avx2(queries.size());
  detail::ccd_never_coplanar(queries, portable.data(), false);
  detail::ccd_never_coplanar(queries, avx2.data(), true);  // the portable kernel without AVX2
  int marked = 0, kept = 0, kept_hits = 0, rejected_unscaled = 0;
  for (std::size_t i = 0; i < queries.size(); ++i) {
    const CcdQuery& q = queries[i];
    ASSERT_EQ(portable[i], avx2[i]) << i;
    for (const CcdPair pair : {CcdPair::kVertexFace, CcdPair::kEdgeEdge}) {
      const CcdResult full = ccd(pair, q.start, q.end);
      const bool unscaled = largest(q) >= 0x1p-300 && largest(q) <= 0x1p300;
      if (portable[i] != 0) {
        ++marked;
        EXPECT_FALSE(full.hit) << i;
        EXPECT_TRUE(full.outcome == CcdOutcome::kSeparatedHull || full.outcome == CcdOutcome::kSeparatedCoplanarity)
            << i << " " << to_string(full.outcome);
        EXPECT_TRUE(unscaled) << i;
      } else {
        ++kept;
        kept_hits += full.hit;
        // The batch finds every rejection of the filter it stands for.
        if (unscaled) {
          EXPECT_NE(full.outcome, CcdOutcome::kSeparatedCoplanarity) << i;
        }
        EXPECT_TRUE(same(detail::ccd_after_coplanarity(pair, q.start, q.end, {}), full)) << i;
      }
      rejected_unscaled += unscaled && full.outcome == CcdOutcome::kSeparatedCoplanarity;
    }
  }
  std::printf("[ ccd batch ] %zu queries x 2 pairs: %d marked apart, %d kept (%d hits), avx2 %s\n", queries.size(),
              marked, kept, kept_hits, detail::ccd_has_avx2() ? "yes" : "no");
  // Both answers occur in number, hits among the kept ones.
  EXPECT_GT(marked, 300);
  EXPECT_GT(kept, 300);
  EXPECT_GT(kept_hits, 50);
  EXPECT_GT(rejected_unscaled, 200);
}

TEST(CcdBatch, DirectionMarksAreTheNarrowPhasesRejections) {
  const std::vector<CcdQuery> queries = make_queries(11);
  std::vector<std::uint8_t> coplanar(queries.size());
  detail::ccd_never_coplanar(queries, coplanar.data(), false);
  int marked = 0, kept = 0, kept_hits = 0;
  for (const Scalar relative : {0.0, 1e-9, 1e-4}) {
    for (const CcdPair pair : {CcdPair::kVertexFace, CcdPair::kEdgeEdge}) {
      // In index batches of up to 16 (the mesh query's queue), every other query.
      for (std::size_t begin = 0; begin < queries.size(); begin += 32) {
        std::vector<std::uint8_t> index;
        for (std::size_t i = begin; i < std::min(begin + 32, queries.size()); i += 2) {
          index.push_back(static_cast<std::uint8_t>(i - begin));
        }
        const std::span<const CcdQuery> batch(queries.data() + begin, std::min<std::size_t>(32, queries.size() - begin));
        const Scalar delta = relative * largest(batch[0]);
        std::uint8_t portable[16] = {}, avx2[16] = {};
        detail::ccd_separated_by_a_direction(pair, batch, index, delta, portable, false);
        detail::ccd_separated_by_a_direction(pair, batch, index, delta, avx2, true);
        for (std::size_t j = 0; j < index.size(); ++j) {
          const CcdQuery& q = batch[index[j]];
          ASSERT_EQ(portable[j], avx2[j]) << begin + index[j];
          CcdOptions o;
          o.min_separation = delta;
          const CcdResult full = ccd(pair, q.start, q.end, o);
          const bool unscaled = largest(q) >= 0x1p-300 && largest(q) <= 0x1p300;
          if (portable[j] != 0) {
            ++marked;
            EXPECT_FALSE(full.hit);
            EXPECT_TRUE(full.outcome == CcdOutcome::kSeparatedHull || full.outcome == CcdOutcome::kSeparatedCoplanarity ||
                        full.outcome == CcdOutcome::kSeparatedDirection)
                << to_string(full.outcome);
            EXPECT_TRUE(unscaled);
            continue;
          }
          if (unscaled) {
            EXPECT_NE(full.outcome, CcdOutcome::kSeparatedDirection) << begin + index[j] << " delta " << delta;
          }
          if (delta == 0 && coplanar[begin + index[j]] != 0) continue;
          ++kept;
          kept_hits += full.hit;
          EXPECT_TRUE(same(detail::ccd_after_direction(pair, q.start, q.end, o), full)) << begin + index[j];
        }
      }
    }
  }
  std::printf("[ ccd batch ] direction: %d marked apart, %d kept (%d hits)\n", marked, kept, kept_hits);
  EXPECT_GT(marked, 300);
  EXPECT_GT(kept, 300);
  EXPECT_GT(kept_hits, 50);
}

TEST(CcdBatch, ANonFiniteCoordinateIsNeverMarkedApart) {
  // Far apart at both times, so that without the non-finite coordinate both filters would
  // mark the query apart; with a NaN or an infinity in any of the 24 coordinates neither may
  // (the query is then `ccd`'s, which reports it out of range).
  CcdQuery apart;
  apart.start = {Vec3(0.2, 0.2, 5), Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(0, 1, 0)};
  apart.end = {Vec3(0.3, 0.1, 5), Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(0, 1, 0)};
  for (const bool avx2 : {false, true}) {
    for (const CcdPair pair : {CcdPair::kVertexFace, CcdPair::kEdgeEdge}) {
      std::uint8_t index[1] = {0}, mark[1] = {9};
      detail::ccd_separated_by_a_direction(pair, {&apart, 1}, index, 0.0, mark, avx2);
      ASSERT_EQ(mark[0], 1) << "the finite query is not a case for the filter";
      for (const Scalar bad : {std::nan(""), Scalar(INFINITY)}) {
        for (int slot = 0; slot < 24; ++slot) {
          CcdQuery q = apart;
          (slot < 12 ? q.start : q.end)[(slot % 12) / 3][slot % 3] = bad;
          // Lane 0 carries the bad query; partial batches repeat it in the other lanes, so a
          // batch of two puts a finite query beside it.
          const CcdQuery batch[2] = {q, apart};
          std::uint8_t two[2] = {0, 1}, marks[2] = {9, 9}, coplanar[2] = {9, 9};
          detail::ccd_separated_by_a_direction(pair, batch, two, 0.0, marks, avx2);
          detail::ccd_never_coplanar(batch, coplanar, avx2);
          EXPECT_EQ(marks[0], 0) << "slot " << slot << " value " << bad << " avx2 " << avx2;
          EXPECT_EQ(coplanar[0], 0) << "slot " << slot << " value " << bad << " avx2 " << avx2;
          EXPECT_EQ(marks[1], 1) << "slot " << slot;
        }
      }
    }
  }
}

TEST(CcdBatch, EveryBatchSizeAndLaneGivesTheSameMarks) {
  const std::vector<CcdQuery> queries = make_queries(7);
  std::vector<std::uint8_t> whole(queries.size());
  detail::ccd_never_coplanar(queries, whole.data(), false);
  for (const bool avx2 : {false, true}) {
    // Batches of 1 to 7 queries, starting anywhere: each query's mark is its own.
    for (std::size_t size = 1; size <= 7; ++size) {
      for (std::size_t begin = 0; begin + size <= queries.size(); begin += size) {
        std::uint8_t part[7] = {};
        detail::ccd_never_coplanar({queries.data() + begin, size}, part, avx2);
        for (std::size_t i = 0; i < size; ++i) ASSERT_EQ(part[i], whole[begin + i]) << begin + i << " size " << size;
      }
    }
  }
}

TEST(CcdBatch, AfterCoplanarityMatchesCcdAtEveryDelta) {
  const std::vector<CcdQuery> queries = make_queries(3);
  for (const Scalar delta : {1e-12, 1e-3}) {
    CcdOptions o;
    o.min_separation = delta;
    for (std::size_t i = 0; i < queries.size(); i += 7) {
      const CcdQuery& q = queries[i];
      for (const CcdPair pair : {CcdPair::kVertexFace, CcdPair::kEdgeEdge}) {
        const CcdOptions scaled = [&] {
          CcdOptions s = o;
          s.min_separation = delta * std::max(largest(q), Scalar(1e-300));
          return s;
        }();
        EXPECT_TRUE(same(detail::ccd_after_coplanarity(pair, q.start, q.end, scaled), ccd(pair, q.start, q.end, scaled)))
            << i;
      }
    }
  }
}

/// Queries placed at the hull filter's boundary: from a query of `make_queries`, the first
/// feature (the vertex, edge a) moved along one axis so that its smallest difference on that axis
/// at both times is the filter's bound err + δ times (1 ± 2^-20), 1/2, 2, or δ itself (err from
/// the moved query's own magnitude, so the gap lands on either side of the bound); plus queries
/// with a NaN, an infinite or a 2^301 coordinate.
std::vector<CcdQuery> hull_boundary_queries(std::uint32_t seed, CcdPair pair, Scalar delta) {
  std::mt19937_64 rng(seed);
  std::vector<CcdQuery> out;
  const int first_end = pair == CcdPair::kVertexFace ? 1 : 2;  // points [0, first_end) move
  const Scalar factors[] = {1 - 0x1p-20, 1, 1 + 0x1p-20, 0.5, 2, 0};
  for (CcdQuery q : make_queries(seed)) {
    const int k = static_cast<int>(rng() % 3);
    const Scalar factor = factors[rng() % 6];
    for (int round = 0; round < 2; ++round) {  // the move changes the magnitude: settle it
      const Scalar err = ccd_rounding_bound(q.start, q.end)[k];
      Scalar lo = INFINITY;
      for (const CcdPoints* x : {&q.start, &q.end}) {
        for (int i = 0; i < first_end; ++i) {
          for (int j = first_end; j < 4; ++j) lo = std::min(lo, (*x)[i][k] - (*x)[j][k]);
        }
      }
      const Scalar shift = (factor == 0 ? delta : (err + delta) * factor) - lo;
      if (!std::isfinite(shift)) break;
      for (CcdPoints* x : {&q.start, &q.end}) {
        for (int i = 0; i < first_end; ++i) (*x)[i][k] += shift;
      }
    }
    out.push_back(q);
  }
  for (const Scalar bad : {Scalar(NAN), Scalar(INFINITY), Scalar(0x1p301)}) {
    for (int i = 0; i < 24; ++i) {
      CcdQuery q = out[static_cast<std::size_t>(i) * 7 % out.size()];
      (i < 12 ? q.start : q.end)[static_cast<std::size_t>(i % 12 / 3)][i % 3] = bad;
      out.push_back(q);
    }
  }
  return out;
}

void expect_same(const CcdResult& a, const CcdResult& b, std::size_t i) {
  EXPECT_EQ(a.hit, b.hit) << i;
  EXPECT_EQ(std::memcmp(&a.toi, &b.toi, sizeof a.toi), 0) << i << ": " << a.toi << " " << b.toi;
  EXPECT_EQ(a.outcome, b.outcome) << i << ": " << to_string(a.outcome) << " " << to_string(b.outcome);
  EXPECT_EQ(a.boxes, b.boxes) << i;
  EXPECT_EQ(a.advance_steps, b.advance_steps) << i;
}

// `ccd` one query at a time (its hull filter decided in vector registers first) and `ccd` on a
// span (the hull four queries at a time, then the batched filters and the advancement in lanes)
// give the scalar narrow phase's result field for field, on queries at the hull filter's
// boundary and around the coplanarity boundary, for both pair types and three δ, as one span
// and in spans of 1 to 9 and of 300 (tails shorter than four lanes, blocks of 256).
TEST(CcdBatch, ManyQueriesAtOnceGiveTheScalarResults) {
  int hull_apart = 0, hull_kept = 0;
  for (const CcdPair pair : {CcdPair::kVertexFace, CcdPair::kEdgeEdge}) {
    for (const Scalar delta : {0.0, 1e-9, 1e-4}) {
      const std::vector<CcdQuery> queries = hull_boundary_queries(pair == CcdPair::kVertexFace ? 5 : 6, pair, delta);
      CcdOptions options;
      options.min_separation = delta;
      std::vector<CcdResult> reference(queries.size());
      for (std::size_t i = 0; i < queries.size(); ++i) {
        reference[i] = detail::ccd_scalar(pair, queries[i].start, queries[i].end, options);
        expect_same(ccd(pair, queries[i].start, queries[i].end, options), reference[i], i);
        const bool at_bound = i < queries.size() - 72;
        hull_apart += at_bound && reference[i].outcome == CcdOutcome::kSeparatedHull;
        hull_kept += at_bound && reference[i].outcome != CcdOutcome::kSeparatedHull;
      }
      for (const std::size_t piece : {queries.size(), std::size_t{1}, std::size_t{3}, std::size_t{9}, std::size_t{300}}) {
        std::vector<CcdResult> out(queries.size());
        for (std::size_t begin = 0; begin < queries.size(); begin += piece) {
          const std::size_t n = std::min(piece, queries.size() - begin);
          ccd(pair, std::span<const CcdQuery>(queries).subspan(begin, n), options, std::span<CcdResult>(out).subspan(begin, n));
        }
        for (std::size_t i = 0; i < queries.size(); ++i) expect_same(out[i], reference[i], i);
      }
    }
  }
  std::printf("[ ccd many ] hull filter at its bound: %d apart, %d kept\n", hull_apart, hull_kept);
  EXPECT_GT(hull_apart, 100);
  EXPECT_GT(hull_kept, 100);
}

}  // namespace
}  // namespace crumple::geometry

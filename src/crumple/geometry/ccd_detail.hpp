#pragma once
/// \file
/// Internal: the CCD narrow phase (ccd.hpp) split for the mesh-level query, which tests many
/// sub-pairs. The coplanarity filter (δ = 0) and the separating-direction filter, where most
/// of them end, run four queries at a time in vector lanes (AVX2 when the processor has it,
/// chosen at run time; two SSE2 halves otherwise), then `ccd_after_coplanarity` or
/// `ccd_after_direction` runs the rest of `ccd` on the queries they kept.
/// Together they give exactly `ccd`'s hit, TOI and, for hits, outcome (docs/ccd.md, "Batched
/// coplanarity filter").

#include <crumple/geometry/ccd.hpp>

#include <cstdint>
#include <span>

namespace crumple::geometry::detail {

using geometry::CcdQuery;

/// `ccd` computed without its vector shortcut for the hull filter (the scalar filters one after
/// another): the reference against which the tests check `ccd` and the batched `ccd` on a span.
CcdResult ccd_scalar(CcdPair pair, const CcdPoints& start, const CcdPoints& end, const CcdOptions& options);

/// Whether the four-lane AVX2 kernel runs on this processor (`has_avx2`, kernel_batch.hpp).
bool ccd_has_avx2();

/// `out[i]` = 1 when `ccd` at δ = 0 on `queries[i]` (either pair type: the test does not depend
/// on it) certainly reports no hit because its coplanarity filter (or its hull filter, which
/// runs first) rejects it: the query's largest |coordinate| lies in [2^-300, 2^300], where `ccd`
/// neither scales it nor skips the filter, and the four certified Bernstein signs of the
/// coplanarity cubic, computed lane by lane in `ccd`'s order of operations (so bit for bit its
/// values and bounds), agree. Else 0. `avx2` picks the kernel (false: the portable one; true
/// only where `ccd_has_avx2()`); both give the same answers.
void ccd_never_coplanar(std::span<const CcdQuery> queries, std::uint8_t* out, bool avx2);
inline void ccd_never_coplanar(std::span<const CcdQuery> queries, std::uint8_t* out) {
  ccd_never_coplanar(queries, out, ccd_has_avx2());
}

/// `out[i]` = 1 when `ccd` with δ = `delta` on `queries[index[i]]` as `pair` certainly reports no
/// hit because its separating-direction filter (or a filter before it) rejects it: the query
/// lies in [2^-300, 2^300] as above and that filter, computed lane by lane in `ccd`'s order of
/// operations (Eigen's cross and dot products included), rejects. Else 0.
void ccd_separated_by_a_direction(CcdPair pair, std::span<const CcdQuery> queries,
                                  std::span<const std::uint8_t> index, Scalar delta, std::uint8_t* out, bool avx2);
inline void ccd_separated_by_a_direction(CcdPair pair, std::span<const CcdQuery> queries,
                                         std::span<const std::uint8_t> index, Scalar delta, std::uint8_t* out) {
  ccd_separated_by_a_direction(pair, queries, index, delta, out, ccd_has_avx2());
}

/// `ccd(pair, start, end, options)` for a query on which `ccd_never_coplanar` gave 0: the same
/// result, without evaluating the coplanarity filter again (it would not reject). Any δ.
CcdResult ccd_after_coplanarity(CcdPair pair, const CcdPoints& start, const CcdPoints& end,
                                const CcdOptions& options);

/// The same for a query on which `ccd_separated_by_a_direction` (with options.min_separation)
/// gave 0 and, at δ = 0, `ccd_never_coplanar` too: neither filter is evaluated again.
CcdResult ccd_after_direction(CcdPair pair, const CcdPoints& start, const CcdPoints& end, const CcdOptions& options);

/// `out[i]` = `ccd_after_direction(pair, queries[i].start, queries[i].end, options)` for every
/// query (all of type `pair`), bit for bit. With `lanes` (where `ccd_has_avx2()`), the
/// conservative advancement of four queries runs in lockstep in vector lanes, a lane refilled
/// with the next query as its query ends; each lane performs the scalar advancement's
/// operations in its order. Otherwise one query after another.
void ccd_after_direction(CcdPair pair, std::span<const CcdQuery> queries, const CcdOptions& options, CcdResult* out,
                         bool lanes);
inline void ccd_after_direction(CcdPair pair, std::span<const CcdQuery> queries, const CcdOptions& options,
                                CcdResult* out) {
  ccd_after_direction(pair, queries, options, out, true);
}

}  // namespace crumple::geometry::detail

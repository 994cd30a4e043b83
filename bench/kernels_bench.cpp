/// Micro-benchmarks of the geometric kernels: time per call (Google Benchmark's "Time" column,
/// one kernel call per iteration) on pre-generated random inputs, so that neither the RNG nor
/// allocation is measured. Inputs cycle through 4096 cases (a few hundred KiB: L2-resident)
/// so that branch predictors see realistic variety.
///
///   build-geom/bench/kernels_bench --benchmark_min_time=0.2
///
/// Seeds are fixed (std::mt19937_64), so runs are comparable.

#include <crumple/geometry/distance.hpp>
#include <crumple/geometry/kdop.hpp>
#include <crumple/geometry/triangle_intersection.hpp>

#include <benchmark/benchmark.h>

#include <cstddef>
#include <random>
#include <vector>

namespace {

using crumple::Scalar;
using crumple::Vec3;
namespace geo = crumple::geometry;

constexpr std::size_t kCases = 4096;  // power of two: index with a mask

/// 4 * kCases random points. Triangles and segments are local (size ~0.2 in a unit box), as
/// in a mesh, so that distances, regions and intersections are mixed.
std::vector<Vec3> make_points(std::uint64_t seed) {
  std::mt19937_64 gen(seed);
  std::uniform_real_distribution<Scalar> box(-1, 1), local(-0.2, 0.2);
  std::vector<Vec3> pts;
  pts.reserve(4 * kCases);
  for (std::size_t i = 0; i < kCases; ++i) {
    const Vec3 c(box(gen), box(gen), box(gen));
    for (int k = 0; k < 4; ++k) pts.emplace_back(c + Vec3(local(gen), local(gen), local(gen)));
  }
  return pts;
}

/// 6 * kCases points: pairs of nearby triangles (~30% intersect).
std::vector<Vec3> make_triangle_pairs(std::uint64_t seed) {
  std::mt19937_64 gen(seed);
  std::uniform_real_distribution<Scalar> box(-1, 1), local(-0.3, 0.3), shift(-0.15, 0.15);
  std::vector<Vec3> pts;
  pts.reserve(6 * kCases);
  for (std::size_t i = 0; i < kCases; ++i) {
    const Vec3 c(box(gen), box(gen), box(gen));
    const Vec3 c2 = c + Vec3(shift(gen), shift(gen), shift(gen));
    for (int k = 0; k < 3; ++k) pts.emplace_back(c + Vec3(local(gen), local(gen), local(gen)));
    for (int k = 0; k < 3; ++k) pts.emplace_back(c2 + Vec3(local(gen), local(gen), local(gen)));
  }
  return pts;
}

void BM_point_segment(benchmark::State& state) {
  const std::vector<Vec3> p = make_points(1);
  std::size_t i = 0;
  for (auto _ : state) {
    const std::size_t k = 4 * (i++ & (kCases - 1));
    benchmark::DoNotOptimize(geo::point_segment(p[k], p[k + 1], p[k + 2]));
  }
}
BENCHMARK(BM_point_segment);

void BM_segment_segment(benchmark::State& state) {
  const std::vector<Vec3> p = make_points(2);
  std::size_t i = 0;
  for (auto _ : state) {
    const std::size_t k = 4 * (i++ & (kCases - 1));
    benchmark::DoNotOptimize(geo::segment_segment(p[k], p[k + 1], p[k + 2], p[k + 3]));
  }
}
BENCHMARK(BM_segment_segment);

/// Near-parallel segments (angle ~1e-6): the slow branch of the robust method.
void BM_segment_segment_near_parallel(benchmark::State& state) {
  std::vector<Vec3> p = make_points(3);
  for (std::size_t k = 0; k < p.size(); k += 4) {
    const Vec3 d = p[k + 1] - p[k];
    p[k + 3] = p[k + 2] + 0.8 * d + Vec3(1e-6, -1e-6, 0) * d.norm();
  }
  std::size_t i = 0;
  for (auto _ : state) {
    const std::size_t k = 4 * (i++ & (kCases - 1));
    benchmark::DoNotOptimize(geo::segment_segment(p[k], p[k + 1], p[k + 2], p[k + 3]));
  }
}
BENCHMARK(BM_segment_segment_near_parallel);

void BM_point_triangle(benchmark::State& state) {
  const std::vector<Vec3> p = make_points(4);
  std::size_t i = 0;
  for (auto _ : state) {
    const std::size_t k = 4 * (i++ & (kCases - 1));
    benchmark::DoNotOptimize(geo::point_triangle(p[k], p[k + 1], p[k + 2], p[k + 3]));
  }
}
BENCHMARK(BM_point_triangle);

void BM_triangle_triangle_intersection(benchmark::State& state) {
  const std::vector<Vec3> p = make_triangle_pairs(5);
  std::size_t i = 0, hits = 0, calls = 0;
  for (auto _ : state) {
    const std::size_t k = 6 * (i++ & (kCases - 1));
    const geo::TriangleIntersection r =
        geo::triangle_triangle_intersection(p[k], p[k + 1], p[k + 2], p[k + 3], p[k + 4], p[k + 5]);
    hits += r.intersects;
    ++calls;
    benchmark::DoNotOptimize(r);
  }
  state.counters["hit_rate"] = calls ? double(hits) / double(calls) : 0.0;
}
BENCHMARK(BM_triangle_triangle_intersection);

/// Triangle pairs sharing a vertex, as between mesh neighbours: exercises the exact fallback
/// of the predicates (orient3d with a repeated point is exactly 0).
void BM_triangle_triangle_intersection_shared_vertex(benchmark::State& state) {
  std::vector<Vec3> p = make_triangle_pairs(6);
  for (std::size_t k = 0; k < p.size(); k += 6) p[k + 3] = p[k];
  std::size_t i = 0;
  for (auto _ : state) {
    const std::size_t k = 6 * (i++ & (kCases - 1));
    benchmark::DoNotOptimize(
        geo::triangle_triangle_intersection(p[k], p[k + 1], p[k + 2], p[k + 3], p[k + 4], p[k + 5]));
  }
}
BENCHMARK(BM_triangle_triangle_intersection_shared_vertex);

/// Writes into a small ring of k-DOPs that stays in L1 (DoNotOptimize on the 100-200 byte
/// result would measure a forced spill; a 4096-entry output array measures cache misses:
/// ~35 ns for K = 18 on a loaded 2-core machine, against ~3 ns for the kernel).
template <int K>
void BM_kdop_from_triangle(benchmark::State& state) {
  const std::vector<Vec3> p = make_points(7);
  std::vector<geo::Kdop<K>> out(64);
  std::size_t i = 0;
  for (auto _ : state) {
    const std::size_t n = i++, k = 4 * (n & (kCases - 1));
    out[n & 63] = geo::Kdop<K>::from_triangle(p[k], p[k + 1], p[k + 2]);
    benchmark::ClobberMemory();
  }
  benchmark::DoNotOptimize(out.data());
}
BENCHMARK(BM_kdop_from_triangle<6>);
BENCHMARK(BM_kdop_from_triangle<18>);
BENCHMARK(BM_kdop_from_triangle<26>);

template <int K>
void BM_kdop_overlap(benchmark::State& state) {
  const std::vector<Vec3> p = make_points(8);
  std::vector<geo::Kdop<K>> boxes;
  boxes.reserve(kCases);
  for (std::size_t k = 0; k < 4 * kCases; k += 4) {
    boxes.push_back(geo::Kdop<K>::from_triangle(p[k], p[k + 1], p[k + 2]));
  }
  std::size_t i = 0, hits = 0, calls = 0;
  for (auto _ : state) {
    // Pairs of unrelated random local triangles: mostly disjoint.
    const std::size_t a = i & (kCases - 1), b = (i * 7 + 1) & (kCases - 1);
    ++i;
    const bool o = boxes[a].overlaps(boxes[b]);
    hits += o;
    ++calls;
    benchmark::DoNotOptimize(o);
  }
  state.counters["hit_rate"] = calls ? double(hits) / double(calls) : 0.0;
}
BENCHMARK(BM_kdop_overlap<6>);
BENCHMARK(BM_kdop_overlap<18>);
BENCHMARK(BM_kdop_overlap<26>);

/// Overlap of k-DOPs that do overlap (the all-slabs path, as near the leaves of a tree walk).
template <int K>
void BM_kdop_overlap_hit(benchmark::State& state) {
  const std::vector<Vec3> p = make_points(9);
  std::vector<geo::Kdop<K>> boxes;
  boxes.reserve(kCases);
  for (std::size_t k = 0; k < 4 * kCases; k += 4) {
    boxes.push_back(geo::Kdop<K>::from_triangle(p[k], p[k + 1], p[k + 2]));
  }
  std::vector<geo::Kdop<K>> inflated = boxes;
  for (auto& b : inflated) b.inflate(0.01);
  std::size_t i = 0;
  for (auto _ : state) {
    const std::size_t a = i++ & (kCases - 1);
    benchmark::DoNotOptimize(boxes[a].overlaps(inflated[a]));
  }
}
BENCHMARK(BM_kdop_overlap_hit<18>);

}  // namespace

BENCHMARK_MAIN();

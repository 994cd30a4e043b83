// Narrow-phase CCD throughput on the real frame pairs of ../shared/data/sample-scalable-ccd.
//
// For each scene: read the two frames, build the vertex–face and edge–edge candidates whose
// swept boxes (inflated by δ) overlap (sort and sweep on x; pairs sharing a vertex skipped), then
// run geometry::ccd on every candidate with 1 and 2 threads and report ns per query, the share
// rejected by each filter, hits by outcome, and, on an evenly spaced sample of the hits, how
// many the exact GMP oracle (tests/support/ccd_oracle.hpp) certifies as false positives.
//
//   ccd_bench [--data DIR] [--max-queries N] [--oracle-sample K] [--scene NAME] [--json]
//             [--threads 1,2] [--max-boxes N] [--max-advance-steps N] [--profile]
//             [--vs-tight-inclusion [--rounds R] [--breakdown]] [--deltas 0,1e-3]
//
// Threads claim chunks of 1024 queries dynamically. --max-advance-steps 0 runs bisection alone
// (the narrow phase before conservative advancement). --profile times each query alone on the
// 1-thread run and prints, per outcome, its share of the time, ns, steps and boxes per query.
//
// --vs-tight-inclusion prints another table: the narrow phase against an independent port of
// Tight-Inclusion (bench/tight_inclusion_ref.hpp, ipc-toolkit's default settings) on the same
// queries and thread counts, R rounds rotating the order of three passes (the narrow phase on
// spans of queries, `geometry::ccd` on each chunk's VF and EE queries gathered; the narrow
// phase one query at a time; Tight-Inclusion one query at a time), each pass timed in thread
// CPU time (CLOCK_THREAD_CPUTIME_ID, summed over the threads, the gathers of the points
// included). The two narrow-phase passes must give the same hits. Queries on which the two
// disagree are sent to the exact oracle (at most K of each kind): a certified contact that
// either misses is a false negative, and the program fails.
//
// --breakdown (with --vs-tight-inclusion, one thread) instead groups the queries by the narrow
// phase's outcome and times both methods on each group alone: the cost split by outcome, with
// the distributions of advancement steps and of Tight-Inclusion's boxes.
//
// δ is each of --deltas (default 0 and 1e-3) × the first frame's bounding-box diagonal.
#include <crumple/geometry/ccd.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/mesh.hpp>

#include "support/ccd_oracle.hpp"
#include "tight_inclusion_ref.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <numeric>
#include <sstream>
#include <string>
#include <thread>
#include <time.h>
#include <vector>

namespace {

using namespace crumple;
using geometry::CcdOutcome;
using geometry::CcdPair;
using geometry::CcdPoints;

struct Scene {
  const char* name;
  const char* frame0;
  const char* frame1;
};

const Scene kScenes[] = {
    {"cloth-ball", "cloth-ball/frames/cloth_ball92.ply", "cloth-ball/frames/cloth_ball93.ply"},
    {"cloth-funnel", "cloth-funnel/frames/227.ply", "cloth-funnel/frames/228.ply"},
    {"rod-twist", "rod-twist/frames/3036.ply", "rod-twist/frames/3037.ply"},
    {"armadillo", "armadillo-rollers/frames/326.ply", "armadillo-rollers/frames/327.ply"},
    {"n-body", "n-body-simulation/frames/balls16_18.ply", "n-body-simulation/frames/balls16_19.ply"},
};

struct Query {
  CcdPair pair;
  std::array<Index, 4> v;
};

struct Box {
  Vec3 lo, hi;
  int kind;  // 0 vertex / edge a, 1 face
  Index id;
};

void sweep(std::vector<Box>& boxes, const std::function<void(const Box&, const Box&)>& emit) {
  std::sort(boxes.begin(), boxes.end(), [](const Box& a, const Box& b) { return a.lo.x() < b.lo.x(); });
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    for (std::size_t j = i + 1; j < boxes.size() && boxes[j].lo.x() <= boxes[i].hi.x(); ++j) {
      const Box& a = boxes[i];
      const Box& b = boxes[j];
      if (a.lo.y() > b.hi.y() || b.lo.y() > a.hi.y() || a.lo.z() > b.hi.z() || b.lo.z() > a.hi.z()) continue;
      emit(a, b);
    }
  }
}

std::vector<Query> candidates(const Positions& x0, const Positions& x1, const std::vector<Face>& faces,
                              const std::vector<Edge>& edges, Scalar inflate, std::size_t cap) {
  std::vector<Query> out;
  const auto swept = [&](std::initializer_list<Index> ids) {
    Box b;
    b.lo = Vec3::Constant(INFINITY);
    b.hi = Vec3::Constant(-INFINITY);
    for (Index i : ids) {
      b.lo = b.lo.cwiseMin(x0[i]).cwiseMin(x1[i]);
      b.hi = b.hi.cwiseMax(x0[i]).cwiseMax(x1[i]);
    }
    b.lo.array() -= inflate;
    b.hi.array() += inflate;
    return b;
  };
  std::vector<Box> boxes;
  for (Index v = 0; v < static_cast<Index>(x0.size()); ++v) {
    Box b = swept({v});
    b.kind = 0;
    b.id = v;
    boxes.push_back(b);
  }
  for (Index f = 0; f < static_cast<Index>(faces.size()); ++f) {
    Box b = swept({faces[f][0], faces[f][1], faces[f][2]});
    b.kind = 1;
    b.id = f;
    boxes.push_back(b);
  }
  std::size_t vf = 0;
  sweep(boxes, [&](const Box& a, const Box& b) {
    if (a.kind == b.kind || vf >= cap) return;
    const Index v = a.kind == 0 ? a.id : b.id;
    const Face& f = faces[a.kind == 1 ? a.id : b.id];
    if (v == f[0] || v == f[1] || v == f[2]) return;
    out.push_back({CcdPair::kVertexFace, {v, f[0], f[1], f[2]}});
    ++vf;
  });
  boxes.clear();
  for (Index e = 0; e < static_cast<Index>(edges.size()); ++e) {
    Box b = swept({edges[e][0], edges[e][1]});
    b.kind = 0;
    b.id = e;
    boxes.push_back(b);
  }
  std::size_t ee = 0;
  sweep(boxes, [&](const Box& a, const Box& b) {
    if (ee >= cap) return;
    const Edge& p = edges[a.id];
    const Edge& q = edges[b.id];
    if (p[0] == q[0] || p[0] == q[1] || p[1] == q[0] || p[1] == q[1]) return;
    out.push_back({CcdPair::kEdgeEdge, {p[0], p[1], q[0], q[1]}});
    ++ee;
  });
  return out;
}

struct Run {
  double ns_per_query = 0;
  std::array<long long, 16> outcomes{};
  std::vector<std::size_t> hits;
  long long boxes = 0, steps = 0;
  // --profile: per outcome, thread ns (each query timed alone), advancement steps and boxes.
  std::array<double, 16> outcome_ns{};
  std::array<long long, 16> outcome_steps{}, outcome_boxes{};
};

Run run(const std::vector<Query>& queries, const Positions& x0, const Positions& x1, Scalar delta, int threads,
        const geometry::CcdOptions& base, bool profile) {
  geometry::CcdOptions options = base;
  options.min_separation = delta;
  const bool dump = std::getenv("CCD_BENCH_DUMP") != nullptr;
  std::vector<Run> parts(threads);
  // Chunks of 1024 queries claimed dynamically: the expensive queries cluster.
  std::atomic<std::size_t> next{0};
  const auto work = [&](int k) {
    Run& part = parts[k];
    for (std::size_t begin; (begin = next.fetch_add(1024)) < queries.size();) {
      const std::size_t end = std::min(queries.size(), begin + 1024);
      for (std::size_t i = begin; i < end; ++i) {
        const Query& q = queries[i];
        const CcdPoints s = {x0[q.v[0]], x0[q.v[1]], x0[q.v[2]], x0[q.v[3]]};
        const CcdPoints e = {x1[q.v[0]], x1[q.v[1]], x1[q.v[2]], x1[q.v[3]]};
        const auto c0 = profile ? std::chrono::steady_clock::now() : std::chrono::steady_clock::time_point{};
        const geometry::CcdResult r = geometry::ccd(q.pair, s, e, options);
        const int o = static_cast<int>(r.outcome);
        if (profile) {
          part.outcome_ns[o] += std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - c0).count();
          part.outcome_steps[o] += r.advance_steps;
          part.outcome_boxes[o] += r.boxes;
        }
        ++part.outcomes[o];
        part.boxes += r.boxes;
        part.steps += r.advance_steps;
        if (r.hit) part.hits.push_back(i);
        if (dump && r.outcome == CcdOutcome::kHitBudget) {
          std::fprintf(stderr, "%s", q.pair == CcdPair::kVertexFace ? "vf" : "ee");
          for (const CcdPoints* x : {&s, &e}) {
            for (const Vec3& p : *x) std::fprintf(stderr, " %a %a %a", p.x(), p.y(), p.z());
          }
          std::fprintf(stderr, "\n");
        }
      }
    }
  };
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::thread> pool;
  for (int k = 1; k < threads; ++k) pool.emplace_back(work, k);
  work(0);
  for (std::thread& t : pool) t.join();
  const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
  Run total;
  total.ns_per_query = queries.empty() ? 0 : ns / static_cast<double>(queries.size());
  for (const Run& p : parts) {
    for (int i = 0; i < 16; ++i) {
      total.outcomes[i] += p.outcomes[i];
      total.outcome_ns[i] += p.outcome_ns[i];
      total.outcome_steps[i] += p.outcome_steps[i];
      total.outcome_boxes[i] += p.outcome_boxes[i];
    }
    total.boxes += p.boxes;
    total.steps += p.steps;
    total.hits.insert(total.hits.end(), p.hits.begin(), p.hits.end());
  }
  return total;
}

/// Thread CPU ns of `work()` run once on each of `threads` threads (the caller's among them),
/// summed over the threads.
template <class Work>
double thread_cpu_ns(int threads, const Work& work) {
  std::atomic<long long> total{0};
  const auto timed = [&] {
    timespec a{}, b{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &a);
    work();
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &b);
    total += (b.tv_sec - a.tv_sec) * 1000000000LL + (b.tv_nsec - a.tv_nsec);
  };
  std::vector<std::thread> pool;
  for (int k = 1; k < threads; ++k) pool.emplace_back(timed);
  timed();
  for (std::thread& t : pool) t.join();
  return static_cast<double>(total.load());
}

/// Thread CPU ns of one pass of `solve(i)` over queries [0, n) with `threads` threads (chunks of
/// 1024 claimed dynamically), summed over the threads.
template <class Solve>
double cpu_pass(std::size_t n, int threads, const Solve& solve) {
  std::atomic<std::size_t> next{0};
  return thread_cpu_ns(threads, [&] {
    for (std::size_t begin; (begin = next.fetch_add(1024)) < n;) {
      const std::size_t end = std::min(n, begin + 1024);
      for (std::size_t i = begin; i < end; ++i) solve(i);
    }
  });
}

/// Thread CPU ns of one pass of the batched narrow phase (`geometry::ccd` on a span) over all
/// queries with `threads` threads: each chunk of 1024 claimed is gathered into one batch per pair
/// type (the gather is timed, as the one-query-at-a-time passes time theirs); `hit[i]` receives
/// query i's answer.
double batch_pass(const std::vector<Query>& queries, const Positions& x0, const Positions& x1, int threads,
                  const geometry::CcdOptions& options, std::vector<std::uint8_t>& hit) {
  const std::size_t n = queries.size();
  std::atomic<std::size_t> next{0};
  return thread_cpu_ns(threads, [&] {
    std::vector<geometry::CcdQuery> batch[2];
    std::vector<std::size_t> ids[2];
    std::vector<geometry::CcdResult> out;
    for (std::size_t begin; (begin = next.fetch_add(1024)) < n;) {
      const std::size_t end = std::min(n, begin + 1024);
      for (int k = 0; k < 2; ++k) {
        batch[k].clear();
        ids[k].clear();
      }
      for (std::size_t i = begin; i < end; ++i) {
        const Query& q = queries[i];
        const int k = q.pair == CcdPair::kVertexFace ? 0 : 1;
        batch[k].push_back({{x0[q.v[0]], x0[q.v[1]], x0[q.v[2]], x0[q.v[3]]},
                            {x1[q.v[0]], x1[q.v[1]], x1[q.v[2]], x1[q.v[3]]}});
        ids[k].push_back(i);
      }
      for (int k = 0; k < 2; ++k) {
        out.resize(batch[k].size());
        geometry::ccd(k == 0 ? CcdPair::kVertexFace : CcdPair::kEdgeEdge, batch[k], options, out);
        for (std::size_t j = 0; j < out.size(); ++j) hit[ids[k][j]] = out[j].hit;
      }
    }
  });
}

/// Oracle verdicts on a sample of queries: certified no contact / certified contact / undecided.
struct Verdicts {
  std::size_t count = 0;
  int no = 0, yes = 0, undecided = 0;
  std::string str() const {
    return std::to_string(count) + (count ? " (" + std::to_string(no) + " / " + std::to_string(yes) + " / " +
                                                std::to_string(undecided) + ")"
                                          : std::string());
  }
};

Verdicts oracle_verdicts(const std::vector<std::size_t>& ids, std::size_t cap, const std::vector<Query>& queries,
                         const Positions& x0, const Positions& x1, Scalar delta) {
  Verdicts v;
  v.count = ids.size();
  if (ids.empty() || cap == 0) return v;
  const std::size_t step = std::max<std::size_t>(1, ids.size() / cap);
  for (std::size_t k = 0; k < ids.size(); k += step) {
    const Query& q = queries[ids[k]];
    const bool vf = q.pair == CcdPair::kVertexFace;
    const CcdPoints s = {x0[q.v[0]], x0[q.v[1]], x0[q.v[2]], x0[q.v[3]]};
    const CcdPoints e = {x1[q.v[0]], x1[q.v[1]], x1[q.v[2]], x1[q.v[3]]};
    const auto d = ccd_oracle::decide(ccd_oracle::make_query(vf, s, e, delta), 300);
    ccd_oracle::Q crossing;
    if (d.verdict == ccd_oracle::Verdict::kNo) ++v.no;
    else if (d.verdict == ccd_oracle::Verdict::kYes) ++v.yes;
    else if (delta == 0 && ccd_oracle::certified_crossing(ccd_oracle::make_points(vf, s, e), crossing)) ++v.yes;
    else ++v.undecided;
  }
  return v;
}

/// --breakdown: the queries grouped by the narrow phase's outcome, and per group the count, both
/// methods' thread CPU ns a query (each group timed alone as one pass, the fastest of `rounds`,
/// alternating which goes first), the advancement steps (mean and distribution) and
/// Tight-Inclusion's boxes (mean and distribution). Printed as a markdown table on stdout.
void breakdown(const char* scene, const std::vector<Query>& queries, const Positions& x0, const Positions& x1,
               Scalar delta, int rounds, const geometry::CcdOptions& base) {
  geometry::CcdOptions options = base;
  options.min_separation = delta;
  const ti_ref::Settings ti_settings;
  std::array<std::vector<std::size_t>, geometry::kCcdOutcomeCount> groups;
  std::vector<std::int64_t> steps(queries.size()), boxes(queries.size());
  const auto points = [&](std::size_t i, CcdPoints& s, CcdPoints& e) {
    const Query& q = queries[i];
    s = {x0[q.v[0]], x0[q.v[1]], x0[q.v[2]], x0[q.v[3]]};
    e = {x1[q.v[0]], x1[q.v[1]], x1[q.v[2]], x1[q.v[3]]};
  };
  const auto ti = [&](std::size_t i) {
    CcdPoints s, e;
    points(i, s, e);
    return queries[i].pair == CcdPair::kVertexFace ? ti_ref::vertex_face_ccd(s, e, delta, ti_settings)
                                                  : ti_ref::edge_edge_ccd(s, e, delta, ti_settings);
  };
  for (std::size_t i = 0; i < queries.size(); ++i) {
    CcdPoints s, e;
    points(i, s, e);
    const geometry::CcdResult r = geometry::ccd(queries[i].pair, s, e, options);
    groups[static_cast<std::size_t>(r.outcome)].push_back(i);
    steps[i] = r.advance_steps;
    boxes[i] = ti(i).boxes;
  }
  // Distribution as "1:n 2:n 3-4:n 5-8:n ..." (power-of-two bins).
  const auto histogram = [](const std::vector<std::size_t>& ids, const std::vector<std::int64_t>& value) {
    std::array<long long, 40> bins{};
    for (std::size_t i : ids) {
      const std::int64_t v = value[i];
      int b = 0;
      while (b < 39 && (std::int64_t{1} << b) <= v) ++b;  // bin b holds [2^(b-1), 2^b)
      ++bins[static_cast<std::size_t>(b)];
    }
    std::string out;
    for (int b = 0; b < 40; ++b) {
      if (bins[static_cast<std::size_t>(b)] == 0) continue;
      const long long lo = b == 0 ? 0 : (1LL << (b - 1)), hi = b == 0 ? 0 : (1LL << b) - 1;
      char item[64];
      if (lo == hi) {
        std::snprintf(item, sizeof item, "%s%lld:%lld", out.empty() ? "" : " ", lo, bins[static_cast<std::size_t>(b)]);
      } else {
        std::snprintf(item, sizeof item, "%s%lld-%lld:%lld", out.empty() ? "" : " ", lo, hi,
                      bins[static_cast<std::size_t>(b)]);
      }
      out += item;
    }
    return out;
  };
  // Would the difference hull on N pieces of the step (the axis test on [j/N, (j+1)/N], the
  // points at the piece's ends interpolated; err doubled for the interpolation) have rejected
  // the queries that reach the advancement? Measurement only (stderr).
  for (const int pieces : {2, 4, 8, 16}) {
    long long rejected = 0, total = 0;
    for (int k : {static_cast<int>(CcdOutcome::kSeparatedAdvancement), static_cast<int>(CcdOutcome::kHitTolerance)}) {
      for (std::size_t i : groups[static_cast<std::size_t>(k)]) {
        CcdPoints s, e;
        points(i, s, e);
        const bool vf = queries[i].pair == CcdPair::kVertexFace;
        Scalar m = 0;
        for (int a = 0; a < 4; ++a) m = std::max({m, s[a].cwiseAbs().maxCoeff(), e[a].cwiseAbs().maxCoeff()});
        const Scalar bound = 2 * (64 * 0x1p-53 * m) + delta;
        const auto diffs = [&](Scalar t, std::array<Vec3, 4>& d) {
          std::array<Vec3, 4> x;
          for (int a = 0; a < 4; ++a) x[a] = (1 - t) * s[a] + t * e[a];
          if (vf) d = {x[0] - x[1], x[0] - x[2], x[0] - x[3], x[0] - x[3]};
          else d = {x[0] - x[2], x[0] - x[3], x[1] - x[2], x[1] - x[3]};
        };
        bool all_apart = true;
        for (int j = 0; j < pieces && all_apart; ++j) {
          std::array<Vec3, 4> d0, d1;
          diffs(Scalar(j) / pieces, d0);
          diffs(Scalar(j + 1) / pieces, d1);
          Vec3 lo = d0[0], hi = d0[0];
          for (int a = 0; a < 4; ++a) {
            lo = lo.cwiseMin(d0[a]).cwiseMin(d1[a]);
            hi = hi.cwiseMax(d0[a]).cwiseMax(d1[a]);
          }
          bool apart = false;
          for (int a = 0; a < 3; ++a) apart = apart || lo[a] > bound || hi[a] < -bound;
          all_apart = apart;
        }
        rejected += all_apart;
        ++total;
      }
    }
    std::fprintf(stderr, "ccd_bench: %s delta %.3g: the hull on %d pieces of the step rejects %lld of the %lld "
                 "queries that reach the advancement\n", scene, delta, pieces, rejected, total);
  }
  std::array<double, geometry::kCcdOutcomeCount> ours_ns{}, theirs_ns{};
  for (int k = 0; k < geometry::kCcdOutcomeCount; ++k) {
    const std::vector<std::size_t>& ids = groups[static_cast<std::size_t>(k)];
    if (ids.empty()) continue;
    double ours = INFINITY, theirs = INFINITY;
    for (int round = 0; round < rounds; ++round) {
      const auto a = [&] {
        ours = std::min(ours, cpu_pass(ids.size(), 1, [&](std::size_t j) {
          CcdPoints s, e;
          points(ids[j], s, e);
          volatile bool hit = geometry::ccd(queries[ids[j]].pair, s, e, options).hit;
          (void)hit;
        }));
      };
      const auto b = [&] {
        theirs = std::min(theirs, cpu_pass(ids.size(), 1, [&](std::size_t j) {
          volatile bool hit = ti(ids[j]).hit;
          (void)hit;
        }));
      };
      if (round % 2 == 0) {
        a();
        b();
      } else {
        b();
        a();
      }
    }
    ours_ns[static_cast<std::size_t>(k)] = ours;
    theirs_ns[static_cast<std::size_t>(k)] = theirs;
  }
  const double ours_total = std::accumulate(ours_ns.begin(), ours_ns.end(), 0.0);
  const double theirs_total = std::accumulate(theirs_ns.begin(), theirs_ns.end(), 0.0);
  for (int k = 0; k < geometry::kCcdOutcomeCount; ++k) {
    const std::vector<std::size_t>& ids = groups[static_cast<std::size_t>(k)];
    if (ids.empty()) continue;
    const double ours = ours_ns[static_cast<std::size_t>(k)], theirs = theirs_ns[static_cast<std::size_t>(k)];
    long long step_sum = 0, box_sum = 0;
    for (std::size_t i : ids) {
      step_sum += steps[i];
      box_sum += boxes[i];
    }
    const double n = static_cast<double>(ids.size());
    std::printf("| %s | %.3g | %s | %zu | %.1f | %.1f | %.1f%% | %.1f%% | %.2f | %s | %.2f | %s |\n", scene, delta,
                std::string(geometry::to_string(static_cast<CcdOutcome>(k))).c_str(), ids.size(), ours / n, theirs / n,
                100.0 * ours / std::max(1.0, ours_total), 100.0 * theirs / std::max(1.0, theirs_total),
                static_cast<double>(step_sum) / n, histogram(ids, steps).c_str(),
                static_cast<double>(box_sum) / n, histogram(ids, boxes).c_str());
    std::fflush(stdout);
  }
}

/// One row of the comparison with Tight-Inclusion; false when the oracle certifies a contact
/// that one of the two misses.
bool compare_tight_inclusion(const char* scene, const std::vector<Query>& queries, const Positions& x0,
                             const Positions& x1, Scalar delta, int threads, int rounds, const geometry::CcdOptions& base,
                             int oracle_sample) {
  geometry::CcdOptions options = base;
  options.min_separation = delta;
  const ti_ref::Settings ti_settings;  // ipc-toolkit's defaults: δ_tol 1e-6, max_itr 1e7, err per query
  const std::size_t n = queries.size();
  std::vector<std::uint8_t> ours(n), theirs(n), single(n);
  std::vector<std::int64_t> ti_boxes(n);
  std::vector<std::uint8_t> ti_capped(n);
  const auto points = [&](std::size_t i, CcdPoints& s, CcdPoints& e) {
    const Query& q = queries[i];
    s = {x0[q.v[0]], x0[q.v[1]], x0[q.v[2]], x0[q.v[3]]};
    e = {x1[q.v[0]], x1[q.v[1]], x1[q.v[2]], x1[q.v[3]]};
  };
  const auto run_ours = [&] { return batch_pass(queries, x0, x1, threads, options, ours); };
  const auto run_single = [&] {
    return cpu_pass(n, threads, [&](std::size_t i) {
      CcdPoints s, e;
      points(i, s, e);
      single[i] = geometry::ccd(queries[i].pair, s, e, options).hit;
    });
  };
  const auto run_theirs = [&] {
    return cpu_pass(n, threads, [&](std::size_t i) {
      CcdPoints s, e;
      points(i, s, e);
      const ti_ref::Result r = queries[i].pair == CcdPair::kVertexFace ? ti_ref::vertex_face_ccd(s, e, delta, ti_settings)
                                                                      : ti_ref::edge_edge_ccd(s, e, delta, ti_settings);
      theirs[i] = r.hit;
      ti_boxes[i] = r.boxes;
      ti_capped[i] = r.output_tolerance > ti_settings.tolerance;
    });
  };
  std::vector<double> ns_ours, ns_theirs, ns_single, ratios, single_ratios;
  for (int round = 0; round < rounds; ++round) {
    // The three passes in a rotating order: batch, one at a time, Tight-Inclusion.
    double a = 0, b = 0, c = 0;
    for (int k = 0; k < 3; ++k) {
      switch ((round + k) % 3) {
        case 0: a = run_ours(); break;
        case 1: c = run_single(); break;
        default: b = run_theirs(); break;
      }
    }
    const double q = std::max<double>(1, static_cast<double>(n));
    ns_ours.push_back(a / q);
    ns_theirs.push_back(b / q);
    ns_single.push_back(c / q);
    ratios.push_back(b / std::max(a, 1.0));
    single_ratios.push_back(b / std::max(c, 1.0));
    std::fprintf(stderr,
                 "ccd_bench: %s delta %.3g threads %d round %d: batch %.1f, one at a time %.1f, TI %.1f ns a query "
                 "(TI / batch %.1fx, TI / one at a time %.1fx)\n",
                 scene, delta, threads, round + 1, a / q, c / q, b / q, ratios.back(), single_ratios.back());
  }
  if (ours != single) {
    std::fprintf(stderr, "ccd_bench: %s: the batched and one-at-a-time narrow phase disagree\n", scene);
    return false;
  }
  const auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.empty() ? 0.0 : v[v.size() / 2];
  };
  std::vector<std::size_t> ours_only, theirs_only;
  long long ours_hits = 0, theirs_hits = 0, boxes = 0, capped = 0;
  for (std::size_t i = 0; i < n; ++i) {
    ours_hits += ours[i];
    theirs_hits += theirs[i];
    boxes += ti_boxes[i];
    capped += ti_capped[i];
    if (ours[i] && !theirs[i]) ours_only.push_back(i);
    if (theirs[i] && !ours[i]) theirs_only.push_back(i);
  }
  const std::size_t cap = static_cast<std::size_t>(std::max(0, oracle_sample));
  const Verdicts vo = oracle_verdicts(ours_only, cap, queries, x0, x1, delta);
  const Verdicts vt = oracle_verdicts(theirs_only, cap, queries, x0, x1, delta);
  const double ratio = median(ratios);
  const auto [lo, hi] = std::minmax_element(ratios.begin(), ratios.end());
  std::printf("| %s | %.3g | %zu | %d | %d | %.0f | %.0f | %.0f | %.1f (%.1f–%.1f) | %s | %.1f | %lld | %lld | %.1f | %lld | %s | %s |\n",
              scene, delta, n, threads, rounds, median(ns_ours), median(ns_single), median(ns_theirs), ratio,
              ratios.empty() ? 0 : *lo, ratios.empty() ? 0 : *hi, ratio >= 10 ? "met" : "not met",
              median(single_ratios), ours_hits, theirs_hits,
              static_cast<double>(boxes) / std::max<double>(1, static_cast<double>(n)), capped, vo.str().c_str(),
              vt.str().c_str());
  std::fflush(stdout);
  if (vo.yes > 0) std::fprintf(stderr, "ccd_bench: %s: the Tight-Inclusion port misses a certified contact\n", scene);
  if (vt.yes > 0) std::fprintf(stderr, "ccd_bench: %s: the narrow phase misses a certified contact\n", scene);
  return vo.yes == 0 && vt.yes == 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string data = CRUMPLE_BENCH_DATA_DIR;
  std::size_t max_queries = 1000000;
  int oracle_sample = 100;
  std::string only;
  bool json = false, profile = false, vs_ti = false, by_outcome = false;
  std::vector<double> relative_deltas{0, 1e-3};
  int rounds = 3;
  std::vector<int> thread_counts{1, 2};
  geometry::CcdOptions base;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "ccd_bench: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--data") data = value();
    else if (a == "--max-queries") max_queries = std::stoull(value());
    else if (a == "--oracle-sample") oracle_sample = std::stoi(value());
    else if (a == "--scene") only = value();
    else if (a == "--json") json = true;
    else if (a == "--profile") profile = true;
    else if (a == "--vs-tight-inclusion") vs_ti = true;
    else if (a == "--breakdown") by_outcome = true;
    else if (a == "--deltas") {
      relative_deltas.clear();
      std::stringstream list(value());
      for (std::string item; std::getline(list, item, ',');) relative_deltas.push_back(std::stod(item));
    }
    else if (a == "--rounds") rounds = std::max(1, std::stoi(value()));
    else if (a == "--max-boxes") base.max_boxes = std::stoll(value());
    else if (a == "--max-advance-steps") base.max_advance_steps = std::stoll(value());
    else if (a == "--threads") {
      thread_counts.clear();
      std::stringstream list(value());
      for (std::string item; std::getline(list, item, ',');) thread_counts.push_back(std::max(1, std::stoi(item)));
    } else {
      std::fprintf(stderr,
                   "usage: ccd_bench [--data DIR] [--max-queries N] [--oracle-sample K] [--scene NAME] [--json]\n"
                   "                 [--threads 1,2] [--max-boxes N] [--max-advance-steps N] [--profile]\n"
                   "                 [--vs-tight-inclusion [--rounds R] [--breakdown]] [--deltas 0,1e-3]\n");
      return 2;
    }
  }
  if (vs_ti && by_outcome) {
    std::printf("| scene | delta | crumple outcome | queries | crumple CPU ns/query | TI port CPU ns/query "
                "| crumple share | TI share | crumple steps/query | crumple steps (distribution) | TI boxes/query "
                "| TI boxes (distribution) |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  } else if (vs_ti) {
    std::printf("| scene | delta | queries | threads | rounds | crumple batched CPU ns/query "
                "| crumple one at a time CPU ns/query | Tight-Inclusion port CPU ns/query "
                "| ratio to batched, median (min–max) | ≥ 10× | ratio to one at a time, median | crumple hits | TI hits | TI boxes/query | TI at max_itr "
                "| crumple-only hits (oracle no / yes / undecided) | TI-only hits (oracle no / yes / undecided) |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  } else if (!json) {
    std::printf("| scene | delta | queries | threads | ns/query | hull | coplanar | direction | advancement-no | bisection-no "
                "| hits | budget hits | steps/query | boxes/query | oracle sample: FP / yes / undecided |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  }
  std::string profile_table;
  bool failed = false;
  for (const Scene& scene : kScenes) {
    if (!only.empty() && only != scene.name) continue;
    const std::filesystem::path dir = std::filesystem::path(data) / "sample-scalable-ccd";
    io::MeshData m0, m1;
    try {
      m0 = io::read_mesh_data(dir / scene.frame0);
      m1 = io::read_mesh_data(dir / scene.frame1);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "ccd_bench: skipping %s: %s\n", scene.name, e.what());
      continue;
    }
    std::vector<Edge> edges;
    for (const Face& f : m0.faces) {
      for (int k = 0; k < 3; ++k) {
        const Index a = f[k], b = f[(k + 1) % 3];
        edges.push_back({std::min(a, b), std::max(a, b)});
      }
    }
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    const Scalar diag = compute_bounds(m0.positions).diagonal();
    for (const double relative : relative_deltas) {
      const Scalar delta = relative * diag;
      const std::vector<Query> queries = candidates(m0.positions, m1.positions, m0.faces, edges, delta, max_queries);
      if (vs_ti && by_outcome) {
        breakdown(scene.name, queries, m0.positions, m1.positions, delta, rounds, base);
        continue;
      }
      if (vs_ti) {
        for (const int threads : thread_counts) {
          if (!compare_tight_inclusion(scene.name, queries, m0.positions, m1.positions, delta, threads, rounds, base,
                                       oracle_sample)) {
            failed = true;
          }
        }
        continue;
      }
      Run one, last;
      for (const int threads : thread_counts) {
        last = run(queries, m0.positions, m1.positions, delta, threads, base, profile && threads == 1);
        if (threads == 1) one = last;
        if (profile && threads == 1) {
          char row[256];
          for (int k = 0; k < geometry::kCcdOutcomeCount; ++k) {
            const long long count = last.outcomes[k];
            if (count == 0) continue;
            const double ns = last.outcome_ns[k];
            std::snprintf(row, sizeof row, "| %s | %.3g | %s | %lld | %.1f%% | %.0f | %.1f | %.1f |\n", scene.name, delta,
                          std::string(geometry::to_string(static_cast<CcdOutcome>(k))).c_str(), count,
                          100.0 * ns / std::max(1.0, std::accumulate(last.outcome_ns.begin(), last.outcome_ns.end(), 0.0)),
                          ns / static_cast<double>(count), static_cast<double>(last.outcome_steps[k]) / static_cast<double>(count),
                          static_cast<double>(last.outcome_boxes[k]) / static_cast<double>(count));
            profile_table += row;
          }
        }
        // Oracle sample on the single-thread hits (same set for any thread count).
        int fp = 0, yes = 0, undecided = 0;
        if (threads == 1 && oracle_sample > 0 && !one.hits.empty()) {
          std::vector<std::size_t> hits = one.hits;
          std::sort(hits.begin(), hits.end());
          const std::size_t step = std::max<std::size_t>(1, hits.size() / oracle_sample);
          for (std::size_t k = 0; k < hits.size(); k += step) {
            const Query& q = queries[hits[k]];
            const CcdPoints s = {m0.positions[q.v[0]], m0.positions[q.v[1]], m0.positions[q.v[2]], m0.positions[q.v[3]]};
            const CcdPoints e = {m1.positions[q.v[0]], m1.positions[q.v[1]], m1.positions[q.v[2]], m1.positions[q.v[3]]};
            const auto d = ccd_oracle::decide(ccd_oracle::make_query(q.pair == CcdPair::kVertexFace, s, e, delta), 300);
            ccd_oracle::Q crossing;
            if (d.verdict == ccd_oracle::Verdict::kNo) ++fp;
            else if (d.verdict == ccd_oracle::Verdict::kYes) ++yes;
            else if (delta == 0 && ccd_oracle::certified_crossing(
                                       ccd_oracle::make_points(q.pair == CcdPair::kVertexFace, s, e), crossing)) ++yes;
            else ++undecided;
          }
        }
        const auto& o = last.outcomes;
        const long long hits = static_cast<long long>(last.hits.size());
        const double n = std::max<double>(1, static_cast<double>(queries.size()));
        const auto pct = [&](CcdOutcome x) { return 100.0 * static_cast<double>(o[static_cast<int>(x)]) / n; };
        if (json) {
          std::printf("{\"scene\":\"%s\",\"delta\":%.6g,\"queries\":%zu,\"threads\":%d,\"ns_per_query\":%.1f,"
                      "\"hull_pct\":%.2f,\"coplanarity_pct\":%.2f,\"direction_pct\":%.2f,\"advancement_no_pct\":%.2f,"
                      "\"bisection_no_pct\":%.2f,\"hits\":%lld,\"budget_hits\":%lld,\"steps_per_query\":%.3f,"
                      "\"boxes_per_query\":%.3f,\"oracle_fp\":%d,\"oracle_yes\":%d,\"oracle_undecided\":%d}\n",
                      scene.name, delta, queries.size(), threads, last.ns_per_query, pct(CcdOutcome::kSeparatedHull),
                      pct(CcdOutcome::kSeparatedCoplanarity), pct(CcdOutcome::kSeparatedDirection),
                      pct(CcdOutcome::kSeparatedAdvancement), pct(CcdOutcome::kSeparatedBisection), hits,
                      o[static_cast<int>(CcdOutcome::kHitBudget)], static_cast<double>(last.steps) / n,
                      static_cast<double>(last.boxes) / n, fp, yes, undecided);
        } else {
          std::printf("| %s | %.3g | %zu | %d | %.1f | %.1f%% | %.1f%% | %.1f%% | %.1f%% | %.1f%% | %lld | %lld | %.2f | %.2f | %s |\n",
                      scene.name, delta, queries.size(), threads, last.ns_per_query, pct(CcdOutcome::kSeparatedHull),
                      pct(CcdOutcome::kSeparatedCoplanarity), pct(CcdOutcome::kSeparatedDirection),
                      pct(CcdOutcome::kSeparatedAdvancement), pct(CcdOutcome::kSeparatedBisection), hits,
                      o[static_cast<int>(CcdOutcome::kHitBudget)], static_cast<double>(last.steps) / n,
                      static_cast<double>(last.boxes) / n,
                      threads == 1 ? (std::to_string(fp) + " / " + std::to_string(yes) + " / " + std::to_string(undecided)).c_str() : "");
        }
        std::fflush(stdout);
      }
      if (thread_counts.size() > 1 && one.hits.size() != last.hits.size()) {
        std::fprintf(stderr, "ccd_bench: %s: hit counts differ between 1 and 2 threads\n", scene.name);
        return 1;
      }
    }
  }
  if (profile && !json) {
    std::printf("\nPer outcome, 1 thread, each query timed alone (the clock adds ~20 ns a query):\n\n");
    std::printf("| scene | delta | outcome | queries | share of time | ns/query | steps/query | boxes/query |\n");
    std::printf("|---|---|---|---|---|---|---|---|\n%s", profile_table.c_str());
  }
  return failed ? 1 : 0;
}

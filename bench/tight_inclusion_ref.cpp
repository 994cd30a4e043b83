// Tight-Inclusion, breadth-first, re-implemented (see the header for what differs from the
// authors' code and why no decision does).
#include "tight_inclusion_ref.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace crumple::ti_ref {
namespace {

constexpr Scalar kInf = std::numeric_limits<Scalar>::infinity();

/// A box of the parameter domain (t, u, v) and its depth in the breadth-first order.
struct Box {
  Scalar t0, t1, u0, u1, v0, v1;
  int level;
};

/// Pop order: the shallowest level first, then the earliest t0 (TI's `horiz_cmp`).
struct LaterFirst {
  bool operator()(const Box& a, const Box& b) const {
    if (a.level != b.level) return a.level > b.level;
    return a.t0 > b.t0;
  }
};

/// The query's data per axis: start positions and displacements of the 4 points.
struct Axis {
  std::array<Scalar, 4> x0, d;
};

/// F's values at the box's 8 corners on one axis, in TI's operation order: each point at time
/// τ is (x1 − x0)·τ + x0; VF: v − ((f1 − f0)·u + (f2 − f0)·v + f0); EE: ((a1 − a0)·u + a0) −
/// ((b1 − b0)·v + b0).
template <bool kVertexFace>
void corner_range(const Axis& a, const Box& b, Scalar& lo, Scalar& hi) {
  lo = kInf;
  hi = -kInf;
  for (const Scalar t : {b.t0, b.t1}) {
    const Scalar p0 = a.d[0] * t + a.x0[0], p1 = a.d[1] * t + a.x0[1];
    const Scalar p2 = a.d[2] * t + a.x0[2], p3 = a.d[3] * t + a.x0[3];
    for (const Scalar u : {b.u0, b.u1}) {
      for (const Scalar v : {b.v0, b.v1}) {
        Scalar f;
        if constexpr (kVertexFace) {
          f = p0 - ((p2 - p1) * u + (p3 - p1) * v + p1);
        } else {
          f = ((p1 - p0) * u + p0) - ((p3 - p2) * v + p2);
        }
        lo = std::min(lo, f);
        hi = std::max(hi, f);
      }
    }
  }
}

Scalar linf(const Vec3& a) { return a.cwiseAbs().maxCoeff(); }

/// Domain tolerances (t, u, v): tolerance / (3 × the largest L∞ change of F's corner values of
/// the unit box along that parameter), +∞ when it does not change. For EE, TI pairs edge a at
/// t = 1 with edge b at t = 0 for the t = 1 corners; reproduced as is (it only sets how fine
/// the boxes must get, never a decision's soundness).
template <bool kVertexFace>
std::array<Scalar, 3> domain_tolerances(const Points& s, const Points& e, Scalar tolerance) {
  std::array<std::array<std::array<Vec3, 2>, 2>, 2> c;  // c[t][u][v]
  if constexpr (kVertexFace) {
    for (int t = 0; t < 2; ++t) {
      const Points& x = t == 0 ? s : e;
      c[t][0][0] = x[0] - x[1];
      c[t][1][0] = x[0] - x[2];
      c[t][0][1] = x[0] - x[3];
      c[t][1][1] = x[0] - (x[2] + x[3] - x[1]);
    }
  } else {
    for (int u = 0; u < 2; ++u) {
      for (int v = 0; v < 2; ++v) {
        c[0][u][v] = s[u] - s[2 + v];
        c[1][u][v] = e[u] - s[2 + v];
      }
    }
  }
  Scalar lt = 0, lu = 0, lv = 0;
  for (int i = 0; i < 2; ++i) {
    for (int j = 0; j < 2; ++j) {
      lt = std::max(lt, linf(c[1][i][j] - c[0][i][j]));
      lu = std::max(lu, linf(c[i][1][j] - c[i][0][j]));
      lv = std::max(lv, linf(c[i][j][1] - c[i][j][0]));
    }
  }
  const auto div = [&](Scalar l) { return l == 0 ? kInf : tolerance / (3 * l); };
  return {div(lt), div(lu), div(lv)};
}

template <bool kVertexFace>
Result root_find(const Points& s, const Points& e, Scalar ms, const Settings& settings) {
  const std::array<Scalar, 3> tol = domain_tolerances<kVertexFace>(s, e, settings.tolerance);
  const std::array<Scalar, 3> err = numerical_error(s, e, kVertexFace, ms > 0);
  std::array<Axis, 3> axes;
  for (int k = 0; k < 3; ++k) {
    for (int i = 0; i < 4; ++i) {
      axes[k].x0[i] = s[i][k];
      axes[k].d[i] = e[i][k] - s[i][k];
    }
  }
  const Scalar co_tol = settings.tolerance;
  Result r;
  r.toi = kInf;
  r.output_tolerance = co_tol;

  thread_local std::vector<Box> heap;
  heap.clear();
  heap.push_back({0, 1, 0, 1, 0, 1, 0});
  const LaterFirst later;

  Scalar toi_skip = kInf;   // earliest box already small enough or inside the ε box
  bool use_skip = false;
  int box_in_level = -1;    // the level whose boxes so far all met the codomain tolerance
  bool level_ok = true;
  int root_level = -1;      // the level whose first live box is the capped answer
  Scalar level_toi = kInf, level_tolerance = co_tol;
  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), later);
    const Box b = heap.back();
    heap.pop_back();
    if (b.t0 >= toi_skip) continue;
    if (b.level != box_in_level) {
      box_in_level = b.level;
      level_ok = true;
    }
    ++r.boxes;
    // Inclusion: F's image of the box lies in the bounding box of its 8 corner values (F is
    // affine in each of t, u, v). Reject when that misses [−(err + δ), err + δ] on some axis.
    bool box_in = true;
    bool zero_in = true;
    std::array<Scalar, 3> width{};
    for (int k = 0; k < 3; ++k) {
      Scalar lo, hi;
      corner_range<kVertexFace>(axes[k], b, lo, hi);
      width[k] = hi - lo;
      const Scalar eps = err[k] + ms;
      if (lo > eps || hi < -eps) {
        zero_in = false;
        break;
      }
      box_in = box_in && lo >= -eps && hi <= eps;
    }
    if (!zero_in) continue;
    const bool small = width[0] <= co_tol && width[1] <= co_tol && width[2] <= co_tol;
    const Scalar wt = b.t1 - b.t0, wu = b.u1 - b.u0, wv = b.v1 - b.v0;
    const bool domain_small = wt <= tol[0] && wu <= tol[1] && wv <= tol[2];
    if (!small) level_ok = false;
    // A hit when the domain tolerance is met, or when every live box of this level so far met
    // the codomain tolerance (so none earlier in t can hide an earlier root at this precision).
    if (domain_small || (box_in && level_ok) || level_ok) {
      r.hit = true;
      r.toi = b.t0;
      return r;
    }
    if (settings.max_iterations > 0) {
      if (root_level != b.level) {
        root_level = b.level;
        level_toi = b.t0;
        level_tolerance = std::max({width[0], width[1], width[2], co_tol});
      }
      if (r.boxes > settings.max_iterations) {
        r.hit = true;
        r.toi = level_toi;
        r.output_tolerance = level_tolerance;
        return r;
      }
    }
    if (small || box_in) {
      toi_skip = std::min(toi_skip, b.t0);
      use_skip = true;
      continue;
    }
    // Split the parameter with the largest width / tolerance among those above tolerance.
    const std::array<Scalar, 3> w = {wt, wu, wv};
    int axis = 0;
    Scalar best = -kInf;
    for (int k = 0; k < 3; ++k) {
      const Scalar score = w[k] > tol[k] ? w[k] / tol[k] : -kInf;
      if (score > best) {
        best = score;
        axis = k;
      }
    }
    Box lo = b, hi = b;
    lo.level = hi.level = b.level + 1;
    Scalar mid;
    if (axis == 0) {
      mid = (b.t0 + b.t1) / 2;
      lo.t1 = hi.t0 = mid;
    } else if (axis == 1) {
      mid = (b.u0 + b.u1) / 2;
      lo.u1 = hi.u0 = mid;
    } else {
      mid = (b.v0 + b.v1) / 2;
      lo.v1 = hi.v0 = mid;
    }
    const Scalar a0 = axis == 0 ? b.t0 : axis == 1 ? b.u0 : b.v0;
    const Scalar a1 = axis == 0 ? b.t1 : axis == 1 ? b.u1 : b.v1;
    if (!(a0 < mid && mid < a1)) {  // no exact split left (TI: "overflow"): conservative hit
      r.hit = true;
      r.toi = std::min(b.t0, toi_skip);
      return r;
    }
    for (const Box& half : {hi, lo}) {
      if (axis == 0 && settings.t_max < 1 && !(half.t1 >= 0 && half.t0 <= settings.t_max)) continue;
      if (kVertexFace && axis != 0 && half.u0 + half.v0 > 1) continue;  // outside u + v ≤ 1
      heap.push_back(half);
      std::push_heap(heap.begin(), heap.end(), later);
    }
  }
  if (use_skip) {
    r.hit = true;
    r.toi = toi_skip;
  }
  return r;
}

}  // namespace

std::array<Scalar, 3> numerical_error(const Points& start, const Points& end, bool vertex_face,
                                      bool minimum_separation) {
  // 30, 28, 34 and 32 × 2^-52 (TI's double-precision filters).
  const Scalar c = minimum_separation ? (vertex_face ? 7.549516567451064e-15 : 7.105427357601002e-15)
                                      : (vertex_face ? 6.661338147750939e-15 : 6.217248937900877e-15);
  std::array<Scalar, 3> err;
  for (int k = 0; k < 3; ++k) {
    Scalar m = 1;
    for (int i = 0; i < 4; ++i) m = std::max({m, std::abs(start[i][k]), std::abs(end[i][k])});
    err[k] = c * (m * m * m);
  }
  return err;
}

Result vertex_face_ccd(const Points& start, const Points& end, Scalar min_separation, const Settings& settings) {
  return root_find<true>(start, end, min_separation, settings);
}

Result edge_edge_ccd(const Points& start, const Points& end, Scalar min_separation, const Settings& settings) {
  return root_find<false>(start, end, min_separation, settings);
}

}  // namespace crumple::ti_ref

#pragma once
// Exact CCD oracle for tests and tools only (GMP rationals, libgmp-dev). Shares no code with
// geometry/ccd.cpp. Every double is a dyadic rational, so the inputs are taken exactly.
//
// What it certifies (docs/ccd.md, "The oracle"):
//  - exact_distance2(t): the exact squared Euclidean distance between the two primitives at a
//    rational time t (a convex quadratic in (u, v) minimised exactly over the triangle or the
//    unit square: the interior stationary point when it lies inside, else the best point of
//    each side, all in rationals).
//  - decide(): a branch and bound over (t, u, v) boxes in order of earliest t. A box is
//    discarded only when the exact bounding box of its 8 exact corner values (F is
//    multilinear, so this contains the image of the box) is at Euclidean distance > δ from 0.
//    Hence, when a box starting at t0 is popped, no time before t0 brings the primitives
//    within δ (every earlier point lies in a discarded box). Witnesses are exact:
//    exact_distance2(t) ≤ δ² at a box's t0 or t1.
//      kYes, exact: the first contact time is `toi_lo` = `toi_hi` exactly.
//      kYes, bracket: a contact exists; the first contact time lies in [toi_lo, toi_hi].
//      kNo: no time in [0, 1] comes within δ (every box discarded).
//      kUndecided: budget spent; no contact before `toi_lo`, nothing else known.
//    δ = 0 contacts at irrational times have no rational witness: they end kUndecided.

#include <crumple/core/types.hpp>

#include <gmpxx.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <queue>
#include <vector>

namespace crumple::ccd_oracle {

using Q = mpq_class;

struct QVec {
  Q x, y, z;
};
inline QVec qvec(const Vec3& p) { return {Q(p.x()), Q(p.y()), Q(p.z())}; }
inline QVec operator-(const QVec& a, const QVec& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline QVec operator+(const QVec& a, const QVec& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline QVec operator*(const Q& s, const QVec& a) { return {s * a.x, s * a.y, s * a.z}; }
inline Q dot(const QVec& a, const QVec& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

/// F(t, u, v) = A(t) + u B(t) + v C(t), each linear in t: the same parametrisation as the
/// issue states (VF: vertex - (f0 + u (f1 - f0) + v (f2 - f0)); EE: (a0 + u (a1 - a0)) -
/// (b0 + v (b1 - b0))), built here in exact arithmetic.
struct Query {
  bool face = true;
  std::array<QVec, 2> a, b, c;  // at t = 0 and t = 1
  Q delta2;
};

inline Query make_query(bool face, const std::array<Vec3, 4>& start, const std::array<Vec3, 4>& end,
                        double delta) {
  Query q;
  q.face = face;
  for (int tau = 0; tau < 2; ++tau) {
    const auto& s = tau == 0 ? start : end;
    const QVec x0 = qvec(s[0]), x1 = qvec(s[1]), x2 = qvec(s[2]), x3 = qvec(s[3]);
    if (face) {
      q.a[tau] = x0 - x1;
      q.b[tau] = x1 - x2;
      q.c[tau] = x1 - x3;
    } else {
      q.a[tau] = x0 - x2;
      q.b[tau] = x1 - x0;
      q.c[tau] = x2 - x3;
    }
  }
  q.delta2 = Q(delta) * Q(delta);
  return q;
}

inline QVec lerp(const QVec& p0, const QVec& p1, const Q& t) { return p0 + t * (p1 - p0); }

/// Exact min over the domain (triangle u, v ≥ 0, u + v ≤ 1 for VF; unit square for EE) of
/// |a + u b + v c|² at time t.
inline Q exact_distance2(const Query& q, const Q& t) {
  const QVec a = lerp(q.a[0], q.a[1], t), b = lerp(q.b[0], q.b[1], t), c = lerp(q.c[0], q.c[1], t);
  const auto point = [&](const Q& u, const Q& v) { return a + u * b + v * c; };
  // Min over a segment of the domain from (u0, v0) to (u1, v1).
  const auto side = [&](const Q& u0, const Q& v0, const Q& u1, const Q& v1) {
    const QVec w = point(u0, v0);
    const QVec d = (u1 - u0) * b + (v1 - v0) * c;
    const Q dd = dot(d, d);
    if (dd == 0) return dot(w, w);
    Q s = -dot(w, d) / dd;
    if (s < 0) s = 0;
    if (s > 1) s = 1;
    const QVec x = w + s * d;
    return dot(x, x);
  };
  Q best;
  if (q.face) {
    best = std::min({side(0, 0, 1, 0), side(1, 0, 0, 1), side(0, 1, 0, 0)});
  } else {
    best = std::min({side(0, 0, 1, 0), side(1, 0, 1, 1), side(1, 1, 0, 1), side(0, 1, 0, 0)});
  }
  const Q bb = dot(b, b), bc = dot(b, c), cc = dot(c, c), ab = dot(a, b), ac = dot(a, c);
  const Q det = bb * cc - bc * bc;
  if (det > 0) {
    const Q u = (ac * bc - ab * cc) / det, v = (ab * bc - ac * bb) / det;
    const bool inside = u >= 0 && v >= 0 && (q.face ? u + v <= 1 : (u <= 1 && v <= 1));
    if (inside) {
      const QVec x = point(u, v);
      best = std::min(best, dot(x, x));
    }
  }
  return best;
}

/// Whether F(t, u, v) is exactly within δ at a given parameter point inside the domain.
inline bool contact_at(const Query& q, const Q& t, const Q& u, const Q& v) {
  if (t < 0 || t > 1 || u < 0 || v < 0 || (q.face ? u + v > 1 : (u > 1 || v > 1))) return false;
  const QVec f = lerp(q.a[0], q.a[1], t) + u * lerp(q.b[0], q.b[1], t) + v * lerp(q.c[0], q.c[1], t);
  return dot(f, f) <= q.delta2;
}

enum class Verdict { kYes, kNo, kUndecided };

struct Decision {
  Verdict verdict = Verdict::kUndecided;
  bool exact_toi = false;
  Q toi_lo = 0;  // no contact before this time (certified in every verdict)
  Q toi_hi = 1;  // kYes: a contact at this time
  std::int64_t boxes = 0;
};

struct OBox {
  Q t0, t1, u0, u1, v0, v1;
  int depth;
};

/// See the file comment. `bracket` is the width at which a kYes bracket stops being refined.
inline Decision decide(const Query& q, std::int64_t budget = 4000, double bracket = 0x1p-40) {
  Decision out;
  const auto witness = [&](const Q& t) { return exact_distance2(q, t) <= q.delta2; };
  if (witness(Q(0))) {
    out.verdict = Verdict::kYes;
    out.exact_toi = true;
    out.toi_lo = out.toi_hi = 0;
    return out;
  }
  const auto later = [](const OBox& x, const OBox& y) {
    return x.t0 > y.t0 || (x.t0 == y.t0 && x.depth < y.depth);
  };
  std::priority_queue<OBox, std::vector<OBox>, decltype(later)> queue(later);
  queue.push({0, 1, 0, 1, 0, 1, 0});
  bool have_witness = false;
  Q best;  // earliest witness time found
  const Q bracket_q(bracket);
  while (!queue.empty()) {
    OBox box = queue.top();
    queue.pop();
    if (have_witness && box.t0 >= best) continue;
    ++out.boxes;
    // Exact corner values and their bounding box.
    std::array<QVec, 8> f;
    for (int it = 0; it < 2; ++it) {
      const Q& t = it ? box.t1 : box.t0;
      const QVec a = lerp(q.a[0], q.a[1], t), b = lerp(q.b[0], q.b[1], t), c = lerp(q.c[0], q.c[1], t);
      const QVec au0 = a + box.u0 * b, au1 = a + box.u1 * b, cv0 = box.v0 * c, cv1 = box.v1 * c;
      f[it * 4 + 0] = au0 + cv0;
      f[it * 4 + 1] = au0 + cv1;
      f[it * 4 + 2] = au1 + cv0;
      f[it * 4 + 3] = au1 + cv1;
    }
    Q dist2 = 0;
    Q width[3] = {0, 0, 0};  // per parameter t, u, v: largest corner difference (L1 over axes)
    for (int k = 0; k < 3; ++k) {
      const auto coord = [k](const QVec& p) -> const Q& { return k == 0 ? p.x : (k == 1 ? p.y : p.z); };
      Q lo = coord(f[0]), hi = coord(f[0]);
      for (int i = 1; i < 8; ++i) {
        lo = std::min(lo, coord(f[i]));
        hi = std::max(hi, coord(f[i]));
      }
      if (lo > 0) dist2 += lo * lo;
      if (hi < 0) dist2 += hi * hi;
      for (int i = 0; i < 8; ++i) {
        for (int bit = 0; bit < 3; ++bit) {
          const int mask = 4 >> bit;
          if (i & mask) continue;
          const Q diff = abs(coord(f[i | mask]) - coord(f[i]));
          if (diff > width[bit]) width[bit] = diff;
        }
      }
    }
    if (dist2 > q.delta2) continue;  // certified: no point of this box within δ
    // No contact before box.t0 (all earlier points lay in discarded boxes).
    out.toi_lo = box.t0;
    if (witness(box.t0)) {
      out.verdict = Verdict::kYes;
      out.exact_toi = true;
      out.toi_hi = box.t0;
      return out;
    }
    if (witness(box.t1) && (!have_witness || box.t1 < best)) {
      have_witness = true;
      best = box.t1;
    }
    if (have_witness && best - box.t0 <= bracket_q) {
      out.verdict = Verdict::kYes;
      out.toi_hi = best;
      return out;
    }
    if (out.boxes >= budget) {
      if (have_witness) {
        out.verdict = Verdict::kYes;
        out.toi_hi = best;
      }
      return out;
    }
    int axis = 0;
    for (int d = 1; d < 3; ++d) {
      if (width[d] > width[axis]) axis = d;
    }
    OBox lo_half = box, hi_half = box;
    lo_half.depth = hi_half.depth = box.depth + 1;
    if (axis == 0) {
      const Q mid = (box.t0 + box.t1) / 2;
      lo_half.t1 = mid;
      hi_half.t0 = mid;
    } else if (axis == 1) {
      const Q mid = (box.u0 + box.u1) / 2;
      lo_half.u1 = mid;
      hi_half.u0 = mid;
    } else {
      const Q mid = (box.v0 + box.v1) / 2;
      lo_half.v1 = mid;
      hi_half.v0 = mid;
    }
    for (OBox* child : {&lo_half, &hi_half}) {
      if (q.face && child->u0 + child->v0 > 1) continue;
      queue.push(std::move(*child));
    }
  }
  if (have_witness) {
    // Every box starting before `best` was discarded: `best` is the first contact.
    out.verdict = Verdict::kYes;
    out.exact_toi = true;
    out.toi_lo = out.toi_hi = best;
  } else {
    out.verdict = Verdict::kNo;
    out.toi_lo = 1;
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// δ = 0 contacts at irrational times: a certificate from the coplanarity function.
//
// f(t) = det[x1 - x0, x2 - x0, x3 - x0](t) (exact, rational t). A strict sign change of f over
// [l, r] puts a coplanarity time t* in (l, r). If, for every t in [l, r] (rational interval
// arithmetic), the in-plane tests are strictly satisfied — VF: the three orientations
// ((f_{i+1} - f_i) × (p - f_i)) · n > 0 with n = (f1 - f0) × (f2 - f0); EE: b0, b1 strictly on
// opposite sides of edge a's line and a0, a1 of edge b's, within the plane (signs of
// (d × w) · n, n = da × db) — then at t* the point lies inside the triangle (the segments
// cross): a contact at t* ≤ r. The samples are 64 equal intervals, each sign change narrowed
// to width 2^-50 by exact bisection.

struct QI {
  Q lo, hi;
};
inline QI qi(const Q& x) { return {x, x}; }
inline QI operator+(const QI& a, const QI& b) { return {a.lo + b.lo, a.hi + b.hi}; }
inline QI operator-(const QI& a, const QI& b) { return {a.lo - b.hi, a.hi - b.lo}; }
inline QI operator*(const QI& a, const QI& b) {
  const Q p[4] = {a.lo * b.lo, a.lo * b.hi, a.hi * b.lo, a.hi * b.hi};
  QI out{p[0], p[0]};
  for (const Q& x : p) {
    if (x < out.lo) out.lo = x;
    if (x > out.hi) out.hi = x;
  }
  return out;
}
struct QIVec {
  QI x, y, z;
};
inline QIVec operator-(const QIVec& a, const QIVec& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline QIVec cross(const QIVec& a, const QIVec& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline QI dot(const QIVec& a, const QIVec& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

/// The 4 input points (exact) at t = 0 and t = 1, in the order of the narrow phase.
struct Points {
  bool face = true;
  std::array<QVec, 4> start, end;
};
inline Points make_points(bool face, const std::array<Vec3, 4>& start, const std::array<Vec3, 4>& end) {
  Points p;
  p.face = face;
  for (int i = 0; i < 4; ++i) {
    p.start[i] = qvec(start[i]);
    p.end[i] = qvec(end[i]);
  }
  return p;
}

inline Q coplanarity(const Points& p, const Q& t) {
  std::array<QVec, 4> x;
  for (int i = 0; i < 4; ++i) x[i] = lerp(p.start[i], p.end[i], t);
  const QVec a = x[1] - x[0], b = x[2] - x[0], c = x[3] - x[0];
  return a.x * (b.y * c.z - b.z * c.y) + a.y * (b.z * c.x - b.x * c.z) + a.z * (b.x * c.y - b.y * c.x);
}

/// True when the in-plane tests hold strictly for every t in [l, r] (see above).
inline bool inside_throughout(const Points& p, const Q& l, const Q& r) {
  std::array<QIVec, 4> x;
  const QI t{l, r};
  for (int i = 0; i < 4; ++i) {
    const auto c = [&](const Q& s, const Q& e) { return qi(s) + t * qi(e - s); };
    x[i] = {c(p.start[i].x, p.end[i].x), c(p.start[i].y, p.end[i].y), c(p.start[i].z, p.end[i].z)};
  }
  const auto positive = [](const QI& v) { return v.lo > 0; };
  const auto negative = [](const QI& v) { return v.hi < 0; };
  if (p.face) {
    const QIVec n = cross(x[2] - x[1], x[3] - x[1]);
    for (int i = 0; i < 3; ++i) {
      const QIVec& fi = x[1 + i];
      const QIVec& fj = x[1 + (i + 1) % 3];
      if (!positive(dot(cross(fj - fi, x[0] - fi), n))) return false;
    }
    return true;
  }
  const QIVec da = x[1] - x[0], db = x[3] - x[2];
  const QIVec n = cross(da, db);
  const QI o1 = dot(cross(da, x[2] - x[0]), n), o2 = dot(cross(da, x[3] - x[0]), n);
  const QI o3 = dot(cross(db, x[0] - x[2]), n), o4 = dot(cross(db, x[1] - x[2]), n);
  const bool ab = (positive(o1) && negative(o2)) || (negative(o1) && positive(o2));
  const bool ba = (positive(o3) && negative(o4)) || (negative(o3) && positive(o4));
  return ab && ba;
}

/// δ = 0: the end `hi` of an interval (lo, hi) holding a certified contact time, the earliest
/// such among the 64 samples; false when none is certified (which proves nothing).
inline bool certified_crossing(const Points& p, Q& hi) {
  const int n = 64;
  Q prev_t = 0;
  Q prev_f = coplanarity(p, prev_t);
  for (int k = 1; k <= n; ++k) {
    const Q t = Q(k) / n;
    const Q f = coplanarity(p, t);
    if ((prev_f > 0 && f < 0) || (prev_f < 0 && f > 0)) {
      Q l = prev_t, r = t, fl = prev_f;
      const Q width = Q(1) / Q(1L << 50);
      while (r - l > width) {
        const Q m = (l + r) / 2;
        const Q fm = coplanarity(p, m);
        if (fm == 0) {
          l = m;
          r = m;
          break;
        }
        if ((fm > 0) == (fl > 0)) {
          l = m;
          fl = fm;
        } else {
          r = m;
        }
      }
      if (inside_throughout(p, l, r)) {
        hi = r;
        return true;
      }
    }
    prev_t = t;
    prev_f = f;
  }
  return false;
}

}  // namespace crumple::ccd_oracle

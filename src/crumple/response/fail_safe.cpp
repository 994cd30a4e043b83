#include <crumple/core/error.hpp>
#include <crumple/geometry/ccd.hpp>
#include <crumple/response/fail_safe.hpp>
#include <crumple/response/union_find_detail.hpp>
#include <crumple/response/untangle.hpp>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace crumple::response {

namespace {
inline std::size_t at(Index i) { return static_cast<std::size_t>(i); }

using detail::root;

/// Moves the zone `members` rigidly (see the file comment); pinned members keep their
/// displacement and the others translate with the pinned ones' mean.
void rigidify(std::span<const Index> members, PositionsView start, std::span<const Scalar> inv_mass,
              std::span<Vec3> u) {
  Vec3 pinned_sum = Vec3::Zero();
  int pinned = 0;
  Scalar mass = 0;
  Vec3 centre = Vec3::Zero(), mean = Vec3::Zero();
  for (Index i : members) {
    if (inv_mass[at(i)] > 0) {
      const Scalar m = 1 / inv_mass[at(i)];
      mass += m;
      centre += m * start[at(i)];
      mean += m * u[at(i)];
    } else {
      pinned_sum += u[at(i)];
      ++pinned;
    }
  }
  if (pinned > 0) {
    const Vec3 shift = pinned_sum / pinned;
    for (Index i : members) {
      if (inv_mass[at(i)] > 0) u[at(i)] = shift;
    }
    return;
  }
  if (!(mass > 0)) return;
  centre /= mass;
  mean /= mass;
  Vec3 momentum = Vec3::Zero();
  Eigen::Matrix<Scalar, 3, 3> inertia = Eigen::Matrix<Scalar, 3, 3>::Zero();
  for (Index i : members) {
    const Scalar m = 1 / inv_mass[at(i)];
    const Vec3 r = start[at(i)] - centre;
    momentum += m * r.cross(u[at(i)] - mean);
    inertia += m * (r.squaredNorm() * Eigen::Matrix<Scalar, 3, 3>::Identity() - r * r.transpose());
  }
  // θ = I⁺ L: the pseudo-inverse, since a zone on a line has no inertia about that line.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<Scalar, 3, 3>> eigen(inertia);
  const Vec3 lambda = eigen.eigenvalues();
  const Scalar cutoff = 1e-12 * lambda.cwiseAbs().maxCoeff();
  Vec3 coords = eigen.eigenvectors().transpose() * momentum;
  for (int k = 0; k < 3; ++k) coords[k] = lambda[k] > cutoff ? coords[k] / lambda[k] : 0;
  const Vec3 theta = eigen.eigenvectors() * coords;
  const Scalar angle = theta.norm();
  const Eigen::Matrix<Scalar, 3, 3> rotation =
      angle > 0 ? Eigen::AngleAxis<Scalar>(angle, theta / angle).toRotationMatrix()
                : Eigen::Matrix<Scalar, 3, 3>::Identity();
  for (Index i : members) {
    const Vec3 r = start[at(i)] - centre;
    u[at(i)] = centre + mean + rotation * r - start[at(i)];
  }
}
}  // namespace

namespace {
/// The points of a stencil's four vertices at the frame's start and end.
std::pair<geometry::CcdPoints, geometry::CcdPoints> points_of(const std::array<Index, 4>& v, PositionsView start,
                                                              std::span<const Vec3> positions) {
  geometry::CcdPoints p0, p1;
  for (std::size_t k = 0; k < 4; ++k) {
    p0[k] = start[at(v[k])];
    p1[k] = positions[at(v[k])];
  }
  return {p0, p1};
}

/// Whether an impact found within δ is live. Not live, each by a narrow-phase certificate that
/// the pair never touches:
///  - a pair within δ already at the frame's start (toi 0) that never touches (δ = 0): the
///    proximity response's;
///  - a hit inside the narrow phase's tolerance band, reported above δ (`kHitTolerance` may
///    report a pair that comes within δ (1 + σ) only) and certified never to come within
///    δ (1 − σ): a pair that grazes δ, which an impulse (it removes only an approach) cannot
///    move out of the band.
bool live_impact(geometry::CcdPair kind, const Stencil& s, Scalar toi, Scalar distance, geometry::CcdOutcome outcome,
                 Scalar delta, PositionsView start, std::span<const Vec3> positions, geometry::CcdOptions narrow) {
  if (toi == 0 && distance <= delta) {
    narrow.min_separation = 0;
  } else if (distance > delta && outcome == geometry::CcdOutcome::kHitTolerance && narrow.separation_tolerance > 0) {
    narrow.min_separation = delta * (1 - std::min<Scalar>(narrow.separation_tolerance, 1));
  } else {
    return true;
  }
  const auto [p0, p1] = points_of(s.vertex, start, positions);
  return geometry::ccd(kind, p0, p1, narrow).hit;
}

/// The pair of `s` re-tested alone over the motion from `start` to `positions` with `narrow`
/// (δ set): false when it is no longer a live impact; otherwise `s` becomes the pair's stencil
/// at its new time of impact, made as `CcdFailSafe::detect` makes it from a query's impact.
bool retest(Stencil& s, PositionsView start, std::span<const Vec3> positions, const geometry::CcdOptions& narrow) {
  const auto [p0, p1] = points_of(s.vertex, start, positions);
  const geometry::CcdPair kind = s.edge_edge ? geometry::CcdPair::kEdgeEdge : geometry::CcdPair::kVertexFace;
  const geometry::CcdResult r = geometry::ccd(kind, p0, p1, narrow);
  if (!r.hit) return false;
  if (s.edge_edge) {
    const EdgeEdgeImpact c = edge_edge_impact(p0, p1, r);
    if (!live_impact(kind, s, c.toi, c.distance, c.outcome, narrow.min_separation, start, positions, narrow)) {
      return false;
    }
    s = edge_edge_stencil({s.vertex[0], s.vertex[1]}, {s.vertex[2], s.vertex[3]}, c.s, c.t, c.normal);
  } else {
    const VertexFaceImpact c = vertex_face_impact(p0, p1, r);
    if (!live_impact(kind, s, c.toi, c.distance, c.outcome, narrow.min_separation, start, positions, narrow)) {
      return false;
    }
    s = vertex_face_stencil(s.vertex[0], {s.vertex[1], s.vertex[2], s.vertex[3]}, c.barycentric, c.normal);
  }
  return true;
}
}  // namespace

namespace {
/// `options` with the query's δ set to the fail-safe's (checked first).
FailSafeOptions checked(FailSafeOptions options) {
  CRUMPLE_CHECK(options.impulse_rounds >= 0 && options.zone_rounds >= 0, "fail-safe rounds must be >= 0");
  if (!(options.restricted_share >= 0 && options.restricted_share <= 1)) {
    throw InputError("fail-safe restricted share must be in [0, 1]");
  }
  if (!(options.min_separation >= 0) || !std::isfinite(options.min_separation)) {
    throw InputError("fail-safe minimum separation must be finite and >= 0");
  }
  options.query.min_separation = options.min_separation;
  return options;
}
}  // namespace

CcdFailSafe::CcdFailSafe(std::shared_ptr<const Topology> topology, FailSafeOptions options)
    : topology_(topology), options_(checked(std::move(options))), query_(topology, options_.query) {}

std::size_t CcdFailSafe::flag_first_query(PositionsView start, std::span<const Vec3> positions,
                                          const StartProximity& proximity) {
  const std::size_t n = start.size();
  motion_valid_ = false;
  if (proximity.pairs == nullptr || n == 0) return kUnrestricted;
  // The margin m: a tenth of R − δ (1 + σ), and far above the rounding of the displacements
  // and of the detector's distances (NaN anywhere: no restriction).
  Scalar magnitude = 0;
  for (std::size_t i = 0; i < n; ++i) {
    magnitude = std::max({magnitude, start[i].cwiseAbs().maxCoeff(), positions[i].cwiseAbs().maxCoeff()});
  }
  const Scalar sigma = std::clamp<Scalar>(options_.query.narrow.separation_tolerance, 0, 1);
  const Scalar reach = options_.min_separation * (1 + sigma);  // δ (1 + σ)
  const Scalar margin = 0.1 * (proximity.radius - reach) + 1e-9 * magnitude;
  const Scalar bound = proximity.radius - reach - margin;  // s
  if (!(bound > 0)) return kUnrestricted;
  const Scalar r2 = 0.25 * bound * bound;  // (s/2)²
  const auto u = [&](Index v) { return positions[static_cast<std::size_t>(v)] - start[static_cast<std::size_t>(v)]; };
  // The reference c: the displacements' mean or their per-axis median (of a cloth half resting
  // and half falling, the mean lies in neither group), whichever flags fewer vertices.
  Vec3 mean = Vec3::Zero(), median;
  for (std::size_t i = 0; i < n; ++i) mean += positions[i] - start[i];
  mean /= static_cast<Scalar>(n);
  scratch_.resize(n);
  for (Eigen::Index k = 0; k < 3; ++k) {
    for (std::size_t i = 0; i < n; ++i) scratch_[i] = positions[i][k] - start[i][k];
    const auto middle = scratch_.begin() + static_cast<std::ptrdiff_t>(n / 2);
    std::nth_element(scratch_.begin(), middle, scratch_.end());
    median[k] = *middle;
  }
  const auto fast = [&](const Vec3& c, bool write) {
    std::size_t count = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const bool far = !((positions[i] - start[i] - c).squaredNorm() <= r2);
      if (write) moved_[i] = far;
      count += static_cast<std::size_t>(far);
    }
    return count;
  };
  moved_.resize(n);
  const bool by_motion = options_.motion_bound;
  const std::size_t far = fast(fast(median, false) <= fast(mean, false) ? median : mean, true);
  if (!by_motion && !restricted(far, n)) return kUnrestricted;
  if (by_motion) {
    exempt_.assign(n, 0);
    motion_reach_ = bound;
  }
  // The pairs within R: flagged unless their own relative motion keeps them beyond δ (1 + σ) + m;
  // with the motion bound, also exempt from it (their relative motion may be within s).
  const auto check = [&](const std::array<Index, 4>& v, std::size_t first_b, Scalar distance) {
    if (!by_motion) {
      for (const Index i : v) {
        if (moved_[static_cast<std::size_t>(i)]) return;  // tested anyway
      }
    }
    Scalar most = 0;  // the largest |uᵢ − uⱼ|², i on one side, j on the other
    for (std::size_t i = 0; i < first_b; ++i) {
      for (std::size_t j = first_b; j < 4; ++j) most = std::max(most, (u(v[i]) - u(v[j])).squaredNorm());
    }
    if (distance - std::sqrt(most) >= reach + margin) return;  // NaN: flagged
    for (const Index i : v) {
      moved_[static_cast<std::size_t>(i)] = 1;
      if (by_motion) exempt_[static_cast<std::size_t>(i)] = 1;
    }
  };
  const auto faces = topology_->faces();
  const auto vertex = [&](Index v) { return v >= 0 && static_cast<std::size_t>(v) < n; };
  for (const VertexFaceContact& c : proximity.pairs->vf) {
    CRUMPLE_CHECK(vertex(c.vertex) && c.face >= 0 && static_cast<std::size_t>(c.face) < faces.size(),
                  "fail-safe: a start-proximity pair is out of range");
    const Face& f = faces[static_cast<std::size_t>(c.face)];
    check({c.vertex, f[0], f[1], f[2]}, 1, c.distance);
  }
  for (const EdgeEdgeContact& c : proximity.pairs->ee) {
    CRUMPLE_CHECK(vertex(c.a[0]) && vertex(c.a[1]) && vertex(c.b[0]) && vertex(c.b[1]),
                  "fail-safe: a start-proximity pair is out of range");
    check({c.a[0], c.a[1], c.b[0], c.b[1]}, 2, c.distance);
  }
  const auto count = static_cast<std::size_t>(std::count(moved_.begin(), moved_.end(), 1));
  motion_valid_ = by_motion;
  return restricted(count, n) ? count : kUnrestricted;
}

std::size_t CcdFailSafe::detect(PositionsView start, std::span<const Vec3> positions, FailSafeStats& stats,
                                const StartProximity* proximity) {
  const PositionsView end(positions.data(), positions.size());
  const bool restrict = options_.restrict_queries && (stats.queries + stats.unchanged > 0 || same_start_);
  queried_valid_ = false;  // until the query has answered
  if (!restrict) {
    // The first query of a frame: restricted to the flagged vertices' pairs when the start's
    // proximity is known and leaves most vertices unflagged (see `apply`), else the sweep.
    const std::size_t flagged = options_.restrict_queries && proximity != nullptr
                                    ? flag_first_query(start, positions, *proximity)
                                    : kUnrestricted;
    if (flagged != kUnrestricted && motion_valid_) {
      query_.query_moved(start, end, moved_, ContinuousQuery::MotionBound{exempt_, motion_reach_}, impacts_);
      stats.first_restricted = true;
      stats.first_flagged = flagged;
    } else if (flagged != kUnrestricted) {
      query_.query_moved(start, end, moved_, impacts_);
      stats.first_restricted = true;
      stats.first_flagged = flagged;
    } else if (motion_valid_) {
      query_.query(start, end, ContinuousQuery::MotionBound{exempt_, motion_reach_}, impacts_);
    } else {
      query_.query(start, end, impacts_);
    }
  } else {
    // Only the pairs holding a vertex whose end moved since the last query can have changed
    // (compared bit for bit: the narrow phase sees bits, and -0 is not 0 to it).
    moved_.resize(positions.size());
    std::size_t count = 0;
    for (std::size_t i = 0; i < positions.size(); ++i) {
      moved_[i] = std::memcmp(positions[i].data(), queried_[i].data(), sizeof(Vec3)) != 0;
      count += static_cast<std::size_t>(moved_[i]);
    }
    if (!restricted(count, positions.size())) {  // the sweep: the same impacts, bit for bit
      query_.query(start, end, impacts_);
    } else if (count > 0) {
      query_.update_moved(start, end, moved_, impacts_);
    }
    ++(count > 0 ? stats.queries : stats.unchanged);
  }
  if (!restrict) ++stats.queries;
  if (options_.restrict_queries) {
    queried_.assign(positions.begin(), positions.end());
    queried_valid_ = true;
  }
  live_.clear();
  const Scalar delta = options_.min_separation;
  const auto live = [&](geometry::CcdPair kind, const Stencil& s, const auto& impact) {
    return live_impact(kind, s, impact.toi, impact.distance, impact.outcome, delta, start, positions,
                       options_.query.narrow);
  };
  const auto faces = topology_->faces();
  for (const VertexFaceImpact& c : impacts_.vf) {
    Stencil s = vertex_face_stencil(c.vertex, faces[at(c.face)], c.barycentric, c.normal);
    if (!live(geometry::CcdPair::kVertexFace, s, c)) continue;
    if (touches_tangle_on_both_sides(s, tangle_)) continue;
    live_.push_back(s);
  }
  for (const EdgeEdgeImpact& c : impacts_.ee) {
    Stencil s = edge_edge_stencil(c.a, c.b, c.s, c.t, c.normal);
    if (!live(geometry::CcdPair::kEdgeEdge, s, c)) continue;
    if (touches_tangle_on_both_sides(s, tangle_)) continue;
    live_.push_back(s);
  }
  return live_.size();
}

FailSafeStats CcdFailSafe::apply(PositionsView start, std::span<const Scalar> inv_mass, Scalar duration,
                                 std::span<Vec3> positions, std::span<Vec3> velocities,
                                 const StartProximity* proximity) {
  const std::size_t n = start.size();
  CRUMPLE_CHECK(n == at(topology_->num_vertices()) && positions.size() == n && velocities.size() == n &&
                    inv_mass.size() == n,
                "fail-safe: start, positions, velocities and inverse masses must have #V entries");
  CRUMPLE_CHECK(duration > 0, "fail-safe: the frame's duration must be > 0");
  FailSafeStats stats;
  // A second call over the same start (the simulation's obstacle rounds) continues from the
  // last query: its impacts are those of the motion from this start to `queried_`.
  same_start_ = options_.restrict_queries && queried_valid_ && start_.size() == n &&
                std::memcmp(start_.data(), start.data(), n * sizeof(Vec3)) == 0;
  if (!same_start_) {
    queried_valid_ = false;
    start_.assign(start.begin(), start.end());
  }
  if (detect(start, positions, stats, proximity) == 0) return stats;
  stats.impacts = live_.size();

  std::vector<Vec3> u(n), original(n);
  for (std::size_t i = 0; i < n; ++i) original[i] = u[i] = positions[i] - start[i];
  std::vector<char> changed(n, 0), frozen(n, 0);
  const auto mark = [&](const Stencil& s) {
    for (int k = 0; k < s.count; ++k) changed[at(s.vertex[static_cast<std::size_t>(k)])] = 1;
  };
  const auto move = [&] {
    for (std::size_t i = 0; i < n; ++i) {
      if (changed[i] && !frozen[i]) positions[i] = start[i] + u[i];
    }
  };
  const auto finish = [&] {
    const Scalar rate = 1 / duration;
    for (std::size_t i = 0; i < n; ++i) {
      if (frozen[i]) {
        velocities[i] = Vec3::Zero();
      } else if (changed[i]) {
        velocities[i] = rate * u[i];
      }
    }
    return stats;
  };

  // 1. CCD impulses on the relative normal displacement, a query after each round. When a
  // query finds exactly the pairs of the last one (the impulses are not clearing them: e.g. two
  // sides of a quad squeezed below δ), the rounds until the next query run on those pairs
  // alone, each round re-testing them (`retest`, at their new times of impact), until none is
  // left, a round applies no impulse, or the rounds run out. Only a query's answer ends the
  // stage.
  geometry::CcdOptions narrow = options_.query.narrow;
  narrow.min_separation = options_.min_separation;
  const auto pairs_of = [&] {
    std::vector<std::array<Index, 5>> pairs;
    pairs.reserve(live_.size());
    for (const Stencil& s : live_) pairs.push_back({s.vertex[0], s.vertex[1], s.vertex[2], s.vertex[3], s.edge_edge});
    return pairs;
  };
  std::vector<std::array<Index, 5>> last_pairs = pairs_of();
  bool stalled = false;
  for (int r = 0; r < options_.impulse_rounds;) {
    bool applied = false;
    for (;;) {
      ++r;
      ++stats.impulse_rounds;
      bool any = false;
      for (const Stencil& s : live_) {
        if (s.normal.squaredNorm() > 0 && correct_velocity(s, inv_mass, u) > 0) {
          mark(s);
          any = true;
        }
      }
      applied = applied || any;
      move();
      if (!stalled || !any || r >= options_.impulse_rounds) break;
      std::erase_if(live_, [&](Stencil& s) { return !retest(s, start, positions, narrow); });
      if (live_.empty()) break;
      ++stats.retested_rounds;  // the next round runs on the re-tested pairs
    }
    if (detect(start, positions, stats) == 0) return finish();
    // No impulse since the last query: the motion is that query's, and so would every later
    // round be (each starts from the query's impacts): on to the zones.
    if (!applied) break;
    std::vector<std::array<Index, 5>> pairs = pairs_of();
    stalled = pairs == last_pairs;
    last_pairs = std::move(pairs);
  }

  // 2. Impact zones: merged, each moved rigidly.
  std::vector<Index> parent(n, -1);
  for (int r = 0; r < options_.zone_rounds; ++r) {
    ++stats.zone_rounds;
    bool grown = false;  // a vertex joined a zone, or two zones merged
    for (const Stencil& s : live_) {
      for (int k = 0; k < s.count; ++k) {
        const Index v = s.vertex[static_cast<std::size_t>(k)];
        if (parent[at(v)] < 0) {
          parent[at(v)] = v;
          ++stats.zone_vertices;
          grown = true;
        }
      }
      const Index first = root(parent, s.vertex[0]);
      for (int k = 1; k < s.count; ++k) {
        const Index other = root(parent, s.vertex[static_cast<std::size_t>(k)]);
        if (other != first) {
          parent[at(other)] = first;
          grown = true;
        }
      }
      mark(s);
    }
    // The same zones as the last round, which already moved each rigidly: moving them again
    // gives the same motion (up to rounding), and the same live impacts. On to the fallback.
    if (r > 0 && !grown) break;
    std::vector<std::pair<Index, Index>> by_zone;  // (root, member)
    for (std::size_t i = 0; i < n; ++i) {
      if (parent[i] >= 0) by_zone.emplace_back(root(parent, static_cast<Index>(i)), static_cast<Index>(i));
    }
    std::sort(by_zone.begin(), by_zone.end());
    std::vector<Index> members;
    for (std::size_t b = 0; b < by_zone.size();) {
      std::size_t e = b;
      members.clear();
      while (e < by_zone.size() && by_zone[e].first == by_zone[b].first) members.push_back(by_zone[e++].second);
      rigidify(members, start, inv_mass, u);
      b = e;
    }
    move();
    if (detect(start, positions, stats) == 0) return finish();
  }

  // 3. The fallback: the vertices of live impacts keep their start positions.
  for (;;) {
    std::size_t added = 0;
    for (const Stencil& s : live_) {
      for (int k = 0; k < s.count; ++k) {
        const std::size_t v = at(s.vertex[static_cast<std::size_t>(k)]);
        if (frozen[v]) continue;
        frozen[v] = 1;
        u[v] = Vec3::Zero();
        positions[v] = start[v];
        ++added;
      }
    }
    if (added == 0) {  // only static pairs left: none can touch (see the file comment)
      stats.static_left = live_.size();
      break;
    }
    stats.frozen += added;
    if (detect(start, positions, stats) == 0) break;
  }
  return finish();
}

}  // namespace crumple::response

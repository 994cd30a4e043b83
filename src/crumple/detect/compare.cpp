#include <crumple/core/error.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/mesh/shapes.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <random>

namespace crumple {

VectorFrames::VectorFrames(TriMesh mesh, std::vector<Positions> frames, std::string label)
    : mesh_(std::move(mesh)), frames_(std::move(frames)), label_(std::move(label)) {
  for (const Positions& f : frames_) {
    CRUMPLE_CHECK(f.size() == static_cast<std::size_t>(mesh_.num_vertices()),
                  "VectorFrames: a frame has " + std::to_string(f.size()) + " positions, the mesh " +
                      std::to_string(mesh_.num_vertices()) + " vertices");
  }
}

// ---------------------------------------------------------------------------------------------

FoldingSequence::FoldingSequence(FoldingParams params)
    : params_(params), mesh_(shapes::lattice(std::max<Index>(params.n, 1), std::max<Index>(params.n, 1))) {
  if (params_.n < 2) throw InputError("folding sequence: n must be >= 2, got " + std::to_string(params_.n));
  if (params_.frames < 1) throw InputError("folding sequence: frames must be >= 1");
  std::mt19937_64 rng(params_.seed);
  std::uniform_real_distribution<double> u(0, 1);
  k1_ = 1.5 + 1.5 * u(rng);
  k2_ = 1.0 + 1.5 * u(rng);
  phase1_ = 2 * std::numbers::pi * u(rng);
  phase2_ = 2 * std::numbers::pi * u(rng);
  speed_ = 0.5 + u(rng);
  const double ell = 1.0 / params_.n;
  jitter_.resize(static_cast<std::size_t>(mesh_.num_vertices()));
  std::uniform_real_distribution<double> s(-1, 1);
  for (Vec3& j : jitter_) j = 0.02 * ell * Vec3(s(rng), s(rng), s(rng));
}

std::string FoldingSequence::name(std::size_t i) const {
  return "folding-n" + std::to_string(params_.n) + "-seed" + std::to_string(params_.seed) + "#" +
         std::to_string(i);
}

Positions FoldingSequence::positions(std::size_t i) const {
  CRUMPLE_CHECK(i < params_.frames, "FoldingSequence: frame " + std::to_string(i) + " out of range");
  constexpr double pi = std::numbers::pi;
  const double s = params_.frames == 1 ? 1.0 : static_cast<double>(i) / static_cast<double>(params_.frames - 1);
  const double ell = 1.0 / params_.n;
  const double R = 1.5 * ell;
  const double theta = (0.8 + 0.35 * s) * pi;
  const double arc = R * theta;
  const double amplitude = 3.3 * R;
  const double x0 = 0.5;
  Positions out = mesh_.positions();
  for (std::size_t v = 0; v < out.size(); ++v) {
    Vec3& p = out[v];
    const double x = p.x(), y = p.y();
    if (x > x0) {
      const double u = x - x0;
      Vec3 q, normal;  // normal: towards the inside of the fold (the lower layer at θ = π)
      if (u <= arc) {
        const double phi = u / R;
        q = Vec3(x0 + R * std::sin(phi), y, R * (1 - std::cos(phi)));
        normal = Vec3(-std::sin(phi), 0, std::cos(phi));
      } else {
        const Vec3 end(x0 + R * std::sin(theta), y, R * (1 - std::cos(theta)));
        q = end + (u - arc) * Vec3(std::cos(theta), 0, std::sin(theta));
        normal = Vec3(-std::sin(theta), 0, std::cos(theta));
      }
      // Travelling ripple towards the lower layer, faded in away from the fold.
      const double fade = std::clamp(u / (6 * R), 0.0, 1.0);
      const double wave = 0.5 + 0.5 * std::sin(2 * pi * (k1_ * u + speed_ * s) + phase1_) *
                                    std::cos(2 * pi * k2_ * y + phase2_);
      q += amplitude * fade * fade * wave * normal;
      p = q;
    }
    p += jitter_[v];
  }
  return out;
}

// ---------------------------------------------------------------------------------------------

ContactMatch match_contacts(const ContactSet& got, const ContactSet& reference) {
  ContactMatch m;
  const auto merge = [&](const auto& a, const auto& b, const auto& less) {
    std::size_t i = 0, j = 0;
    while (i < a.size() || j < b.size()) {
      if (j == b.size() || (i < a.size() && less(a[i], b[j]))) {
        ++m.false_contacts;
        ++i;
      } else if (i == a.size() || less(b[j], a[i])) {
        ++m.missed;
        ++j;
      } else {
        ++m.found;
        ++i;
        ++j;
      }
    }
    m.reported += a.size();
    m.reference += b.size();
  };
  merge(got.vf, reference.vf, CanonicalLess{});
  merge(got.ee, reference.ee, CanonicalLess{});
  merge(got.tt, reference.tt, CanonicalLess{});
  return m;
}

namespace {

double timed_update(Detector& d, const Positions& previous, const Positions& current, ContactSet& out) {
  const auto start = std::chrono::steady_clock::now();
  d.update(previous, current, out);
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

ReferenceRun run_reference(Detector& reference, const FrameSource& frames) {
  reference.set_topology(frames.mesh().topology_ptr());
  ReferenceRun run;
  Positions previous;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    Positions current = frames.positions(i);
    ContactSet contacts;
    run.ms.push_back(timed_update(reference, previous, current, contacts));
    run.contacts.push_back(std::move(contacts));
    previous = std::move(current);
  }
  return run;
}

namespace {

ComparisonSummary compare_impl(Detector& method, const FrameSource& frames,
                               const std::function<const ContactSet&(std::size_t, const Positions&,
                                                                     const Positions&, double&)>& reference,
                               const std::function<void(const FrameComparison&)>& on_frame) {
  method.set_topology(frames.mesh().topology_ptr());
  ComparisonSummary summary;
  Positions previous;
  ContactSet got;
  double ms_sum = 0, ref_sum = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    Positions current = frames.positions(i);
    FrameComparison frame;
    frame.frame = i;
    frame.name = frames.name(i);
    frame.ms = timed_update(method, previous, current, got);
    const ContactSet& ref = reference(i, previous, current, frame.reference_ms);
    frame.match = match_contacts(got, ref);
    frame.stats = method.stats();
    summary.total += frame.match;
    summary.min_recall = std::min(summary.min_recall, frame.match.recall());
    ms_sum += frame.ms;
    ref_sum += frame.reference_ms;
    ++summary.frames;
    if (on_frame) on_frame(frame);
    previous = std::move(current);
  }
  if (summary.frames > 0) {
    summary.mean_ms = ms_sum / static_cast<double>(summary.frames);
    summary.mean_reference_ms = ref_sum / static_cast<double>(summary.frames);
  }
  return summary;
}

}  // namespace

ComparisonSummary compare_detectors(Detector& method, const ReferenceRun& reference,
                                    const FrameSource& frames,
                                    const std::function<void(const FrameComparison&)>& on_frame) {
  CRUMPLE_CHECK(reference.contacts.size() == frames.size() && reference.ms.size() == frames.size(),
                "compare_detectors: the reference run has " + std::to_string(reference.contacts.size()) +
                    " frames, the source " + std::to_string(frames.size()));
  return compare_impl(
      method, frames,
      [&](std::size_t i, const Positions&, const Positions&, double& ms) -> const ContactSet& {
        ms = reference.ms[i];
        return reference.contacts[i];
      },
      on_frame);
}

ComparisonSummary compare_detectors(Detector& method, Detector& reference, const FrameSource& frames,
                                    const std::function<void(const FrameComparison&)>& on_frame) {
  reference.set_topology(frames.mesh().topology_ptr());
  ContactSet ref;
  return compare_impl(
      method, frames,
      [&](std::size_t, const Positions& previous, const Positions& current, double& ms) -> const ContactSet& {
        ms = timed_update(reference, previous, current, ref);
        return ref;
      },
      on_frame);
}

}  // namespace crumple

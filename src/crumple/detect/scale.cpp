#include <crumple/core/error.hpp>
#include <crumple/core/parallel.hpp>
#include <crumple/detect/scale_detail.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <mutex>
#include <string>

namespace crumple::detail {
namespace {

/// Chunks of the passes over the positions: one below this many vertices, so a small mesh
/// pays no dispatch.
constexpr std::size_t kGrain = std::size_t{1} << 16;

}  // namespace

Scalar finite_magnitude(PositionsView x, int threads) {
  Scalar magnitude = 0;
  std::mutex mutex;
  parallel_for_chunks(x.size(), threads, kGrain, [&](std::size_t begin, std::size_t end) {
    constexpr Scalar kInf = std::numeric_limits<Scalar>::infinity();
    Scalar m = 0;
    for (std::size_t v = begin; v < end; ++v) {
      for (int a = 0; a < 3; ++a) {
        const Scalar c = std::abs(x[v][a]);
        m = c < kInf && c > m ? c : m;  // NaN compares false: left out
      }
    }
    const std::lock_guard lock(mutex);
    magnitude = std::max(magnitude, m);
  });
  return magnitude;
}

int detection_exponent(Scalar magnitude) {
  if (!(magnitude > 0)) return 0;
  const int e = std::ilogb(magnitude);  // magnitude in [2^e, 2^(e+1))
  if (e >= -64 && e < 64) return 0;
  // The multiple of 32 nearest -e, so that e + k lies in [-16, 16).
  const int q = (e + 16 >= 0) ? (e + 16) / 32 : -((-(e + 16) + 31) / 32);  // floor((e + 16) / 32)
  return -32 * q;
}

void scale_positions(PositionsView x, int k, Positions& y, int threads, std::string_view what) {
  y.resize(x.size());
  // 2^k itself when it is a double (k >= -1074: subnormal powers are exact), so one product,
  // correctly rounded, gives what std::scalbn gives; k > 1023 only for meshes whose every
  // coordinate is below 2^-1007, scaled by std::scalbn.
  const bool product = k >= -1074 && k <= 1023;
  const Scalar factor = product ? std::scalbn(Scalar(1), k) : 0;
  std::atomic<std::size_t> first_lossy{x.size()};
  parallel_for_chunks(x.size(), threads, kGrain, [&](std::size_t begin, std::size_t end) {
    std::size_t lossy = x.size();
    for (std::size_t v = begin; v < end; ++v) {
      for (int a = 0; a < 3; ++a) {
        const Scalar c = x[v][a];
        const Scalar s = product ? c * factor : std::scalbn(c, k);
        y[v][a] = s;
        // Only a product below the normal range can have lost bits (scaling up never does).
        if (k < 0 && std::abs(s) < std::numeric_limits<Scalar>::min() && c != 0 && std::scalbn(s, -k) != c) {
          lossy = std::min(lossy, v);
        }
      }
    }
    std::size_t seen = first_lossy.load();
    while (lossy < seen && !first_lossy.compare_exchange_weak(seen, lossy)) {
    }
  });
  const std::size_t v = first_lossy.load();
  if (v == x.size()) return;
  int axis = 0;
  while (axis < 2 && std::scalbn(y[v][axis], -k) == x[v][axis]) ++axis;
  char value[32];
  std::snprintf(value, sizeof value, "%.17g", x[v][axis]);
  throw InputError(std::string(what) + " span more than the double range: vertex " + std::to_string(v) + "'s " +
                   "xyz"[axis] + " coordinate " + value +
                   " is too small beside the largest coordinate to be computed with it (the detectors "
                   "compute in coordinates scaled by 2^" + std::to_string(k) +
                   ", where it would lose bits: magnitudes below about 1e-308 of the largest cannot be kept)");
}

Scalar scaled_thickness(Scalar h, int k) {
  const Scalar s = std::min(std::scalbn(h, k), kMaxScaledThickness);
  return h > 0 && s == 0 ? std::numeric_limits<Scalar>::denorm_min() : s;
}

void scale_distances(ContactSet& set, int k) {
  for (VertexFaceContact& c : set.vf) c.distance = std::scalbn(c.distance, k);
  for (EdgeEdgeContact& c : set.ee) c.distance = std::scalbn(c.distance, k);
}

}  // namespace crumple::detail

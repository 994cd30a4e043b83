#pragma once
/// \file
/// Wall-clock milliseconds for the per-phase timings that detectors and apps report.

#include <chrono>

namespace crumple {

/// Milliseconds elapsed on the steady clock since `start`.
inline double ms_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

}  // namespace crumple

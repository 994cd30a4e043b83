#pragma once
/// \file
/// Helpers shared by the geometry tests: a seeded random source that prints its seed, input
/// dumps in JSON (STYLE.md §9: a failing check prints its input so it can become a
/// regression test) and random rotations.

#include <crumple/core/types.hpp>
#include <crumple/geometry/kernel_batch.hpp>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <initializer_list>
#include <numbers>
#include <random>
#include <string>

namespace crumple::geometry::test {

/// std::mt19937_64 with a fixed seed, printed once on construction so that a failure can be
/// replayed.
class Rng {
 public:
  Rng(const char* what, std::uint64_t seed) : gen_(seed) {
    std::printf("[ seed     ] %s: mt19937_64 seed = %llu\n", what,
                static_cast<unsigned long long>(seed));
  }
  Scalar uniform(Scalar lo, Scalar hi) { return std::uniform_real_distribution<Scalar>(lo, hi)(gen_); }
  int integer(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(gen_); }
  std::int64_t integer64(std::int64_t lo, std::int64_t hi) {
    return std::uniform_int_distribution<std::int64_t>(lo, hi)(gen_);
  }
  bool coin() { return integer(0, 1) == 1; }
  Vec3 vec(Scalar lo, Scalar hi) { return Vec3(uniform(lo, hi), uniform(lo, hi), uniform(lo, hi)); }
  /// Uniform on the unit sphere.
  Vec3 unit() {
    std::normal_distribution<Scalar> n(0, 1);
    for (;;) {
      const Vec3 v(n(gen_), n(gen_), n(gen_));
      const Scalar l = v.norm();
      if (l > 1e-6) return v / l;
    }
  }
  /// A unit vector orthogonal to the unit vector `d`.
  Vec3 orthogonal_unit(const Vec3& d) {
    for (;;) {
      const Vec3 v = unit();
      const Vec3 o = v - v.dot(d) * d;
      if (o.norm() > 0.1) return o.normalized();
    }
  }
  /// Uniformly random rotation (from a random unit quaternion).
  Eigen::Matrix3d rotation() {
    std::normal_distribution<Scalar> n(0, 1);
    Eigen::Quaterniond q(n(gen_), n(gen_), n(gen_), n(gen_));
    q.normalize();
    return q.toRotationMatrix();
  }
  /// A point of small integer coordinates (-2 to 2; z = 0 half of the time): inputs full of
  /// exact ties (equal lengths, parameters exactly 0 or 1, coplanar and collinear points).
  Vec3 small_integer_point() {
    return Vec3(integer(-2, 2), integer(-2, 2), integer(-2, 2) * (coin() ? 1 : 0));
  }
  /// A scale 10^k, k uniform in [lo, hi].
  Scalar scale(int lo, int hi) { return std::pow(10.0, integer(lo, hi)); }
  std::mt19937_64& engine() { return gen_; }

 private:
  std::mt19937_64 gen_;
};

/// "[x,y,z]" with 17 significant digits (round-trips exactly).
inline std::string json(const Vec3& v) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "[%.17g,%.17g,%.17g]", v.x(), v.y(), v.z());
  return buf;
}

/// {"kernel":..., "points":[...]} for a failure message.
inline std::string json_case(const char* kernel, std::initializer_list<Vec3> points) {
  std::string s = std::string("{\"kernel\":\"") + kernel + "\",\"points\":[";
  bool first = true;
  for (const Vec3& p : points) {
    if (!first) s += ',';
    s += json(p);
    first = false;
  }
  return s + "]}";
}

/// Fixture of the tests of the kernels' AVX2 lanes (kernel_batch.hpp): skipped, visibly, on a CPU
/// without AVX2, where the detectors call the scalar kernels and the lanes are never used.
class LanesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!has_avx2()) GTEST_SKIP() << "this CPU has no AVX2: the narrow phase runs the scalar kernels";
  }
};

/// The bits of x, for comparisons that must be exact to the last bit (and tell -0 from 0).
inline std::uint64_t bits(Scalar x) {
  std::uint64_t b = 0;
  std::memcpy(&b, &x, sizeof b);
  return b;
}

/// Largest absolute coordinate among the points (the scale L of tolerances).
inline Scalar max_abs_coord(std::initializer_list<Vec3> points) {
  Scalar m = 0;
  for (const Vec3& p : points) m = std::max(m, p.cwiseAbs().maxCoeff());
  return m;
}

/// Unit roundoff of double.
inline constexpr Scalar kEps = 0x1p-53;

}  // namespace crumple::geometry::test

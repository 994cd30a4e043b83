#pragma once
// Groups of test meshes (STYLE.md: fixtures hand out groups so one invariant is checked over
// many meshes), and seeded random deformations.

#include <crumple/mesh/mesh.hpp>
#include <crumple/mesh/shapes.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace crumple::testing {

/// The shared real-mesh folder: the environment variable CRUMPLE_DATA_DIR when set and not
/// empty (so `CRUMPLE_DATA_DIR=... ctest` moves every test program to another copy), else the
/// folder configured at build time (-DCRUMPLE_DATA_DIR, default ../shared/data).
inline std::filesystem::path data_dir() {
  const char* env = std::getenv("CRUMPLE_DATA_DIR");
  return std::filesystem::path(env != nullptr && *env != '\0' ? env : CRUMPLE_DATA_DIR);
}

/// Path of a file in the shared real-mesh folder (`data_dir`).
inline std::filesystem::path data_path(const std::string& relative) { return data_dir() / relative; }

/// `n` separate triangles through one point (their centroid) in seeded random planes, so that
/// every pair intersects (n (n - 1) / 2 triangle contacts, as many as broad-phase candidates);
/// or (`apart`) the same triangles spread on a grid 3 units apart, meeting none. Returns the
/// mesh and its positions.
inline std::pair<TriMesh, Positions> hedgehog(Index n, bool apart) {
  std::mt19937 random(11);
  std::normal_distribution<Scalar> normal;
  std::uniform_real_distribution<Scalar> angle(0, 6.283185307179586);
  Positions x;
  std::vector<Face> faces;
  const auto side = static_cast<Index>(std::ceil(std::sqrt(static_cast<double>(n))));
  for (Index t = 0; t < n; ++t) {
    const Vec3 normal_of_plane = Vec3(normal(random), normal(random), normal(random)).normalized();
    const Vec3 u = normal_of_plane.unitOrthogonal(), v = normal_of_plane.cross(u);
    const Scalar phase = angle(random);
    const Vec3 offset = apart ? Vec3(3.0 * (t % side), 3.0 * (t / side), 0) : Vec3::Zero();
    for (int k = 0; k < 3; ++k) {
      const Scalar a = phase + 2.0943951023931953 * k;
      x.push_back(offset + std::cos(a) * u + std::sin(a) * v);
    }
    faces.push_back({3 * t, 3 * t + 1, 3 * t + 2});
  }
  TriMesh mesh = TriMesh::create(x, faces);
  return {std::move(mesh), std::move(x)};
}

/// Small built-in meshes with different topology: open lattices, a folded lattice, a closed
/// tetrahedron and octahedron, a non-manifold fan, a strip.
inline std::vector<std::pair<std::string, TriMesh>> small_meshes() {
  std::vector<std::pair<std::string, TriMesh>> out;
  out.emplace_back("lattice1x1", shapes::lattice(1, 1));
  out.emplace_back("lattice5x3", shapes::lattice(5, 3));
  out.emplace_back("strip12x1", shapes::lattice(12, 1, 3.0, 0.25));
  out.emplace_back("folded8", shapes::folded_cloth({.n = 8, .gap = 0.05, .wave = 0.01, .thickness = 0.06}));
  out.emplace_back("tetrahedron",
                   TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)},
                                   {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}}));
  out.emplace_back("octahedron",
                   TriMesh::create({Vec3(1, 0, 0), Vec3(-1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0),
                                    Vec3(0, 0, 1), Vec3(0, 0, -1)},
                                   {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4},
                                    {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}}));
  // Three triangles on one edge (non-manifold) plus a separate triangle.
  out.emplace_back("nonmanifold",
                   TriMesh::create({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 1, 0), Vec3(0.5, -1, 0),
                                    Vec3(0.5, 0, 1), Vec3(3, 0, 0), Vec3(4, 0, 0), Vec3(3, 1, 0)},
                                   {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}, {5, 6, 7}}));
  return out;
}

/// Displaces every vertex by a seeded uniform random vector of length up to `amplitude`.
inline Positions jitter(PositionsView x, double amplitude, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  Positions out(x.begin(), x.end());
  for (Vec3& p : out) {
    Vec3 d;
    do {
      d = Vec3(u(rng), u(rng), u(rng));
    } while (d.squaredNorm() > 1);
    p += amplitude * d;
  }
  return out;
}

/// A lattice displaced by a smooth seeded random field (folds of height `amplitude`).
inline Positions smooth_crumple(const TriMesh& lattice, double amplitude, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  const double fx = 1 + 3 * u(rng), fy = 1 + 3 * u(rng), ph = 6.28 * u(rng);
  Positions out = lattice.positions();
  for (Vec3& p : out) {
    const double x = p.x(), y = p.y();
    p.z() = amplitude * std::sin(fx * 6.28 * x + ph) * std::cos(fy * 6.28 * y);
    p.x() = x + 0.5 * amplitude * std::sin(fy * 6.28 * y + ph);
    p.y() = y + 0.5 * amplitude * std::cos(fx * 6.28 * x);
  }
  return out;
}

/// A lattice crumpled by a smooth seeded random displacement field plus noise: many near pairs.
inline Positions crumple_lattice(const TriMesh& lattice, double amplitude, std::uint64_t seed) {
  return jitter(smooth_crumple(lattice, amplitude, seed), amplitude * 0.05, seed + 1);
}

}  // namespace crumple::testing

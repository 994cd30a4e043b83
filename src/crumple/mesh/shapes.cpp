#include <crumple/core/error.hpp>
#include <crumple/mesh/shapes.hpp>

#include <cmath>
#include <numbers>

namespace crumple::shapes {

TriMesh lattice(Index nx, Index ny, Scalar width, Scalar height) {
  CRUMPLE_CHECK(nx >= 1 && ny >= 1, "lattice: nx and ny must be >= 1");
  Positions x;
  x.reserve(static_cast<std::size_t>(nx + 1) * static_cast<std::size_t>(ny + 1));
  for (Index j = 0; j <= ny; ++j) {
    for (Index i = 0; i <= nx; ++i) {
      x.emplace_back(width * i / nx, height * j / ny, 0.0);
    }
  }
  std::vector<Face> faces;
  faces.reserve(2 * static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny));
  const auto id = [nx](Index i, Index j) { return j * (nx + 1) + i; };
  for (Index j = 0; j < ny; ++j) {
    for (Index i = 0; i < nx; ++i) {
      faces.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      faces.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  }
  return TriMesh::create(std::move(x), std::move(faces));
}

TriMesh folded_cloth(const FoldedClothParams& params) {
  CRUMPLE_CHECK(params.n >= 2, "folded_cloth: n must be >= 2");
  CRUMPLE_CHECK(params.gap > 0, "folded_cloth: gap must be > 0");
  TriMesh flat = lattice(params.n, params.n);
  Positions x = flat.positions();
  const Scalar radius = params.gap / 2;
  const Scalar pi = std::numbers::pi;
  const Scalar half_turn = pi * radius;  // arc length of the half-cylinder
  for (Vec3& p : x) {
    const Scalar u = p.x() - 0.5;  // arc length past the fold line
    if (u <= 0) continue;
    if (u <= half_turn) {
      const Scalar angle = u / radius;
      p.x() = 0.5 + radius * std::sin(angle);
      p.z() = radius - radius * std::cos(angle);
    } else {
      const Scalar back = u - half_turn;  // distance travelled back over the lower layer
      p.x() = 0.5 - back;
      p.z() = params.gap + params.wave * std::sin(2 * pi * 3 * back) * std::sin(2 * pi * 2 * p.y()) *
                               std::min<Scalar>(1, back / 0.1);
    }
  }
  flat.set_positions(std::move(x));
  return flat;
}

}  // namespace crumple::shapes

#pragma once
// The same positions in the buffers an engine may hold, for the `VertexView` tests.
#include <crumple/core/vertex_view.hpp>

#include <cstring>
#include <string>
#include <utility>
#include <vector>

namespace crumple::testing {

/// An engine's vertex buffers holding the same positions: packed floats, an interleaved float
/// buffer (position, normal, uv: 8 floats, 32 bytes a vertex), an interleaved double buffer
/// (position + 3 doubles, 48 bytes), and packed doubles starting 4 bytes off alignment.
struct Buffers {
  std::vector<float> packed;
  std::vector<float> interleaved;
  std::vector<double> wide;
  std::vector<unsigned char> misaligned;
  Positions reference;  ///< the float values as doubles: the `double` path's input

  explicit Buffers(PositionsView x) {
    const std::size_t n = x.size();
    packed.resize(3 * n);
    interleaved.assign(8 * n, -7.0f);
    wide.assign(6 * n, 1e300);
    misaligned.resize(3 * n * sizeof(double) + 4);
    reference.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      for (int k = 0; k < 3; ++k) {
        const float f = static_cast<float>(x[i][k]);
        packed[3 * i + static_cast<std::size_t>(k)] = f;
        interleaved[8 * i + static_cast<std::size_t>(k)] = f;
        reference[i][k] = static_cast<double>(f);
        wide[6 * i + static_cast<std::size_t>(k)] = reference[i][k];
      }
    }
    std::memcpy(misaligned.data() + 4, reference.data(), 3 * n * sizeof(double));
  }

  std::vector<std::pair<std::string, VertexView>> views() const {
    const std::size_t n = reference.size();
    return {
        {"packed float", VertexView(packed.data(), n)},
        {"interleaved float", VertexView(interleaved.data(), n, 8 * sizeof(float))},
        {"interleaved double", VertexView(wide.data(), n, 6 * sizeof(double))},
        {"misaligned double",
         VertexView(reinterpret_cast<const double*>(misaligned.data() + 4), n)},  // read by memcpy
        {"native double", VertexView(PositionsView(reference))},
    };
  }
};

}  // namespace crumple::testing

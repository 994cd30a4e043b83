#pragma once
/// \file
/// Positions as a host application (a game engine, NumPy) holds them: `float` or `double`, the
/// three components of a vertex consecutive, vertices packed or `stride` bytes apart (an
/// interleaved vertex buffer: position, normal, uv, ...). The library computes in `double`
/// (`Vec3`, STYLE.md §14): `Detector::update` reads a view of packed, aligned doubles in place and
/// converts any other view once per frame into a buffer of its own (docs/design.md, "Engine
/// integration").
///
/// A view does not own its memory; the buffer must stay valid and unchanged while it is used.

#include <crumple/core/types.hpp>

#include <cstddef>
#include <cstdint>

namespace crumple {

/// The type of a position's components.
enum class ComponentType : std::uint8_t { f32, f64 };

class VertexView {
 public:
  /// No vertices.
  VertexView() = default;
  /// Packed `Vec3`s (read in place by the detectors).
  explicit VertexView(PositionsView positions) noexcept;
  /// `count` vertices whose x, y, z are consecutive `float`s (or `double`s) from `first`,
  /// vertex i at byte offset i * stride; `stride` 0 means packed (3 * sizeof component). Any
  /// address and stride are accepted (components are read without alignment assumptions).
  /// Preconditions (`PreconditionError`): `first` non-null when count > 0; stride 0 or at least
  /// the three components' size.
  VertexView(const float* first, std::size_t count, std::size_t stride = 0);
  VertexView(const double* first, std::size_t count, std::size_t stride = 0);

  std::size_t size() const { return count_; }
  bool empty() const { return count_ == 0; }
  ComponentType type() const { return type_; }
  /// Bytes from one vertex to the next.
  std::size_t stride() const { return stride_; }
  const void* data() const { return data_; }

  /// Whether the view can be read in place as `Vec3`s: packed doubles at an address aligned for
  /// `double` (empty views too).
  bool is_native() const;
  /// The view as `Vec3`s. Precondition: `is_native()`.
  PositionsView native() const;

  /// Vertex i (< size(), unchecked), converted to `double`.
  Vec3 operator[](std::size_t i) const;
  /// Every vertex converted to `double` into `out` (resized to size(); its storage is reused).
  /// Each component is the exact `double` value of the `float` or `double` read.
  void convert(Positions& out) const;

 private:
  const unsigned char* data_ = nullptr;
  std::size_t count_ = 0;
  std::size_t stride_ = sizeof(Vec3);
  ComponentType type_ = ComponentType::f64;
};

/// Throws `InputError` naming the first vertex with a non-finite coordinate (as the
/// `PositionsView` overload in mesh.hpp, without converting the view).
void check_finite(const VertexView& positions);

}  // namespace crumple

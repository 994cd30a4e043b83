#include <crumple/core/error.hpp>
#include <crumple/core/vertex_view.hpp>

#include <cstring>
#include <sstream>
#include <string>

namespace crumple {

namespace {

static_assert(sizeof(Vec3) == 3 * sizeof(double), "Vec3 must be three packed doubles");

/// Component k of the vertex at `p`, read without alignment assumptions.
template <class T>
double component(const unsigned char* p, int k) {
  T value;
  std::memcpy(&value, p + k * sizeof(T), sizeof(T));
  return static_cast<double>(value);
}

template <class T>
Vec3 vertex(const unsigned char* p) {
  return Vec3(component<T>(p, 0), component<T>(p, 1), component<T>(p, 2));
}

template <class T>
void convert_all(const unsigned char* data, std::size_t count, std::size_t stride, Vec3* out) {
  for (std::size_t i = 0; i < count; ++i) out[i] = vertex<T>(data + i * stride);
}

std::size_t checked_stride(const void* first, std::size_t count, std::size_t stride,
                           std::size_t component) {
  CRUMPLE_CHECK(first != nullptr || count == 0, "VertexView: null data for " + std::to_string(count) + " vertices");
  CRUMPLE_CHECK(stride == 0 || stride >= 3 * component,
                "VertexView: stride " + std::to_string(stride) + " bytes is less than a position's " +
                    std::to_string(3 * component));
  return stride == 0 ? 3 * component : stride;
}

}  // namespace

VertexView::VertexView(PositionsView positions) noexcept
    : data_(reinterpret_cast<const unsigned char*>(positions.data())), count_(positions.size()) {}

VertexView::VertexView(const float* first, std::size_t count, std::size_t stride)
    : data_(reinterpret_cast<const unsigned char*>(first)),
      count_(count),
      stride_(checked_stride(first, count, stride, sizeof(float))),
      type_(ComponentType::f32) {}

VertexView::VertexView(const double* first, std::size_t count, std::size_t stride)
    : data_(reinterpret_cast<const unsigned char*>(first)),
      count_(count),
      stride_(checked_stride(first, count, stride, sizeof(double))),
      type_(ComponentType::f64) {}

bool VertexView::is_native() const {
  if (count_ == 0) return true;
  return type_ == ComponentType::f64 && stride_ == sizeof(Vec3) &&
         reinterpret_cast<std::uintptr_t>(data_) % alignof(Vec3) == 0;
}

PositionsView VertexView::native() const {
  CRUMPLE_CHECK(is_native(), "VertexView::native: not packed, aligned doubles");
  if (count_ == 0) return {};
  return PositionsView(reinterpret_cast<const Vec3*>(data_), count_);
}

Vec3 VertexView::operator[](std::size_t i) const {
  const unsigned char* p = data_ + i * stride_;
  return type_ == ComponentType::f32 ? vertex<float>(p) : vertex<double>(p);
}

void VertexView::convert(Positions& out) const {
  out.resize(count_);
  if (type_ == ComponentType::f32) {
    convert_all<float>(data_, count_, stride_, out.data());
  } else {
    convert_all<double>(data_, count_, stride_, out.data());
  }
}

void check_finite(const VertexView& positions) {
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const Vec3 x = positions[i];
    if (!x.allFinite()) {
      std::ostringstream msg;
      msg.precision(17);
      msg << "vertex " << i << " has a non-finite coordinate (" << x.x() << " " << x.y() << " " << x.z() << ")";
      throw InputError(msg.str());
    }
  }
}

}  // namespace crumple

#pragma once
/// \file
/// An 8-bit RGB image and its PNG encoding (stb_image_write from Debian's libstb-dev).

#include <cstdint>
#include <filesystem>
#include <vector>

namespace crumple::render {

/// An 8-bit sRGB colour.
struct Rgb {
  std::uint8_t r = 0, g = 0, b = 0;
  friend bool operator==(const Rgb&, const Rgb&) = default;
};

/// A `width` × `height` RGB image, rows top to bottom, 3 bytes a pixel.
class Picture {
 public:
  Picture() = default;
  /// Filled with `fill`. Throws `InputError` unless 1 <= width, height <= 16384.
  Picture(int width, int height, Rgb fill = {});

  int width() const { return width_; }
  int height() const { return height_; }
  /// Pixel (x, y), x right, y down; both in range (unchecked).
  Rgb at(int x, int y) const {
    const std::size_t i = 3 * (static_cast<std::size_t>(y) * width_ + x);
    return {data_[i], data_[i + 1], data_[i + 2]};
  }
  void set(int x, int y, Rgb c) {
    const std::size_t i = 3 * (static_cast<std::size_t>(y) * width_ + x);
    data_[i] = c.r;
    data_[i + 1] = c.g;
    data_[i + 2] = c.b;
  }
  const std::vector<std::uint8_t>& data() const { return data_; }
  std::vector<std::uint8_t>& data() { return data_; }
  /// Reverses the row order (OpenGL framebuffers are bottom to top).
  void flip_vertically();

 private:
  int width_ = 0, height_ = 0;
  std::vector<std::uint8_t> data_;
};

/// PNG file content of a picture.
std::vector<std::uint8_t> encode_png(const Picture& picture);
/// Writes a PNG atomically (temporary file, then rename); throws `ParseError` naming the file
/// when it cannot be written.
void write_png(const std::filesystem::path& path, const Picture& picture);

/// A picture is "in collision colour" where red clearly dominates: r >= 160, g, b <= 100.
bool is_collision_red(Rgb c);

}  // namespace crumple::render

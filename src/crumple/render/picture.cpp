#include <crumple/render/picture.hpp>

#include <crumple/core/atomic_file.hpp>
#include <crumple/core/error.hpp>

#include <algorithm>
#include <string>

// stb_image_write, compiled here only, with internal linkage (libimgui links libstb too).
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#endif
#include <stb/stb_image_write.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

namespace crumple::render {

Picture::Picture(int width, int height, Rgb fill) : width_(width), height_(height) {
  if (width < 1 || height < 1 || width > 16384 || height > 16384) {
    throw InputError(std::string("picture size must be 1..16384 on each side, got ")
                         .append(std::to_string(width))
                         .append("x")
                         .append(std::to_string(height)));
  }
  data_.resize(3 * static_cast<std::size_t>(width) * height);
  for (std::size_t i = 0; i < data_.size(); i += 3) {
    data_[i] = fill.r;
    data_[i + 1] = fill.g;
    data_[i + 2] = fill.b;
  }
}

void Picture::flip_vertically() {
  const std::size_t row = 3 * static_cast<std::size_t>(width_);
  for (int y = 0; y < height_ / 2; ++y) {
    std::swap_ranges(data_.begin() + static_cast<std::ptrdiff_t>(y * row),
                     data_.begin() + static_cast<std::ptrdiff_t>((y + 1) * row),
                     data_.begin() + static_cast<std::ptrdiff_t>((height_ - 1 - y) * row));
  }
}

namespace {

void append_bytes(void* context, void* data, int size) {
  auto* out = static_cast<std::vector<std::uint8_t>*>(context);
  const auto* bytes = static_cast<const std::uint8_t*>(data);
  out->insert(out->end(), bytes, bytes + size);
}

}  // namespace

std::vector<std::uint8_t> encode_png(const Picture& picture) {
  CRUMPLE_CHECK(picture.width() > 0 && picture.height() > 0, "empty picture");
  std::vector<std::uint8_t> out;
  const int ok = stbi_write_png_to_func(append_bytes, &out, picture.width(), picture.height(), 3,
                                        picture.data().data(), 3 * picture.width());
  if (!ok) throw Error("PNG encoding failed");
  return out;
}

void write_png(const std::filesystem::path& path, const Picture& picture) {
  const std::vector<std::uint8_t> bytes = encode_png(picture);
  write_file_atomically(
      path,
      [&](std::ostream& os) {
        os.write(reinterpret_cast<const char*>(bytes.data()),
                 static_cast<std::streamsize>(bytes.size()));
      },
      true);
}

bool is_collision_red(Rgb c) { return c.r >= 160 && c.g <= 100 && c.b <= 100; }

}  // namespace crumple::render

// Stanford PLY: ascii, binary_little_endian and binary_big_endian.
//
// The file is read into memory in one call and decoded from the buffer. Element counts are
// checked against the file size before anything is allocated: every element has a minimum
// encoded size (its fixed properties and list counts; one token per property in ascii), so a
// header whose counts cannot fit in the bytes that follow it is rejected up front, and every
// allocation stays within a small multiple of the file size.
//
// Units: the header (ply_header.cpp), the ascii and binary bodies (ply_ascii.cpp, ply_binary.cpp),
// sharing the parsed header (ply_detail.hpp); reading and writing here.

#include <crumple/core/atomic_file.hpp>
#include <crumple/io/io_detail.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/io/ply_detail.hpp>

#include <bit>
#include <cstring>
#include <ostream>

namespace crumple::io {

namespace {

void append_header(std::string& out, std::string_view format, std::size_t nv, std::size_t nf) {
  out += "ply\nformat ";
  out += format;
  out += " 1.0\ncomment written by crumple\nelement vertex ";
  detail::append_int(out, static_cast<std::int64_t>(nv));
  out += "\nproperty double x\nproperty double y\nproperty double z\nelement face ";
  detail::append_int(out, static_cast<std::int64_t>(nf));
  out += "\nproperty list uchar int vertex_indices\nend_header\n";
}

template <class U>
void append_raw(std::string& out, U value, bool swap) {
  if (swap) {
    if constexpr (sizeof(U) == 4) value = __builtin_bswap32(value);
    if constexpr (sizeof(U) == 8) value = __builtin_bswap64(value);
  }
  char bytes[sizeof(U)];
  std::memcpy(bytes, &value, sizeof(U));
  out.append(bytes, sizeof(U));
}

}  // namespace

MeshData read_ply(const std::filesystem::path& path) {
  const std::string bytes = detail::read_whole_file(path);
  const detail::PlyHeader header = detail::parse_ply_header(path, bytes);
  if (header.encoding == PlyEncoding::Ascii) return detail::read_ply_ascii_body(path, bytes, header);
  return detail::read_ply_binary_body(path, bytes, header);
}

void write_ply(const std::filesystem::path& path, PositionsView positions,
               std::span<const Face> faces, PlyEncoding encoding) {
  detail::check_mesh_for_writing(positions, faces);
  std::string out;
  if (encoding == PlyEncoding::Ascii) {
    out.reserve(256 + positions.size() * 64 + faces.size() * 24);
    append_header(out, "ascii", positions.size(), faces.size());
    detail::append_position_lines(out, "", positions);
    detail::append_face_lines(out, "3 ", faces, 0);
  } else {
    const bool big = encoding == PlyEncoding::BinaryBigEndian;
    const bool swap = big != (std::endian::native == std::endian::big);
    out.reserve(256 + positions.size() * 24 + faces.size() * 13);
    append_header(out, big ? "binary_big_endian" : "binary_little_endian", positions.size(),
                  faces.size());
    for (const Vec3& p : positions) {
      for (int a = 0; a < 3; ++a) append_raw(out, std::bit_cast<std::uint64_t>(p[a]), swap);
    }
    for (const Face& f : faces) {
      out += static_cast<char>(3);
      for (const Index id : f) append_raw(out, static_cast<std::uint32_t>(id), swap);
    }
  }
  detail::write_string_atomically(path, out, /*binary=*/true);
}

}  // namespace crumple::io

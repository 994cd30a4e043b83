#pragma once
/// \file
/// Internal: the PLY reader's parsed header, shared by its units: ply_header.cpp parses the
/// header, ply_ascii.cpp and ply_binary.cpp decode the body, ply.cpp holds `read_ply` and
/// `write_ply`.

#include <crumple/io/mesh_io.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace crumple::io::detail {

enum class PlyType : std::uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

constexpr std::size_t size_of(PlyType t) {
  switch (t) {
    case PlyType::Int8:
    case PlyType::UInt8: return 1;
    case PlyType::Int16:
    case PlyType::UInt16: return 2;
    case PlyType::Int32:
    case PlyType::UInt32:
    case PlyType::Float32: return 4;
    case PlyType::Float64: return 8;
  }
  return 0;
}

constexpr bool is_integer(PlyType t) { return t != PlyType::Float32 && t != PlyType::Float64; }

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::Float32;  // item type for a list
  bool is_list = false;
  PlyType count_type = PlyType::UInt8;  // lists only
};

enum class PlyRole : std::uint8_t { Skip, Vertex, Face };

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
  std::int64_t header_line = 0;
  PlyRole role = PlyRole::Skip;
  // Vertex: property index of x, y, z. Face: property index of the index list (in xyz[0]).
  std::array<int, 3> xyz{-1, -1, -1};
  // Smallest possible encoded size of one element in binary (every list empty). Only used to
  // reject impossible counts before allocating; a short face list gets its own, clearer error.
  std::uint64_t min_binary_size = 0;
  // Smallest number of ascii tokens of one element (every list empty).
  std::uint64_t min_tokens = 0;
};

struct PlyHeader {
  PlyEncoding encoding = PlyEncoding::Ascii;
  std::vector<PlyElement> elements;
  std::size_t body_offset = 0;      // first byte after the end_header line
  std::int64_t body_first_line = 0;  // line number of that byte
  int vertex_element = -1;
};

/// The header of the PLY file `bytes` (read from `path`): its elements, their properties and
/// roles, and where the body starts. Throws `ParseError` naming the file and the line.
PlyHeader parse_ply_header(const std::filesystem::path& path, std::string_view bytes);

/// The vertices and faces of an ascii body described by `header`. Throws `ParseError` naming the
/// file and the line.
MeshData read_ply_ascii_body(const std::filesystem::path& path, std::string_view bytes, const PlyHeader& header);

/// The vertices and faces of a binary body (either byte order) described by `header`. Throws
/// `ParseError` naming the file and the byte offset.
MeshData read_ply_binary_body(const std::filesystem::path& path, std::string_view bytes, const PlyHeader& header);

}  // namespace crumple::io::detail

// The body of a binary PLY file (either byte order), decoded from the buffer; counts are checked
// against the bytes left before anything is allocated (ply_detail.hpp).

#include <crumple/io/io_detail.hpp>
#include <crumple/io/ply_detail.hpp>

#include <bit>
#include <cstring>
#include <limits>
#include <string>

namespace crumple::io::detail {

namespace {

template <class U>
U load_unsigned(const unsigned char* p, bool swap) {
  U u;
  std::memcpy(&u, p, sizeof u);
  if (swap) {
    if constexpr (sizeof(U) == 2) u = __builtin_bswap16(u);
    if constexpr (sizeof(U) == 4) u = __builtin_bswap32(u);
    if constexpr (sizeof(U) == 8) u = __builtin_bswap64(u);
  }
  return u;
}

double decode_real(const unsigned char* p, PlyType t, bool swap) {
  switch (t) {
    case PlyType::Int8: return static_cast<std::int8_t>(p[0]);
    case PlyType::UInt8: return p[0];
    case PlyType::Int16: return static_cast<std::int16_t>(load_unsigned<std::uint16_t>(p, swap));
    case PlyType::UInt16: return load_unsigned<std::uint16_t>(p, swap);
    case PlyType::Int32: return static_cast<std::int32_t>(load_unsigned<std::uint32_t>(p, swap));
    case PlyType::UInt32: return load_unsigned<std::uint32_t>(p, swap);
    case PlyType::Float32: return std::bit_cast<float>(load_unsigned<std::uint32_t>(p, swap));
    case PlyType::Float64: return std::bit_cast<double>(load_unsigned<std::uint64_t>(p, swap));
  }
  return 0;
}

// Integer types only (0 for the float types). Every PLY integer type has at most 32 bits, so
// its value is exact in the double of `decode_real`.
std::int64_t decode_int(const unsigned char* p, PlyType t, bool swap) {
  if (t == PlyType::Float32 || t == PlyType::Float64) return 0;
  return static_cast<std::int64_t>(decode_real(p, t, swap));
}

class BinaryBody {
 public:
  BinaryBody(const std::filesystem::path& path, std::string_view bytes, const PlyHeader& header)
      : path_(path),
        data_(reinterpret_cast<const unsigned char*>(bytes.data())),
        size_(bytes.size()),
        pos_(header.body_offset),
        header_(header),
        swap_((header.encoding == PlyEncoding::BinaryBigEndian) !=
              (std::endian::native == std::endian::big)) {}

  MeshData read() {
    check_sizes();
    MeshData mesh;
    for (const PlyElement& e : header_.elements) {
      switch (e.role) {
        case PlyRole::Vertex: read_vertices(e, mesh.positions); break;
        case PlyRole::Face: read_faces(e, mesh.faces); break;
        case PlyRole::Skip: skip_element(e); break;
      }
    }
    if (pos_ != size_) {
      fail_at_byte(path_, static_cast<std::int64_t>(pos_),
                   std::to_string(size_ - pos_) +
                       " unexpected bytes after the last element (do the header counts match the data?)");
    }
    return mesh;
  }

 private:
  // Rejects counts that cannot fit in the body, before any allocation.
  void check_sizes() const {
    const std::uint64_t body = size_ - pos_;
    std::uint64_t needed = 0;
    for (const PlyElement& e : header_.elements) {
      if (e.min_binary_size == 0) continue;
      const std::uint64_t max_count = (body - needed) / e.min_binary_size;
      if (e.count > max_count) {
        fail_at_line(path_, e.header_line,
                     "the header declares " + std::to_string(e.count) + " " + quote(e.name) +
                         " elements of at least " + std::to_string(e.min_binary_size) +
                         (e.min_binary_size == 1 ? " byte" : " bytes") +
                         " each, which cannot fit in the " + std::to_string(body) +
                         " bytes after the header (file truncated or header corrupt)");
      }
      needed += e.count * e.min_binary_size;
    }
  }

  [[noreturn]] void fail_truncated(std::size_t needed, const PlyElement& e, std::uint64_t i,
                                   const std::string& what) const {
    fail_at_byte(path_, static_cast<std::int64_t>(pos_),
                 "unexpected end of file: expected " + std::to_string(needed) + " bytes for " +
                     what + " of " + quote(e.name) + " " + std::to_string(i) + " (of " +
                     std::to_string(e.count) + "), but only " + std::to_string(size_ - pos_) +
                     " remain");
  }

  void require(std::size_t needed, const PlyElement& e, std::uint64_t i,
               const std::string_view property) const {
    if (size_ - pos_ < needed) fail_truncated(needed, e, i, "property " + quote(property));
  }

  // Stride of an element without lists, or 0 when it has a list.
  static std::size_t fixed_stride(const PlyElement& e) {
    std::size_t stride = 0;
    for (const PlyProperty& p : e.properties) {
      if (p.is_list) return 0;
      stride += size_of(p.type);
    }
    return stride;
  }

  // Reads a list count at pos_ and advances; checks that the items fit.
  std::size_t read_list_count(const PlyElement& e, std::uint64_t i, const PlyProperty& p) {
    require(size_of(p.count_type), e, i, p.name);
    const std::int64_t n = decode_int(data_ + pos_, p.count_type, swap_);
    if (n < 0) {
      fail_at_byte(path_, static_cast<std::int64_t>(pos_),
                   "negative list length " + std::to_string(n) + " in property " + quote(p.name) +
                       " of " + quote(e.name) + " " + std::to_string(i));
    }
    pos_ += size_of(p.count_type);
    const std::uint64_t bytes = static_cast<std::uint64_t>(n) * size_of(p.type);
    if (size_ - pos_ < bytes) {
      fail_truncated(static_cast<std::size_t>(bytes), e, i,
                     std::to_string(n) + " items of list " + quote(p.name));
    }
    return static_cast<std::size_t>(n);
  }

  void skip_element(const PlyElement& e) {
    const std::size_t stride = fixed_stride(e);
    if (stride != 0 || e.properties.empty()) {
      const std::uint64_t bytes = e.count * stride;  // fits: checked by check_sizes
      if (size_ - pos_ < bytes) {
        const std::uint64_t i = (size_ - pos_) / stride;
        pos_ += i * stride;
        fail_truncated(stride, e, i, "all properties");
      }
      pos_ += bytes;
      return;
    }
    for (std::uint64_t i = 0; i < e.count; ++i) skip_properties(e, i, 0, e.properties.size());
  }

  // Skips properties [begin, end) of element i.
  void skip_properties(const PlyElement& e, std::uint64_t i, std::size_t begin, std::size_t end) {
    for (std::size_t p = begin; p < end; ++p) {
      const PlyProperty& prop = e.properties[p];
      if (prop.is_list) {
        pos_ += read_list_count(e, i, prop) * size_of(prop.type);
      } else {
        require(size_of(prop.type), e, i, prop.name);
        pos_ += size_of(prop.type);
      }
    }
  }

  void read_vertices(const PlyElement& e, Positions& positions) {
    const std::size_t stride = fixed_stride(e);
    positions.resize(e.count);  // checked against the file size by check_sizes
    if (stride != 0) {
      std::array<std::size_t, 3> offset{};
      std::array<PlyType, 3> type{};
      for (int a = 0; a < 3; ++a) {
        const auto p = static_cast<std::size_t>(e.xyz[a]);
        for (std::size_t q = 0; q < p; ++q) offset[a] += size_of(e.properties[q].type);
        type[a] = e.properties[p].type;
      }
      const std::uint64_t available = (size_ - pos_) / stride;
      for (std::uint64_t i = 0; i < e.count; ++i) {
        if (i >= available) fail_truncated(stride, e, i, "all properties");
        const unsigned char* row = data_ + pos_;
        Vec3& x = positions[i];
        for (int a = 0; a < 3; ++a) x[a] = decode_real(row + offset[a], type[a], swap_);
        if (!x.allFinite()) fail_non_finite(i);
        pos_ += stride;
      }
      return;
    }
    // Vertices with a list property (rare): property by property.
    for (std::uint64_t i = 0; i < e.count; ++i) {
      const std::size_t start = pos_;
      for (std::size_t p = 0; p < e.properties.size(); ++p) {
        const PlyProperty& prop = e.properties[p];
        if (prop.is_list) {
          pos_ += read_list_count(e, i, prop) * size_of(prop.type);
          continue;
        }
        require(size_of(prop.type), e, i, prop.name);
        for (int a = 0; a < 3; ++a) {
          if (static_cast<int>(p) == e.xyz[a]) positions[i][a] = decode_real(data_ + pos_, prop.type, swap_);
        }
        pos_ += size_of(prop.type);
      }
      if (!positions[i].allFinite()) {
        pos_ = start;
        fail_non_finite(i);
      }
    }
  }

  [[noreturn]] void fail_non_finite(std::uint64_t i) const {
    fail_at_byte(path_, static_cast<std::int64_t>(pos_),
                 "vertex " + std::to_string(i) + " has a non-finite coordinate");
  }

  void read_faces(const PlyElement& e, std::vector<Face>& faces) {
    const std::int64_t nv =
        static_cast<std::int64_t>(header_.elements[static_cast<std::size_t>(header_.vertex_element)].count);
    const auto list_index = static_cast<std::size_t>(e.xyz[0]);
    const PlyProperty& list = e.properties[list_index];
    const std::size_t item = size_of(list.type);
    // Reserve no more triangles than the remaining bytes can hold, whatever the header says.
    const std::uint64_t fit = (size_ - pos_) / (size_of(list.count_type) + 3 * item);
    faces.reserve(faces.size() + static_cast<std::size_t>(std::min<std::uint64_t>(e.count, fit)));
    for (std::uint64_t i = 0; i < e.count; ++i) {
      skip_properties(e, i, 0, list_index);
      const std::size_t count_at = pos_;
      const std::size_t n = read_list_count(e, i, list);
      if (n < 3) {
        fail_at_byte(path_, static_cast<std::int64_t>(count_at),
                     "face " + std::to_string(i) + " has " + std::to_string(n) +
                         " vertices (at least 3 needed)");
      }
      Index first = 0;
      Index previous = 0;
      for (std::size_t k = 0; k < n; ++k) {
        const std::int64_t id = decode_int(data_ + pos_, list.type, swap_);
        if (id < 0 || id >= nv) {
          fail_at_byte(path_, static_cast<std::int64_t>(pos_),
                       "face " + std::to_string(i) + " has vertex index " + std::to_string(id) +
                           " outside [0, " + std::to_string(nv) + ")");
        }
        pos_ += item;
        const auto v = static_cast<Index>(id);
        if (k == 0) {
          first = v;
        } else if (k >= 2) {
          const Face t{first, previous, v};
          if (const auto problem = detail::repeated_vertex(t, 0)) {
            fail_at_byte(path_, static_cast<std::int64_t>(count_at), "face " + std::to_string(i) + ": " + *problem);
          }
          faces.push_back(t);
        }
        previous = v;
      }
      if (faces.size() > static_cast<std::size_t>(std::numeric_limits<Index>::max())) {
        fail_at_byte(path_, static_cast<std::int64_t>(pos_), "too many triangles (at most 2^31-1)");
      }
      skip_properties(e, i, list_index + 1, e.properties.size());
    }
  }

  const std::filesystem::path& path_;
  const unsigned char* data_;
  std::size_t size_;
  std::size_t pos_;
  const PlyHeader& header_;
  bool swap_;
};

}  // namespace

MeshData read_ply_binary_body(const std::filesystem::path& path, std::string_view bytes, const PlyHeader& header) {
  return BinaryBody(path, bytes, header).read();
}

}  // namespace crumple::io::detail

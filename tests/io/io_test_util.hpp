#pragma once
// Helpers shared by the crumple::io tests: a temporary folder per test, byte-exact file writing,
// ParseError expectations, and small meshes with awkward coordinates.

#include <crumple/core/error.hpp>
#include <crumple/core/types.hpp>
#include <crumple/io/mesh_io.hpp>

#include <support/temp_dir.hpp>

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <random>
#include <string>

namespace crumple::io::test {

namespace fs = std::filesystem;

using crumple::testing::TempDir;

inline void write_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << "cannot write " << path;
}

inline std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// Where a ParseError is expected to point.
struct At {
  std::optional<std::int64_t> line;
  std::optional<std::int64_t> byte;
  static At Line(std::int64_t l) { return {l, std::nullopt}; }
  static At Byte(std::int64_t b) { return {std::nullopt, b}; }
  static At Nowhere() { return {}; }
};

/// Runs `read`, expects a ParseError naming `file`, at `at`, whose message contains `needle`.
/// Returns the message (what()) for further checks.
inline std::string expect_parse_error(const std::function<void()>& read, const fs::path& file,
                                      At at, const std::string& needle) {
  try {
    read();
  } catch (const ParseError& e) {
    EXPECT_EQ(e.file(), file.string()) << e.what();
    EXPECT_EQ(e.line(), at.line) << e.what();
    EXPECT_EQ(e.byte_offset(), at.byte) << e.what();
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos)
        << "message lacks \"" << needle << "\": " << e.what();
    EXPECT_EQ(std::string(e.what()).rfind(file.string(), 0), 0u) << e.what();
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected ParseError, got another exception: " << e.what();
    return {};
  }
  ADD_FAILURE() << "expected ParseError for " << file << " (\"" << needle << "\"), got none";
  return {};
}

/// Bitwise equality of positions (distinguishes -0 from 0, keeps every bit).
inline ::testing::AssertionResult same_bits(const Positions& a, const Positions& b) {
  if (a.size() != b.size()) {
    return ::testing::AssertionFailure() << "sizes differ: " << a.size() << " vs " << b.size();
  }
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      if (std::bit_cast<std::uint64_t>(a[i][k]) != std::bit_cast<std::uint64_t>(b[i][k])) {
        return ::testing::AssertionFailure()
               << "vertex " << i << " coordinate " << k << ": " << a[i][k] << " vs " << b[i][k];
      }
    }
  }
  return ::testing::AssertionSuccess();
}

/// A small closed-ish mesh (a strip of quads split in two) with coordinates chosen to stress
/// exact round trips: random doubles of every magnitude, -0, subnormals, 0.1, 1/3, huge values.
struct TestMesh {
  Positions positions;
  std::vector<Face> faces;
};

inline TestMesh awkward_mesh(std::size_t columns = 8, std::uint64_t seed = 12345) {
  TestMesh m;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_int_distribution<int> exponent(-300, 300);
  const double specials[] = {-0.0, 0.1, 1.0 / 3.0, 5e-324, -2.2250738585072014e-308,
                             1.7976931348623157e308, 123456789.123456789, -1e-5};
  for (std::size_t i = 0; i < 2 * (columns + 1); ++i) {
    Vec3 p;
    for (int k = 0; k < 3; ++k) {
      const std::size_t j = 3 * i + static_cast<std::size_t>(k);
      p[k] = j < std::size(specials) ? specials[j] : std::ldexp(unit(rng), exponent(rng));
    }
    m.positions.push_back(p);
  }
  for (std::size_t c = 0; c < columns; ++c) {
    const auto a = static_cast<Index>(2 * c);
    m.faces.push_back({a, static_cast<Index>(a + 1), static_cast<Index>(a + 2)});
    m.faces.push_back({static_cast<Index>(a + 2), static_cast<Index>(a + 1), static_cast<Index>(a + 3)});
  }
  return m;
}

/// Cut points for truncation tests of a file of `size` bytes: every byte of the first and last
/// 64 bytes, and every `stride`-th byte between them (stride 1: every byte).
inline std::vector<std::size_t> cut_points(std::size_t size, std::size_t stride) {
  std::vector<std::size_t> cuts;
  for (std::size_t cut = 0; cut < size; ++cut) {
    if (cut < 64 || cut + 64 >= size || cut % stride == 0) cuts.push_back(cut);
  }
  return cuts;
}

/// True when every face id is in range and every coordinate finite (what a reader that did not
/// throw must guarantee).
inline bool consistent(const MeshData& m) {
  for (const Vec3& p : m.positions) {
    if (!p.allFinite()) return false;
  }
  for (const Face& f : m.faces) {
    for (const Index id : f) {
      if (id < 0 || static_cast<std::size_t>(id) >= m.positions.size()) return false;
    }
  }
  return true;
}

}  // namespace crumple::io::test

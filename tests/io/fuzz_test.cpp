// Garbage in, ParseError out: random bytes and seeded mutations of valid files of every format
// must give a ParseError naming the file (or, where the mutation left a valid file, a consistent
// mesh) — never a crash, hang, other exception or out-of-range id. Seeds are fixed and printed.

#include "io_test_util.hpp"

#include <crumple/io/x3d.hpp>

namespace crumple::io::test {
namespace {

struct Reader {
  const char* extension;
  std::function<void(const fs::path&, const TestMesh&)> write;
  std::function<MeshData(const fs::path&)> read;
};

std::vector<Reader> readers() {
  return {
      {".obj", [](const fs::path& p, const TestMesh& m) { write_obj(p, m.positions, m.faces); }, read_obj},
      {".off", [](const fs::path& p, const TestMesh& m) { write_off(p, m.positions, m.faces); }, read_off},
      {".x3d", [](const fs::path& p, const TestMesh& m) { write_x3d(p, m.positions, m.faces); }, read_x3d},
      {".ply", [](const fs::path& p, const TestMesh& m) { write_ply(p, m.positions, m.faces, PlyEncoding::Ascii); },
       read_ply},
      {".ply", [](const fs::path& p, const TestMesh& m) { write_ply(p, m.positions, m.faces, PlyEncoding::BinaryLittleEndian); },
       read_ply},
      {".ply", [](const fs::path& p, const TestMesh& m) { write_ply(p, m.positions, m.faces, PlyEncoding::BinaryBigEndian); },
       read_ply},
      {".x3d",
       [](const fs::path& p, const TestMesh& m) {
         MassSpringData d;
         d.positions = m.positions;
         d.masses.assign(m.positions.size(), 1.0);
         d.velocities.assign(m.positions.size(), Vec3::Zero());
         d.springs = {{0, 1}, {1, 2}};
         d.stiffness = {1, 2};
         d.damping_ratio = {0.1, 0.2};
         d.rest_length = {1, 1};
         d.faces = m.faces;
         write_mass_spring(p, d);
       },
       [](const fs::path& p) {
         MassSpringData d = read_mass_spring(p);
         return MeshData{d.positions, d.faces};
       }},
  };
}

// Reads and checks the outcome; returns true when the reader threw ParseError.
bool read_safely(const Reader& reader, const fs::path& file) {
  try {
    const MeshData m = reader.read(file);
    EXPECT_TRUE(consistent(m)) << file;
    return false;
  } catch (const ParseError& e) {
    EXPECT_EQ(e.file(), file.string());
    EXPECT_TRUE(e.line() || e.byte_offset()) << "no location: " << e.what();
    return true;
  }
}

TEST(Fuzz, RandomBytesAreRejected) {
  TempDir dir;
  const std::uint64_t seed = 20240601;
  std::cout << "[ info ] seed " << seed << "\n";
  std::mt19937_64 rng(seed);
  for (const Reader& reader : readers()) {
    const fs::path file = dir / (std::string("garbage") + reader.extension);
    for (int trial = 0; trial < 40; ++trial) {
      std::string bytes(static_cast<std::size_t>(rng() % 512 + 1), '\0');
      for (char& c : bytes) c = static_cast<char>(rng() & 0xff);
      write_bytes(file, bytes);
      SCOPED_TRACE(std::string(reader.extension) + " trial " + std::to_string(trial));
      EXPECT_TRUE(read_safely(reader, file)) << "random bytes were accepted";
    }
  }
}

TEST(Fuzz, MutatedValidFiles) {
  TempDir dir;
  const std::uint64_t seed = 7;
  std::cout << "[ info ] seed " << seed << "\n";
  std::mt19937_64 rng(seed);
  const TestMesh mesh = awkward_mesh(3);
  const char interesting[] = {'\0', '\n', '\r', ' ', '-', '/', '#', '<', '>', '"', '\'', ',', '9',
                              '0', '.', 'e', '\x7f', '\xff', '\x80', 'a'};
  for (const Reader& reader : readers()) {
    const fs::path file = dir / (std::string("valid") + reader.extension);
    reader.write(file, mesh);
    const std::string valid = read_bytes(file);
    std::size_t rejected = 0;
    constexpr int trials = 200;
    for (int trial = 0; trial < trials; ++trial) {
      std::string bytes = valid;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits; ++e) {
        const std::size_t at = rng() % bytes.size();
        switch (rng() % 4) {
          case 0: bytes[at] = static_cast<char>(rng() & 0xff); break;
          case 1: bytes[at] = interesting[rng() % sizeof interesting]; break;
          case 2: bytes.erase(at, 1 + rng() % 8); break;
          case 3: bytes.insert(at, 1, interesting[rng() % sizeof interesting]); break;
        }
        if (bytes.empty()) bytes.push_back('x');
      }
      write_bytes(file, bytes);
      SCOPED_TRACE(std::string(reader.extension) + " trial " + std::to_string(trial));
      rejected += read_safely(reader, file) ? 1 : 0;
    }
    // Most mutations must be caught (a flipped digit in a coordinate stays a valid file).
    EXPECT_GT(rejected, static_cast<std::size_t>(trials / 5)) << reader.extension;
  }
}

}  // namespace
}  // namespace crumple::io::test

// Loading cost of a mesh file: read + validation + topology (`io::read_mesh`) and the edge
// statistics `crumple info` prints, with the wall time and the process's peak resident memory.
// Two steps, so that making the file does not count in the peak:
//   ./build/release/bench/load_bench make fan 60000 /tmp/fan.obj        # triangles around vertex 0
//   ./build/release/bench/load_bench make copies 20000 /tmp/copies.obj  # one face, repeated
//   ./build/release/bench/load_bench make grid 1000 /tmp/grid.ply       # 2 x 1000^2 triangles
//   ./build/release/bench/load_bench load /tmp/fan.obj                  # one JSON line
// (issue 45 goals: the fan and the copies under 0.5 s and 200 MB each.)
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/mesh.hpp>
#include <crumple/mesh/shapes.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include <sys/resource.h>

namespace {

using namespace crumple;

double peak_rss_mb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // kB on Linux
}

int make(const std::string& kind, long n, const std::string& path) {
  Positions positions;
  std::vector<Face> faces;
  if (kind == "fan") {  // n triangles around vertex 0, rim on the unit circle
    positions.push_back(Vec3::Zero());
    for (long i = 0; i <= n; ++i) {
      const double a = 6.283185307179586 * static_cast<double>(i) / static_cast<double>(n + 1);
      positions.emplace_back(std::cos(a), std::sin(a), 0.0);
      if (i > 0) faces.push_back({0, static_cast<Index>(i), static_cast<Index>(i + 1)});
    }
  } else if (kind == "copies") {
    positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
    faces.assign(static_cast<std::size_t>(n), Face{0, 1, 2});
  } else if (kind == "grid") {
    const TriMesh m = shapes::lattice(static_cast<Index>(n), static_cast<Index>(n));
    positions = m.positions();
    faces.assign(m.topology().faces().begin(), m.topology().faces().end());
  } else {
    std::fprintf(stderr, "unknown scene '%s' (fan, copies or grid)\n", kind.c_str());
    return 2;
  }
  io::write_mesh(path, positions, faces);
  return 0;
}

int load(const std::string& path) {
  const auto start = std::chrono::steady_clock::now();
  const TriMesh mesh = io::read_mesh(path);
  const EdgeLengthStats lengths = edge_length_stats(mesh.topology(), mesh.positions());
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "{\"file\": \"%s\", \"faces\": %d, \"vertices\": %d, \"seconds\": %.4f, \"peak_rss_mb\": %.1f, "
      "\"topology_mb\": %.1f, \"mean_edge\": %.6g}\n",
      path.c_str(), mesh.num_faces(), mesh.num_vertices(), seconds, peak_rss_mb(),
      static_cast<double>(mesh.topology().memory_bytes()) / (1024.0 * 1024.0), lengths.mean);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const std::string verb = argc > 1 ? argv[1] : "";
    if (verb == "make" && argc == 5) return make(argv[2], std::strtol(argv[3], nullptr, 10), argv[4]);
    if (verb == "load" && argc == 3) return load(argv[2]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "load_bench: %s\n", e.what());
    return 1;
  }
  std::fprintf(stderr, "usage: load_bench make fan|copies|grid N FILE | load_bench load FILE\n");
  return 2;
}

// Peak memory of an exact detection against the size of its output (issue 45, item 7): per
// case, the contacts, their records' bytes (count x sizeof record), and two peaks above what was
// held before the detector was made: the bytes of live allocations (this program's counting
// operator new) and the process's resident memory (VmHWM, reset through /proc/self/clear_refs).
// The detector is made afresh, detects the first frame, then the second with the motion (the
// first frame's contacts gone by then); the records are the larger frame's.
//   build/release/bench/exact_memory_bench --thickness 0.15 FRAME0 FRAME1
//   build/release/bench/exact_memory_bench --lattice 200 --spacings 3   # a crumpled lattice
//   build/release/bench/exact_memory_bench --hedgehog 4000 --kinds tt   # every face pair meets
//   (--hedgehog N --apart: the same triangles moved apart, the O(faces) part)
// One JSON line per case.
#include <crumple/detect/detector.hpp>
#include <crumple/detect/method.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/mesh.hpp>
#include <crumple/mesh/shapes.hpp>

#include "support/counting_new.hpp"
#include "support/meshes.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <fstream>
#include <string>

namespace {

using namespace crumple;
using testing::counting::g_live;
using testing::counting::g_peak;

/// A field of /proc/self/status in kB (VmRSS, VmHWM).
long long status_kb(const char* field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(field, 0) == 0) return std::atoll(line.c_str() + std::strlen(field) + 1);
  }
  return -1;
}

double record_bytes(const ContactSet& c) {
  return static_cast<double>(c.vf.size() * sizeof(VertexFaceContact) + c.ee.size() * sizeof(EdgeEdgeContact) +
                             c.tt.size() * sizeof(TriangleTriangleContact));
}

void run(const std::string& name, const TriMesh& mesh, const Positions& x0, const Positions& x1, Scalar h,
         const std::string& method, const std::string& kinds, int threads) {
  {
    std::ofstream reset("/proc/self/clear_refs");
    reset << "5";  // VmHWM back to VmRSS
  }
  const long long rss_before = status_kb("VmRSS:");
  const long long before = g_live.load();
  g_peak.store(before);
  DetectorOptions options;
  options.thickness = h;
  options.kinds = ContactKinds::parse(kinds);
  options.threads = threads;
  auto detector = make_detector(MethodSpec::parse(method), options);
  detector->set_topology(mesh.topology_ptr());
  double records = 0;
  std::size_t contacts = 0;
  {
    ContactSet first;
    detector->update(x0, first);
    records = record_bytes(first);
    contacts = first.size();
  }
  ContactSet out;
  const auto start = std::chrono::steady_clock::now();
  detector->update(x0, x1, out);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (record_bytes(out) > records) {
    records = record_bytes(out);
    contacts = out.size();
  }
  const double peak = static_cast<double>(g_peak.load() - before);
  const double hwm = static_cast<double>(status_kb("VmHWM:") - rss_before) * 1024.0;
  std::printf(
      "{\"case\": \"%s\", \"method\": \"%s\", \"kinds\": \"%s\", \"threads\": %d, \"thickness\": %.6g, \"faces\": %d, "
      "\"contacts\": %zu, \"records_mb\": %.2f, \"peak_alloc_mb\": %.2f, \"peak_alloc_ratio\": %.3f, "
      "\"peak_rss_mb\": %.2f, \"peak_rss_ratio\": %.3f, \"second_frame_ms\": %.1f}\n",
      name.c_str(), method.c_str(), kinds.c_str(), threads, h, mesh.num_faces(), contacts, records / 1e6, peak / 1e6,
      peak / records, hwm / 1e6, hwm / records, ms);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  try {
    std::string method = "kdop", kinds = "vf,ee";
    int threads = 2;
    double thickness = 0, spacings = 3;
    long lattice = 0, hedgehog = 0;
    bool apart = false;
    std::vector<std::string> frames;
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      const auto value = [&]() -> std::string {
        if (i + 1 >= argc) throw std::runtime_error(a + " needs a value");
        return argv[++i];
      };
      if (a == "--method") method = value();
      else if (a == "--kinds") kinds = value();
      else if (a == "--threads") threads = std::stoi(value());
      else if (a == "--thickness") thickness = std::stod(value());
      else if (a == "--lattice") lattice = std::stol(value());
      else if (a == "--spacings") spacings = std::stod(value());
      else if (a == "--hedgehog") hedgehog = std::stol(value());
      else if (a == "--apart") apart = true;
      else frames.push_back(a);
    }
    if (lattice > 0) {
      const TriMesh mesh = shapes::lattice(static_cast<Index>(lattice), static_cast<Index>(lattice));
      const Positions x0 = testing::smooth_crumple(mesh, 0.15, 7);
      Positions x1 = x0;
      for (Vec3& p : x1) p *= 0.995;
      run("lattice-" + std::to_string(lattice), mesh, x0, x1, spacings / static_cast<double>(lattice), method, kinds,
          threads);
      return 0;
    }
    if (hedgehog > 0) {
      const auto [mesh, x0] = testing::hedgehog(static_cast<Index>(hedgehog), apart);
      Positions x1 = x0;
      for (Vec3& p : x1) p *= 0.995;
      run(std::string(apart ? "hedgehog-apart-" : "hedgehog-") + std::to_string(hedgehog), mesh, x0, x1,
          thickness > 0 ? thickness : 1e-3, method, kinds, threads);
      return 0;
    }
    if (frames.size() != 2 || !(thickness > 0)) {
      std::fprintf(stderr, "usage: exact_memory_bench --thickness H FRAME0 FRAME1 | --lattice N [--spacings K] |\n"
                           "       --hedgehog N [--apart]\n"
                           "       [--method M] [--kinds vf,ee] [--threads T]\n");
      return 2;
    }
    const TriMesh m0 = io::read_mesh(frames[0]);
    const TriMesh m1 = io::read_mesh(frames[1]);
    run(frames[1], m0, m0.positions(), m1.positions(), thickness, method, kinds, threads);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "exact_memory_bench: %s\n", e.what());
    return 1;
  }
}

// Uses the installed library: builds a folded cloth, detects contacts with the reference method.
#include <crumple/detect/detector.hpp>
#include <crumple/mesh/shapes.hpp>
#ifdef CONSUMER_HAS_IO
#include <crumple/io/mesh_io.hpp>
#endif

#include <cstdio>

int main() {
  const crumple::TriMesh mesh = crumple::shapes::folded_cloth({.n = 8, .gap = 0.05, .wave = 0.0, .thickness = 0.06});
  auto detector = crumple::make_detector(crumple::MethodSpec::parse("naive"), {.thickness = 0.06});
  detector->set_topology(mesh.topology_ptr());
  crumple::ContactSet contacts;
  detector->update(mesh.positions(), contacts);
  std::printf("consumer: %zu vf, %zu ee\n", contacts.vf.size(), contacts.ee.size());
#ifdef CONSUMER_HAS_IO
  std::printf("consumer: io available (%d)\n", static_cast<int>(crumple::io::format_from_path("x.ply")));
#endif
  return contacts.vf.empty() || contacts.ee.empty() ? 1 : 0;
}

// Peak memory of an exact detection against its output (issue 45, item 7): the records are
// held once, beside a few bytes a contact and O(faces), never a second copy. Counted by a
// counting allocator (this program's operator new and delete), not by timing or RSS.

#include <crumple/detect/detector.hpp>
#include <crumple/detect/exact/narrow_frame.hpp>
#include <crumple/detect/method.hpp>
#include <crumple/mesh/shapes.hpp>

#include <gtest/gtest.h>
#include "support/counting_new.hpp"
#include "support/meshes.hpp"

#include <algorithm>

namespace crumple {
namespace {

using testing::counting::g_live;
using testing::counting::g_peak;

struct Measured {
  double records = 0;  // bytes of the larger output's records: count x sizeof(record)
  double extra = 0;    // peak of live bytes, above those live before the detector was made
};

double record_bytes(const ContactSet& c) {
  return static_cast<double>(c.vf.size() * sizeof(VertexFaceContact) + c.ee.size() * sizeof(EdgeEdgeContact) +
                             c.tt.size() * sizeof(TriangleTriangleContact));
}

// A detector made afresh: its first frame (x0), then the next one (x0 -> x1) into a new set
// once the first is gone, at thickness h. The peak counts whatever the detector holds across
// frames.
Measured measure(const TriMesh& mesh, const Positions& x0, const Positions& x1, Scalar h, const char* kinds) {
  const long long before = g_live.load();
  g_peak.store(before);
  DetectorOptions options;
  options.thickness = h;
  options.kinds = ContactKinds::parse(kinds);
  options.threads = 2;
  auto detector = make_detector(MethodSpec::parse("kdop"), options);
  detector->set_topology(mesh.topology_ptr());
  Measured m;
  {
    ContactSet first;
    detector->update(x0, first);
    m.records = record_bytes(first);
  }
  ContactSet out;
  detector->update(x0, x1, out);
  m.records = std::max(m.records, record_bytes(out));
  m.extra = static_cast<double>(g_peak.load() - before);
  return m;
}

TEST(ExactMemory, PeakIsTheRecordsOnceAndAFraction) {
#ifdef CRUMPLE_SANITIZED
  const Index n = 32;
#else
  const Index n = 48;
#endif
  const TriMesh lattice = shapes::lattice(n, n);
  const Positions x0 = testing::crumple_lattice(lattice, 0.15, 7);
  Positions x1 = x0;
  for (Vec3& p : x1) p *= 0.995;  // a small motion: the tree is refitted
  const Scalar spacing = 1.0 / static_cast<Scalar>(n);
  // O(faces): the same frames with few contacts (the tree, the orphan lists, the counters).
  const Measured thin = measure(lattice, x0, x1, 0.05 * spacing, "vf,ee");
  // And the records a frame may keep beside their keys, O(faces) too (exact/narrow_frame.hpp),
  // with their storage kept from the frame before.
  const double kept = 2.0 * static_cast<double>(exact::kKeepBytesPerFace) * static_cast<double>(lattice.num_faces());
  for (const char* kinds : {"vf,ee", "vf,ee,tt"}) {
    const Measured thick = measure(lattice, x0, x1, 3 * spacing, kinds);
    ASSERT_GT(thick.records, 3 * (thin.extra + kept)) << "the records must dominate for the bound to say anything";
    EXPECT_LE(thick.extra, 1.5 * thick.records + thin.extra + kept)
        << kinds << ": peak " << thick.extra / thick.records << " x the records (" << thick.records / 1e6
        << " MB), O(faces) " << (thin.extra + kept) / 1e6 << " MB";
  }
}

}  // namespace
}  // namespace crumple

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
#include <cmath>
#include <random>
#include <string>
#include <utility>

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

// Triangle intersections alone (`--kinds tt`) past the record budget. A triangle contact (8
// bytes) is as large as its key and as a broad-phase candidate, so every copy counts: all the
// candidates held through the narrow phase, keys grown by doubling beside kept records, and the
// gather's places (an address and a second face a contact) beside the keys, then beside the
// output, took 5.1 x the records here. On `testing::hedgehog` (every pair of faces meets), and
// the same triangles moved apart for the O(faces) part.
TEST(ExactMemory, TriangleIntersectionsAlonePastTheBudget) {
  // As many contacts as a face's share of the O(faces) part (about 1.6 kB here) times 3, at
  // least: fewer would let the bound pass whatever the gather holds (also under the sanitizers).
  const Index n = 2400;
  const auto [spread, x_apart] = testing::hedgehog(n, true);
  const auto [mesh, x0] = testing::hedgehog(n, false);
  Positions x1 = x0, y1 = x_apart;
  for (Vec3& p : x1) p *= 0.995;
  for (Vec3& p : y1) p *= 0.995;
  const Measured thin = measure(spread, x_apart, y1, 1e-3, "tt");
  ASSERT_EQ(thin.records, 0) << "the triangles moved apart do not meet";
  const double kept = 2.0 * static_cast<double>(exact::kKeepBytesPerFace) * static_cast<double>(mesh.num_faces());
  const Measured thick = measure(mesh, x0, x1, 1e-3, "tt");
  ASSERT_EQ(thick.records, static_cast<double>(sizeof(TriangleTriangleContact)) * n * (n - 1) / 2)
      << "every pair of triangles meets";
  ASSERT_GT(thick.records, 3 * (thin.extra + kept)) << "the records must dominate for the bound to say anything";
  RecordProperty("peak_over_records", std::to_string(thick.extra / thick.records));
  RecordProperty("o_faces_mb", std::to_string(thin.extra / 1e6));
  EXPECT_LE(thick.extra, 1.5 * thick.records + thin.extra + kept)
      << "tt: peak " << thick.extra / thick.records << " x the records (" << thick.records / 1e6 << " MB), O(faces) "
      << (thin.extra + kept) / 1e6 << " MB";
}

}  // namespace
}  // namespace crumple

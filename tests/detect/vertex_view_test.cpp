// Detection from a host application's buffers (`VertexView`): float and double, packed and
// strided (interleaved), aligned or not. Every view gives exactly the contacts of the `double`
// path on the same values (the float input converted to double), for every method.
#include <crumple/core/error.hpp>
#include <crumple/core/vertex_view.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/meshes.hpp>
#include <support/vertex_buffers.hpp>

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace crumple {
namespace {

using testing::Buffers;

/// Bit-exact equality of two contact sets (every field of every record).
void expect_same(const ContactSet& a, const ContactSet& b, const std::string& what) {
  ASSERT_EQ(a.vf.size(), b.vf.size()) << what;
  ASSERT_EQ(a.ee.size(), b.ee.size()) << what;
  ASSERT_EQ(a.tt.size(), b.tt.size()) << what;
  for (std::size_t i = 0; i < a.vf.size(); ++i) {
    EXPECT_EQ(a.vf[i].vertex, b.vf[i].vertex) << what;
    EXPECT_EQ(a.vf[i].face, b.vf[i].face) << what;
    EXPECT_EQ(a.vf[i].distance, b.vf[i].distance) << what;
    EXPECT_EQ(a.vf[i].barycentric, b.vf[i].barycentric) << what;
    EXPECT_EQ(a.vf[i].normal, b.vf[i].normal) << what;
  }
  for (std::size_t i = 0; i < a.ee.size(); ++i) {
    EXPECT_EQ(a.ee[i].edge0, b.ee[i].edge0) << what;
    EXPECT_EQ(a.ee[i].edge1, b.ee[i].edge1) << what;
    EXPECT_EQ(a.ee[i].distance, b.ee[i].distance) << what;
    EXPECT_EQ(a.ee[i].s, b.ee[i].s) << what;
    EXPECT_EQ(a.ee[i].t, b.ee[i].t) << what;
    EXPECT_EQ(a.ee[i].normal, b.ee[i].normal) << what;
  }
  for (std::size_t i = 0; i < a.tt.size(); ++i) {
    EXPECT_EQ(a.tt[i].face0, b.tt[i].face0) << what;
    EXPECT_EQ(a.tt[i].face1, b.tt[i].face1) << what;
  }
}

TEST(DetectFromVertexView, EveryViewGivesTheContactsOfTheDoublePath) {
  const TriMesh mesh = shapes::lattice(10, 10);
  const Positions x0 = testing::crumple_lattice(mesh, 0.2, 11);
  const Positions x1 = testing::jitter(x0, 0.004, 12);
  const Buffers b0(x0), b1(x1);
  DetectorOptions options;
  options.thickness = 0.03;
  options.kinds = ContactKinds::parse("vf,ee,tt");
  options.threads = 2;
  for (const std::string spec : {"naive", "kdop", "hash", "sap", "stochastic:seed=3"}) {
    auto reference = make_detector(MethodSpec::parse(spec), options);
    reference->set_topology(mesh.topology_ptr());
    ContactSet expected0, expected1;
    reference->update(b0.reference, expected0);
    reference->update(b0.reference, b1.reference, expected1);  // with motion (kdop uses it)
    ASSERT_GT(expected0.vf.size() + expected0.ee.size(), 50u) << spec;
    const auto views0 = b0.views();
    const auto views1 = b1.views();
    for (std::size_t v = 0; v < views0.size(); ++v) {
      auto detector = make_detector(MethodSpec::parse(spec), options);
      detector->set_topology(mesh.topology_ptr());
      ContactSet got;
      detector->update(views0[v].second, got);
      expect_same(got, expected0, spec + ", " + views0[v].first + ", frame 0");
      detector->update(views0[v].second, views1[v].second, got);
      expect_same(got, expected1, spec + ", " + views0[v].first + ", frame 1");
    }
  }
}

TEST(DetectFromVertexView, WrongCountIsAPreconditionError) {
  const TriMesh mesh = shapes::lattice(2, 2);
  const Buffers b(mesh.positions());
  auto detector = make_detector(MethodSpec::parse("kdop"), DetectorOptions{});
  detector->set_topology(mesh.topology_ptr());
  ContactSet out;
  EXPECT_THROW(detector->update(VertexView(b.packed.data(), b.reference.size() - 1), out), PreconditionError);
  // kdop uses motion: a previous frame of another count is refused too.
  EXPECT_THROW(detector->update(VertexView(b.packed.data(), 2), VertexView(b.packed.data(), b.reference.size()), out),
               PreconditionError);
}

}  // namespace
}  // namespace crumple

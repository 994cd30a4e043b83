// Positions from a host application's buffers (`VertexView`): float and double, packed and
// strided (interleaved), aligned or not. Every view gives exactly the contacts of the `double`
// path on the same values (the float input converted to double), for every method.
#include <crumple/core/error.hpp>
#include <crumple/core/vertex_view.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/meshes.hpp>

#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <string>
#include <vector>

namespace crumple {
namespace {

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

/// An engine's vertex buffers holding the same positions: packed floats, an interleaved float
/// buffer (position, normal, uv: 8 floats, 32 bytes a vertex), an interleaved double buffer
/// (position + 3 doubles, 48 bytes), and packed doubles starting 4 bytes off alignment.
struct Buffers {
  std::vector<float> packed;
  std::vector<float> interleaved;
  std::vector<double> wide;
  std::vector<unsigned char> misaligned;
  Positions reference;  ///< the float values as doubles: the `double` path's input

  explicit Buffers(PositionsView x) {
    const std::size_t n = x.size();
    packed.resize(3 * n);
    interleaved.assign(8 * n, -7.0f);
    wide.assign(6 * n, 1e300);
    misaligned.resize(3 * n * sizeof(double) + 4);
    reference.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      for (int k = 0; k < 3; ++k) {
        const float f = static_cast<float>(x[i][k]);
        packed[3 * i + static_cast<std::size_t>(k)] = f;
        interleaved[8 * i + static_cast<std::size_t>(k)] = f;
        reference[i][k] = static_cast<double>(f);
        wide[6 * i + static_cast<std::size_t>(k)] = reference[i][k];
      }
    }
    std::memcpy(misaligned.data() + 4, reference.data(), 3 * n * sizeof(double));
  }

  std::vector<std::pair<std::string, VertexView>> views() const {
    const std::size_t n = reference.size();
    return {
        {"packed float", VertexView(packed.data(), n)},
        {"interleaved float", VertexView(interleaved.data(), n, 8 * sizeof(float))},
        {"interleaved double", VertexView(wide.data(), n, 6 * sizeof(double))},
        {"misaligned double",
         VertexView(reinterpret_cast<const double*>(misaligned.data() + 4), n)},  // read by memcpy
        {"native double", VertexView(PositionsView(reference))},
    };
  }
};

TEST(VertexView, ConvertsExactlyAndReadsNativeInPlace) {
  const TriMesh mesh = shapes::lattice(3, 2);
  const Positions x = testing::jitter(mesh.positions(), 0.01, 5);
  const Buffers b(x);
  for (const auto& [name, view] : b.views()) {
    ASSERT_EQ(view.size(), x.size()) << name;
    Positions converted;
    view.convert(converted);
    EXPECT_EQ(converted, b.reference) << name;
    for (std::size_t i = 0; i < x.size(); ++i) EXPECT_EQ(view[i], b.reference[i]) << name;
  }
  const VertexView native(PositionsView(b.reference));
  EXPECT_TRUE(native.is_native());
  EXPECT_EQ(native.native().data(), b.reference.data());  // no copy
  EXPECT_TRUE(VertexView(reinterpret_cast<const double*>(b.reference.data()), x.size()).is_native());
  EXPECT_FALSE(VertexView(b.packed.data(), x.size()).is_native());
  EXPECT_FALSE(VertexView(b.wide.data(), x.size(), 48).is_native());
  EXPECT_FALSE(VertexView(reinterpret_cast<const double*>(b.misaligned.data() + 4), x.size()).is_native());
  EXPECT_THROW((void)VertexView(b.packed.data(), x.size()).native(), PreconditionError);
  EXPECT_TRUE(VertexView().empty() && VertexView().is_native() && VertexView().native().empty());
}

TEST(VertexView, PreconditionsAndNonFiniteValues) {
  const std::vector<float> xyz{0, 1, 2, 3, 4, 5};
  EXPECT_THROW(VertexView(xyz.data(), 2, 8), PreconditionError);  // less than 3 floats
  EXPECT_THROW(VertexView(static_cast<const double*>(nullptr), 1), PreconditionError);
  EXPECT_NO_THROW(VertexView(static_cast<const float*>(nullptr), 0));
  EXPECT_EQ(VertexView(xyz.data(), 2, 12).stride(), 12u);
  EXPECT_EQ(VertexView(xyz.data(), 1, 0).stride(), 12u);  // 0 = packed
  EXPECT_NO_THROW(check_finite(VertexView(xyz.data(), 2)));
  std::vector<float> bad = xyz;
  bad[4] = std::numeric_limits<float>::quiet_NaN();
  try {
    check_finite(VertexView(bad.data(), 2));
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 1 has a non-finite coordinate"), std::string::npos) << e.what();
  }
}

TEST(VertexView, EveryViewGivesTheContactsOfTheDoublePath) {
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

TEST(VertexView, WrongCountIsAPreconditionError) {
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

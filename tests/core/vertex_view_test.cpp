// VertexView: float and double positions, packed or strided, aligned or not, converted
// exactly; native views read in place; preconditions; non-finite values named.
#include <crumple/core/error.hpp>
#include <crumple/core/vertex_view.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/meshes.hpp>
#include <support/vertex_buffers.hpp>

#include <gtest/gtest.h>

#include <limits>
#include <string>
#include <vector>

namespace crumple {
namespace {

using testing::Buffers;

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

}  // namespace
}  // namespace crumple

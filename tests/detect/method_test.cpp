#include <crumple/core/error.hpp>
#include <crumple/detect/detector.hpp>

#include <gtest/gtest.h>

namespace crumple {
namespace {

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(MethodSpec, ParsesNamesAndRoundTrips) {
  const MethodSpec spec = MethodSpec::parse("naive");
  EXPECT_EQ(spec.method(), Method::Naive);
  EXPECT_TRUE(spec.params().empty());
  EXPECT_EQ(spec.to_string(), "naive");
  EXPECT_EQ(MethodSpec::parse(" naive: ").to_string(), "naive");
  for (const MethodInfo& m : all_methods()) {
    EXPECT_EQ(parse_method(m.name), m.method);
    EXPECT_EQ(to_string(m.method), m.name);
  }
}

TEST(MethodSpec, UnknownNameListsValidNames) {
  const std::string msg = error_of([] { MethodSpec::parse("bogus:x=1"); });
  EXPECT_NE(msg.find("unknown method 'bogus'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("naive"), std::string::npos) << msg;
}

TEST(MethodSpec, UnknownOrMalformedKeysAreErrors) {
  std::string msg = error_of([] { MethodSpec::parse("naive:active=3"); });
  EXPECT_NE(msg.find("unknown key 'active'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("valid keys"), std::string::npos) << msg;
  msg = error_of([] { MethodSpec::parse("naive:justaword"); });
  EXPECT_NE(msg.find("expected key=value"), std::string::npos) << msg;
}

TEST(ContactKinds, ParseAndPrint) {
  const ContactKinds k = ContactKinds::parse("ee,tt");
  EXPECT_FALSE(k.vf);
  EXPECT_TRUE(k.ee);
  EXPECT_TRUE(k.tt);
  EXPECT_EQ(k.to_string(), "ee,tt");
  EXPECT_THROW(ContactKinds::parse("vf,xx"), InputError);
  EXPECT_THROW(ContactKinds::parse(""), InputError);
}

TEST(Factory, MakesEveryMethodWithItsCapabilities) {
  for (const MethodInfo& m : all_methods()) {
    auto d = make_detector(MethodSpec(m.method), {.thickness = 0.1});
    ASSERT_NE(d, nullptr);
    EXPECT_EQ(d->method(), m.method);
    EXPECT_EQ(d->capabilities().exact, m.capabilities.exact);
  }
  EXPECT_TRUE(method_info(Method::Naive).capabilities.exact);
}

TEST(Detector, RejectsBadOptionsAndMisuse) {
  EXPECT_THROW(make_detector(MethodSpec(Method::Naive), {.thickness = -1}), InputError);
  EXPECT_THROW(make_detector(MethodSpec(Method::Naive), {.thickness = std::nan("")}), InputError);
  auto d = make_detector(MethodSpec(Method::Naive), {.thickness = 0.1});
  ContactSet out;
  Positions x(3, Vec3::Zero());
  EXPECT_THROW(d->update(x, out), PreconditionError);  // no topology yet
  d->set_topology(std::make_shared<const Topology>(Topology::build(3, {{0, 1, 2}})));
  Positions wrong(4, Vec3::Zero());
  EXPECT_THROW(d->update(wrong, out), PreconditionError);
  EXPECT_THROW(d->update(Positions(2, Vec3::Zero()), x, out), PreconditionError);
}

}  // namespace
}  // namespace crumple

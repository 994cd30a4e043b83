#include <crumple/core/error.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/broad_phase/hash_grid.hpp>
#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/detect/stochastic.hpp>
#include <crumple/detect/broad_phase/sweep_prune.hpp>

#include <gtest/gtest.h>

#include <sstream>

namespace crumple {
namespace {

// Frames of the folding sequence below: under the sanitizers the same fold (same first and last
// angle) in half as many steps, since the naive method's frames are most of the time there.
#ifdef CRUMPLE_SANITIZED
constexpr std::size_t kFoldFrames = 6;
#else
constexpr std::size_t kFoldFrames = 12;
#endif

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

// The defaults printed by --help (`MethodInfo::params`) are the ones the detectors use: a spec
// naming every documented default explicitly behaves exactly like the bare method name (same
// contacts and same counters on a folding sequence where the stochastic walks are long).
TEST(MethodSpec, DocumentedDefaultsAreTheDefaults) {
  const FoldingSequence frames({.n = 20, .frames = kFoldFrames, .seed = 3});
  const auto topo = frames.mesh().topology_ptr();
  for (const MethodInfo& m : all_methods()) {
    std::string text(m.name);
    char sep = ':';
    for (const ParamInfo& p : m.params) {
      text += sep + std::string(p.key) + "=" + std::string(p.default_value);
      sep = ',';
    }
    SCOPED_TRACE(text);
    const DetectorOptions options{.thickness = frames.thickness(), .kinds = ContactKinds::parse("vf,ee,tt")};
    auto bare = make_detector(MethodSpec(m.method), options);
    auto named = make_detector(MethodSpec::parse(text), options);
    bare->set_topology(topo);
    named->set_topology(topo);
    Positions previous;
    for (std::size_t i = 0; i < frames.size(); ++i) {
      const Positions x = frames.positions(i);
      ContactSet a, b;
      if (previous.empty()) {
        bare->update(x, a);
        named->update(x, b);
      } else {
        bare->update(previous, x, a);
        named->update(previous, x, b);
      }
      const ContactMatch match = match_contacts(b, a);
      EXPECT_EQ(match.missed + match.false_contacts, 0u) << "frame " << i;
      for (const auto& [key, value] : bare->stats().items()) {
        if (!key.ends_with("_ms")) {
          EXPECT_EQ(named->stats().get(key), value) << key << ", frame " << i;
        }
      }
      previous = x;
    }
  }
}

// The same, on the parameters themselves (a small scene can build the same tree whatever the
// leaf size, so behaviour alone does not show a default that differs): the bare name, each
// documented default named alone, and the struct a program fills in code are all equal.
template <class Params>
void expect_documented_defaults(Method method) {
  const MethodInfo& info = method_info(method);
  const Params bare = Params::from_spec(MethodSpec(method));
  EXPECT_TRUE(bare == Params{}) << info.name << ": the bare spec differs from the struct's defaults";
  for (const ParamInfo& p : info.params) {
    const std::string text = std::string(info.name) + ":" + std::string(p.key) + "=" + std::string(p.default_value);
    EXPECT_TRUE(Params::from_spec(MethodSpec::parse(text)) == bare) << text << " is not the default";
  }
}

TEST(MethodSpec, DocumentedDefaultsAreTheParameterStructsDefaults) {
  expect_documented_defaults<KdopParams>(Method::Kdop);
  expect_documented_defaults<HashParams>(Method::Hash);
  expect_documented_defaults<SapParams>(Method::Sap);
  expect_documented_defaults<StochasticParams>(Method::Stochastic);
}

std::string text_of(const ContactSet& set) {
  std::ostringstream out;
  write_contacts(out, set);
  return out.str();
}

// `update` replaces whatever `out` held: a set reused from frame to frame (whose size the exact
// methods keep and rewrite in place) and one that starts with junk give exactly the contacts of
// a fresh set, as the counts rise and fall; and a throwing update leaves `out` empty.
TEST(Detector, UpdateReplacesWhateverOutHeld) {
  const FoldingSequence frames({.n = 20, .frames = kFoldFrames, .seed = 3});
  const auto topo = frames.mesh().topology_ptr();
  const DetectorOptions options{.thickness = frames.thickness(), .kinds = ContactKinds::parse("vf,ee,tt")};
  for (const MethodInfo& m : all_methods()) {
    SCOPED_TRACE(m.name);
    auto fresh = make_detector(MethodSpec(m.method), options);
    auto reused = make_detector(MethodSpec(m.method), options);
    fresh->set_topology(topo);
    reused->set_topology(topo);
    ContactSet kept;
    kept.vf.assign(5000, VertexFaceContact{.vertex = 7, .face = 3, .distance = -1});
    kept.ee.assign(5000, EdgeEdgeContact{.edge0 = 1, .edge1 = 2, .a = {9, 8}, .b = {7, 6}});
    kept.tt.assign(5000, TriangleTriangleContact{.face0 = 4, .face1 = 4});
    std::size_t smallest = 5000, largest = 0;
    for (std::size_t i = 0; i < frames.size(); ++i) {
      const Positions x = frames.positions(i);
      ContactSet a;
      fresh->update(x, a);
      reused->update(x, kept);
      EXPECT_EQ(text_of(kept), text_of(a)) << "frame " << i;
      smallest = std::min(smallest, a.size());
      largest = std::max(largest, a.size());
    }
    EXPECT_LT(smallest, largest);  // the sequence did make the set shrink and grow
  }
  // A throwing update (an exact method's cap) empties the set it was given.
  const Positions last = frames.positions(frames.size() - 1);
  auto uncapped = make_detector(MethodSpec::parse("kdop"), options);
  auto capped = make_detector(MethodSpec::parse("kdop:max_contacts=1"), options);
  uncapped->set_topology(topo);
  capped->set_topology(topo);
  ContactSet out;
  uncapped->update(last, out);
  ASSERT_GT(out.size(), 1u);
  EXPECT_THROW(capped->update(last, out), Error);
  EXPECT_TRUE(out.empty());
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

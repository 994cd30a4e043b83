// The `NAME[:key=value,...]` syntax shared by method and scene specs.
#include <crumple/core/error.hpp>
#include <crumple/core/spec_text.hpp>
#include <crumple/detect/method.hpp>
#include <crumple/sim/scene.hpp>

#include <gtest/gtest.h>

#include <array>
#include <string>
#include <string_view>

namespace crumple {
namespace {

std::string error_of(std::string_view text, std::string_view hint = {}) {
  try {
    SpecText::split(text, "thing", hint);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(SpecText, SplitsTrimsAndSkipsEmptyItems) {
  const SpecText s = SpecText::split("  name : a = 1 ,, b=x y ,", "thing");
  EXPECT_EQ(s.name, "name");
  ASSERT_EQ(s.items.size(), 2u);
  EXPECT_EQ(s.items[0], (std::pair<std::string, std::string>{"a", "1"}));
  EXPECT_EQ(s.items[1], (std::pair<std::string, std::string>{"b", "x y"}));
  EXPECT_EQ(SpecText::split("bare", "thing").items.size(), 0u);
  EXPECT_EQ(SpecText::split("bare:", "thing").name, "bare");
  EXPECT_EQ(SpecText::split("k:v=", "thing").items.at(0).second, "") << "an empty value is a value";
}

TEST(SpecText, MalformedItemsAndRepeatedKeysAreErrors) {
  EXPECT_NE(error_of("n:word").find("thing 'n:word': expected key=value, got 'word'"), std::string::npos);
  EXPECT_NE(error_of("n:=3").find("expected key=value, got '=3'"), std::string::npos);
  EXPECT_NE(error_of("n:a=1,a=2").find("key 'a' given twice"), std::string::npos);
  EXPECT_NE(error_of("n:word", "valid keys: a, b").find("(valid keys: a, b)"), std::string::npos);
}

TEST(SpecText, StrictValueConversions) {
  EXPECT_EQ(parse_integer("42"), 42);
  EXPECT_EQ(parse_integer("-7"), -7);
  EXPECT_FALSE(parse_integer("4x"));
  EXPECT_FALSE(parse_integer(""));
  EXPECT_FALSE(parse_integer("1.5"));
  EXPECT_EQ(parse_number("2.5e-3"), 2.5e-3);
  EXPECT_FALSE(parse_number("inf"));
  EXPECT_FALSE(parse_number("nan"));
  EXPECT_FALSE(parse_number("1,5"));
  EXPECT_EQ(parse_switch("on"), true);
  EXPECT_EQ(parse_switch("0"), false);
  EXPECT_FALSE(parse_switch("yes"));
}

TEST(SpecText, FormatIsParsedBackUnchanged) {
  const std::vector<std::pair<std::string, std::string>> items{{"a", "1"}, {"b", "x"}};
  EXPECT_EQ(format_spec("n", items), "n:a=1,b=x");
  EXPECT_EQ(format_spec("n", {}), "n");
  EXPECT_EQ(SpecText::split(format_spec("n", items), "thing").items, items);
  const std::vector<std::string> names{"x", "y", "z"};
  EXPECT_EQ(join_list(names, [](const std::string& s) { return s; }), "x, y, z");
}

struct Key {
  std::string_view key;
};

std::string set_error(SpecItems& items, std::span<const Key> table, std::string key) {
  try {
    set_spec_key(items, table, std::move(key), "v", "thing 'n'");
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(SpecText, SetKeyChecksTheTableThenReplacesOrAppends) {
  constexpr std::array<Key, 2> table{{{"a"}, {"b"}}};
  SpecItems items;
  set_spec_key(items, table, "b", "1", "thing 'n'");
  set_spec_key(items, table, "a", "2", "thing 'n'");
  set_spec_key(items, table, "b", "3", "thing 'n'");
  EXPECT_EQ(items, (SpecItems{{"b", "3"}, {"a", "2"}})) << "first-set order kept, value replaced";
  ASSERT_NE(find_spec_value(items, "a"), nullptr);
  EXPECT_EQ(*find_spec_value(items, "a"), "2");
  EXPECT_EQ(find_spec_value(items, "c"), nullptr);

  EXPECT_EQ(set_error(items, table, "c"), "thing 'n': unknown key 'c' (valid keys: a, b)");
  EXPECT_EQ(items.size(), 2u) << "an unknown key changes nothing";
  EXPECT_EQ(set_error(items, {}, "a"), "thing 'n': unknown key 'a' (valid keys: none)");
}

template <class Spec>
std::string spec_error(std::string_view text) {
  try {
    Spec::parse(text);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

// Method and scene specs set their keys through `set_spec_key`, so an unknown key reads the
// same way in both and lists the owner's keys.
TEST(SpecText, MethodAndSceneSpecsReportUnknownKeysAlike) {
  EXPECT_EQ(spec_error<MethodSpec>("sap:zz=1"),
            "method sap: unknown key 'zz' (valid keys: axis, max_contacts, overflow)");
  EXPECT_EQ(spec_error<MethodSpec>("naive:zz=1"), "method naive: unknown key 'zz' (valid keys: cull)");
  const std::string scene = spec_error<sim::SceneSpec>("hanging-cloth:zz=1");
  EXPECT_EQ(scene.rfind("scene 'hanging-cloth': unknown key 'zz' (valid keys: ", 0), 0u) << scene;
  EXPECT_NE(scene.find("nx"), std::string::npos) << scene;
  MethodSpec m = MethodSpec::parse("sap:axis=x");
  m.set("axis", "z");
  EXPECT_EQ(m.to_string(), "sap:axis=z");
  sim::SceneSpec s = sim::SceneSpec::parse("hanging-cloth:nx=4");
  s.set("nx", "5");
  EXPECT_EQ(s.get_int("nx"), 5);
}

}  // namespace
}  // namespace crumple

// The `NAME[:key=value,...]` syntax shared by method and scene specs.
#include <crumple/core/error.hpp>
#include <crumple/core/spec_text.hpp>

#include <gtest/gtest.h>

#include <string>

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

}  // namespace
}  // namespace crumple

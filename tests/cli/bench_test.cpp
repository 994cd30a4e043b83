// `crumple bench --quick`: every section runs on tiny inputs; the outputs must be well formed
// and the measurements coherent (exact methods at recall 1, no method with a false contact).
#include <gtest/gtest.h>

#include <support/run_cli.hpp>
#include <support/temp_dir.hpp>

#include <cctype>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace crumple {
namespace {

using testing::run_cli;

std::string slurp(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// A strict JSON syntax check (RFC 8259 grammar, no extensions): true when `text` is exactly one
/// value surrounded by optional whitespace.
class JsonChecker {
 public:
  explicit JsonChecker(const std::string& text) : s_(text) {}
  bool valid() {
    skip();
    if (!value()) return false;
    skip();
    return i_ == s_.size();
  }

 private:
  void skip() {
    while (i_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[i_]))) ++i_;
  }
  bool lit(const char* w) {
    const std::string word(w);
    if (s_.compare(i_, word.size(), word) != 0) return false;
    i_ += word.size();
    return true;
  }
  bool string() {
    if (s_[i_] != '"') return false;
    for (++i_; i_ < s_.size(); ++i_) {
      const char c = s_[i_];
      if (c == '"') {
        ++i_;
        return true;
      }
      if (static_cast<unsigned char>(c) < 0x20) return false;
      if (c == '\\') ++i_;
    }
    return false;
  }
  bool number() {
    const std::size_t start = i_;
    if (s_[i_] == '-') ++i_;
    while (i_ < s_.size() && (std::isdigit(static_cast<unsigned char>(s_[i_])) || s_[i_] == '.' || s_[i_] == 'e' ||
                              s_[i_] == 'E' || s_[i_] == '+' || s_[i_] == '-')) {
      ++i_;
    }
    return i_ > start && std::isdigit(static_cast<unsigned char>(s_[i_ - 1]));
  }
  bool value() {
    if (i_ >= s_.size()) return false;
    const char c = s_[i_];
    if (c == '{' || c == '[') {
      const char close = c == '{' ? '}' : ']';
      ++i_;
      skip();
      if (i_ < s_.size() && s_[i_] == close) {
        ++i_;
        return true;
      }
      for (;;) {
        skip();
        if (c == '{') {
          if (i_ >= s_.size() || !string()) return false;
          skip();
          if (i_ >= s_.size() || s_[i_++] != ':') return false;
          skip();
        }
        if (!value()) return false;
        skip();
        if (i_ >= s_.size()) return false;
        if (s_[i_] == ',') {
          ++i_;
          continue;
        }
        if (s_[i_] == close) {
          ++i_;
          return true;
        }
        return false;
      }
    }
    if (c == '"') return string();
    if (c == 't') return lit("true");
    if (c == 'f') return lit("false");
    if (c == 'n') return lit("null");
    return number();
  }
  const std::string& s_;
  std::size_t i_ = 0;
};

/// CSV with a header; fields may be double-quoted (no embedded quotes).
struct Csv {
  std::vector<std::string> header;
  std::vector<std::map<std::string, std::string>> rows;
  bool ragged = false;
};

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> out(1);
  bool quoted = false;
  for (char c : line) {
    if (c == '"') {
      quoted = !quoted;
    } else if (c == ',' && !quoted) {
      out.emplace_back();
    } else {
      out.back().push_back(c);
    }
  }
  return out;
}

Csv read_csv(const std::filesystem::path& path) {
  Csv csv;
  std::ifstream in(path);
  std::string line;
  if (!std::getline(in, line)) return csv;
  csv.header = split_csv_line(line);
  while (std::getline(in, line)) {
    const auto fields = split_csv_line(line);
    if (fields.size() != csv.header.size()) csv.ragged = true;
    std::map<std::string, std::string> row;
    for (std::size_t i = 0; i < fields.size() && i < csv.header.size(); ++i) row[csv.header[i]] = fields[i];
    csv.rows.push_back(row);
  }
  return csv;
}

// One run of `crumple bench --quick` (tens of seconds under sanitizers), checked part by part.
// Under the sanitizers every frame is timed once (`--repeat 1`, a third of the detection work):
// what is checked (files, their form, exact recall, no false contact) does not depend on it.
#ifdef CRUMPLE_SANITIZED
constexpr const char* kQuickBench = "bench --quick --repeat 1 --out ";
#else
constexpr const char* kQuickBench = "bench --quick --out ";
#endif
struct QuickRun {
  testing::TempDir dir;
  // Progress lines at once (CRUMPLE_PROGRESS_SECONDS=0), checked by expect_every_output.
  testing::CliResult result =
      testing::run_program("CRUMPLE_PROGRESS_SECONDS=0 " + std::string(CRUMPLE_CLI), kQuickBench + dir.path().string());
};

void expect_every_output(const QuickRun& run) {
  ASSERT_EQ(run.result.status, 0) << run.result.out;
  EXPECT_NE(run.result.out.find("wrote"), std::string::npos) << run.result.out;
  EXPECT_NE(run.result.out.find("crumple bench: section "), std::string::npos) << run.result.out;
  for (const char* name : {"bench.md", "bench.json", "fig42.csv", "fig43.csv", "second.csv", "scaling.csv",
                           "budget.csv", "fig42-fps.svg", "fig42-speedup.svg", "scaling.svg", "budget.svg"}) {
    EXPECT_TRUE(std::filesystem::is_regular_file(run.dir / name)) << name;
  }
  // Atomic writes leave no temporary file behind.
  for (const auto& entry : std::filesystem::directory_iterator(run.dir.path())) {
    EXPECT_EQ(entry.path().filename().string().find(".tmp"), std::string::npos) << entry.path();
  }
}

void expect_well_formed_json(const QuickRun& run) {
  ASSERT_EQ(run.result.status, 0) << run.result.out;
  const std::string json = slurp(run.dir / "bench.json");
  EXPECT_TRUE(JsonChecker(json).valid()) << json.substr(0, 400);
  for (const char* key : {"\"machine\":", "\"commit\":", "\"fig42\":[", "\"fig43\":[", "\"second\":[",
                          "\"scaling\":[", "\"budget\":["}) {
    EXPECT_NE(json.find(key), std::string::npos) << key;
  }
  EXPECT_FALSE(JsonChecker("{\"a\":[1,2,}").valid());  // the checker does reject bad JSON
  EXPECT_FALSE(JsonChecker("{\"a\":1} x").valid());
}

void expect_coherent_tables(const QuickRun& run) {
  ASSERT_EQ(run.result.status, 0) << run.result.out;
  const Csv fig42 = read_csv(run.dir / "fig42.csv");
  EXPECT_FALSE(fig42.ragged);
  EXPECT_EQ(fig42.rows.size(), 2u * 16u * 4u);  // two tables x 16 methods x 4 bins
  std::size_t measured = 0;
  for (const auto& row : fig42.rows) {
    EXPECT_EQ(row.at("false_contacts"), "0") << row.at("spec");
    const std::string& spec = row.at("spec");
    const bool exact = spec.rfind("naive", 0) == 0 || spec.rfind("kdop", 0) == 0 || spec == "hash" || spec == "sap";
    if (exact && !row.at("recall").empty()) {
      EXPECT_EQ(row.at("recall"), "1") << spec << " bin " << row.at("bin");
      EXPECT_EQ(row.at("missed"), "0") << spec;
      ++measured;
    }
  }
  EXPECT_GT(measured, 0u);  // some bin held frames

  const Csv scaling = read_csv(run.dir / "scaling.csv");
  EXPECT_FALSE(scaling.ragged);
  EXPECT_GE(scaling.rows.size(), 2u * 6u);  // two lattices x at least the six non-naive methods
  for (const auto& row : scaling.rows) {
    const std::string& spec = row.at("spec");
    if (spec.rfind("stochastic", 0) != 0) {
      EXPECT_EQ(row.at("recall"), "1") << spec << " on " << row.at("input");
    }
    EXPECT_GT(std::stod(row.at("mean_ms")), 0.0);
  }
  for (const char* name : {"fig43.csv", "second.csv", "budget.csv"}) {
    const Csv t = read_csv(run.dir / name);
    EXPECT_FALSE(t.ragged) << name;
    EXPECT_FALSE(t.rows.empty()) << name;
  }
}

void expect_markdown_and_plots(const QuickRun& run) {
  ASSERT_EQ(run.result.status, 0) << run.result.out;
  const std::string md = slurp(run.dir / "bench.md");
  for (const char* part : {"## Figure 4.2", "## Figure 4.3", "second test", "## Scaling", "## Time budget",
                           "| naive O(n²)", "![fps](fig42-fps.svg)"}) {
    EXPECT_NE(md.find(part), std::string::npos) << part;
  }
  for (const char* name : {"fig42-fps.svg", "fig42-speedup.svg", "scaling.svg", "budget.svg"}) {
    const std::string svg = slurp(run.dir / name);
    EXPECT_EQ(svg.rfind("<svg xmlns=\"http://www.w3.org/2000/svg\"", 0), 0u) << name;
    EXPECT_NE(svg.find("</svg>\n"), std::string::npos) << name;
    EXPECT_NE(svg.find("<polyline"), std::string::npos) << name << " has no data line";
  }
}

TEST(CliBench, QuickRunWritesWellFormedCoherentOutputs) {
  const QuickRun run;
  {
    SCOPED_TRACE("outputs");
    expect_every_output(run);
  }
  {
    SCOPED_TRACE("json");
    expect_well_formed_json(run);
  }
  {
    SCOPED_TRACE("tables");
    expect_coherent_tables(run);
  }
  {
    SCOPED_TRACE("markdown and plots");
    expect_markdown_and_plots(run);
  }
}

TEST(CliBenchArgs, BadOptionsAreRejected) {
  const auto bad_section = run_cli("bench --quick --sections thesis,nope --out /nonexistent/x");
  EXPECT_NE(bad_section.status, 0);
  EXPECT_NE(bad_section.out.find("nope"), std::string::npos) << bad_section.out;
  const auto bad_repeat = run_cli("bench --quick --repeat 0");
  EXPECT_NE(bad_repeat.status, 0);
  EXPECT_NE(bad_repeat.out.find("--repeat"), std::string::npos) << bad_repeat.out;
}

TEST(CliBenchArgs, UnwritableOutputFolderIsAClearError) {
  const testing::TempDir dir;
  const auto blocker = dir / "file";
  std::ofstream(blocker) << "x";
  const auto r = run_cli("bench --quick --sections budget -q --out " + (blocker / "sub").string());
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find("crumple: error:"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace crumple

// Runs `exact_bench` (bench/exact_bench.cpp, built with the benchmarks) as a user would: its
// command line is checked before any work, and its tables replace the old files, leaving nothing
// else behind.
#ifdef CRUMPLE_EXACT_BENCH

#include <support/meshes.hpp>
#include <support/run_cli.hpp>
#include <support/temp_dir.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

namespace crumple {
namespace {

testing::CliResult bench(const std::string& args) { return testing::run_program(CRUMPLE_EXACT_BENCH, args); }

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), {}};
}

std::string data_option() { return "--data " + testing::data_path("").string(); }

TEST(ExactBench, HelpDescribesEveryOption) {
  const testing::CliResult r = bench("--help");
  EXPECT_EQ(r.status, 0) << r.out;
  for (const char* option : {"--data", "--methods", "--scenes", "--repeat", "--thread-counts", "--tt", "--json", "--md",
                             "--reference", "--threads", "--small-only"}) {
    EXPECT_NE(r.out.find(option), std::string::npos) << option << "\n" << r.out;
  }
}

// Each bad command line fails with a message naming the option (and what is wrong), before
// any scene is loaded ("[1/..." is the first scene's progress line).
TEST(ExactBench, BadCommandLinesFailBeforeAnyWork) {
  const testing::TempDir dir;
  struct Case {
    std::string args, says;
  };
  const std::vector<Case> cases{
      {"--repeat abc", "--repeat"},
      {"--repeat 0", "--repeat"},
      {"--thread-counts '1;x'", "--thread-counts"},
      {"--thread-counts -1", "--thread-counts"},
      {"--scenes 'cloth-funnel;bogus'", "unknown scene 'bogus'"},
      {"--scenes ';'", "scene list is empty"},
      {"--methods 'kdop;kdopp'", "unknown method 'kdopp'"},
      {"--methods 'kdop;kdop:k=7'", "key 'k' expects one of 6 14 18 26"},
      {"--methods 'hash:cell=-1'", "cell must be a number >= 0"},
      {"--json " + (dir / "missing" / "x.json").string(), "does not exist"},
      {"--md " + dir.path().string(), "is a folder"},
      {"--json ''", "the file name is empty"},
      {"--data " + (dir / "missing").string(), "--data"},
      {"--small-only", "requires --reference"},
      {"--reference " + (dir / "r.txt").string() + " --small-only --scenes cloth-funnel --json " +
           (dir / "x.json").string(),
       "excludes"},
      {"--bogus", "--bogus"},
  };
  for (const Case& c : cases) {
    // Options the case leaves out keep a run short (seconds) should the check ever let it
    // through.
    std::string args = c.args;
    for (const auto& [option, value] : {std::pair<std::string, std::string>{"--scenes", "cloth-funnel"},
                                        {"--methods", "kdop"}, {"--repeat", "1"}, {"--thread-counts", "1"}}) {
      if (args.find(option) == std::string::npos && args.find("--reference") == std::string::npos) {
        args += " " + option + " " + value;
      }
    }
    const testing::CliResult r = bench(args);
    EXPECT_NE(r.status, 0) << c.args << "\n" << r.out;
    EXPECT_NE(r.status, -1) << c.args << " did not exit normally\n" << r.out;
    EXPECT_NE(r.out.find(c.says), std::string::npos) << c.args << "\n" << r.out;
    EXPECT_EQ(r.out.find("[1/"), std::string::npos) << c.args << " started running\n" << r.out;
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir.path())) << "a failed command line wrote a file";
}

// One short run: the JSON and markdown tables replace what was there, hold the detector's
// contact counts (the naive reference's for the funnel's second frame: 5,034 VF and 13,683
// EE, tests/data/reference/real_meshes.txt) and leave no temporary file behind.
TEST(ExactBench, WritesBothTablesWhole) {
  const testing::TempDir dir;
  std::ofstream(dir / "t.json") << "stale";
  const testing::CliResult r = bench(data_option() + " --scenes cloth-funnel --methods 'kdop;sap' --repeat 1 " +
                                     "--thread-counts '1;2' --json " + (dir / "t.json").string() + " --md " +
                                     (dir / "t.md").string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("[1/1] cloth-funnel"), std::string::npos) << r.out;
  const std::string json = read_text(dir / "t.json");
  EXPECT_EQ(json.rfind("[\n", 0), 0u) << json;
  EXPECT_EQ(json.substr(json.size() - 2), "]\n") << json;
  EXPECT_EQ(json.find("stale"), std::string::npos);
  const std::string md = read_text(dir / "t.md");
  for (const char* method : {"kdop", "sap"}) {
    for (int threads : {1, 2}) {
      const std::string row_start =
          "| cloth-funnel | vf,ee | `" + std::string(method) + "` | " + std::to_string(threads) + " |";
      const std::size_t at = md.find(row_start);
      ASSERT_NE(at, std::string::npos) << row_start << "\n" << md;
      const std::string row = md.substr(at, md.find('\n', at) - at);
      EXPECT_NE(row.find("| 5034 | 13683 | 0 |"), std::string::npos) << row;
      const std::string record = "\"scene\":\"cloth-funnel\",\"query\":\"vf,ee\",\"method\":\"" + std::string(method) +
                                 "\",\"threads\":" + std::to_string(threads) + ",";
      const std::size_t in_json = json.find(record);
      ASSERT_NE(in_json, std::string::npos) << record << "\n" << json;
      const std::string line = json.substr(in_json, json.find('\n', in_json) - in_json);
      EXPECT_NE(line.find("\"vf\":5034,\"ee\":13683,\"tt\":0}"), std::string::npos) << line;
    }
  }
  std::vector<std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) files.push_back(entry.path().filename().string());
  std::sort(files.begin(), files.end());
  EXPECT_EQ(files, (std::vector<std::string>{"t.json", "t.md"}));
}

}  // namespace
}  // namespace crumple

#endif  // CRUMPLE_EXACT_BENCH

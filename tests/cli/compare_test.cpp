// `crumple compare` and the stochastic method on the command line.
#include <crumple/detect/compare.hpp>
#include <crumple/io/mesh_io.hpp>

#include <gtest/gtest.h>

#include <support/run_cli.hpp>
#include <support/temp_dir.hpp>

#include <filesystem>
#include <string>

namespace crumple {
namespace {

using Output = testing::CliResult;
using testing::run_cli;

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

TEST(CliCompare, BuiltInSequencePrintsFramesAndSummary) {
  const Output r = run_cli("compare --method stochastic:setting=1,variant=vertex --size 16 --frames 6 -j 1");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("against naive"), std::string::npos) << r.out;
  EXPECT_EQ(count(r.out, "\nframe "), 6u) << r.out;
  EXPECT_NE(r.out.find("summary  frames 6"), std::string::npos) << r.out;
  EXPECT_EQ(count(r.out, "false 0 "), 7u) << r.out;  // six frames and the summary
  EXPECT_NE(r.out.find("recall"), std::string::npos);
}

TEST(CliCompare, JsonHasOneObjectPerFrameAndASummary) {
  const Output r = run_cli("compare --method stochastic:variant=direct,seed=3 --size 16 --frames 4 --json -j 1");
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_EQ(count(r.out, "{\"frame\":"), 4u) << r.out;
  EXPECT_EQ(count(r.out, "\"false\":0"), 5u) << r.out;
  EXPECT_NE(r.out.find("\"summary\":true"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"distance_evals\":"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"reference_ms\":"), std::string::npos) << r.out;
}

TEST(CliCompare, FramesFromFilesAndNaiveAgainstItself) {
  const testing::TempDir dir;
  const FoldingSequence seq({.n = 8, .frames = 5, .seed = 1});
  std::string files;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const auto path = dir / std::string("f").append(std::to_string(i)).append(".obj");
    io::write_obj(path, seq.positions(i), seq.mesh().topology().faces());
    files.append(" ").append(path.string());
  }
  const Output r = run_cli("compare --method naive --thickness " + std::to_string(seq.thickness()) + files);
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("f4.obj"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("missed 0  false 0  recall 1.0000  min recall 1.0000"), std::string::npos) << r.out;
}

TEST(CliCompare, BadArgumentsAreOneLineErrors) {
  Output r = run_cli("compare --method stochastic:variant=bogus --size 6 --frames 2");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("variant"), std::string::npos) << r.out;
  r = run_cli("compare --method stochastic:active=0 --size 6 --frames 2");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.out.find("active"), std::string::npos) << r.out;
  r = run_cli("compare --size 1");
  EXPECT_NE(r.status, 0);
}

TEST(CliDetect, StochasticStatisticsInJson) {
  const Output r = run_cli("detect --method stochastic:setting=2,variant=vertex --json");
  ASSERT_EQ(r.status, 0) << r.out;
  for (const char* key : {"\"drawn\":", "\"kept\":", "\"deleted\":", "\"converge_steps\":", "\"distance_evals\":",
                          "\"cache_hits\":", "\"propagation_visits\":", "\"vv_zone_tests\":"}) {
    EXPECT_NE(r.out.find(key), std::string::npos) << key << "\n" << r.out;
  }
  const Output help = run_cli("detect --help");
  EXPECT_NE(help.out.find("stochastic"), std::string::npos);
  EXPECT_NE(help.out.find("setting=0"), std::string::npos) << help.out;
}

}  // namespace
}  // namespace crumple

// The hybrid detector on the command line: its risk report in `detect --json`.
#include <support/run_cli.hpp>

#include <gtest/gtest.h>

#include <string>

namespace crumple {
namespace {

using Output = testing::CliResult;
using testing::run_cli;

TEST(CliDetect, HybridRiskReportInJson) {
  const Output r = run_cli("detect --method hybrid:every=2 --json");
  ASSERT_EQ(r.status, 0) << r.out;
  for (const char* key : {"\"zones\":", "\"zones_examined\":", "\"zones_due_left\":", "\"oldest_zone_age\":",
                          "\"est_missed\":", "\"drawn\":", "\"kept\":"}) {
    EXPECT_NE(r.out.find(key), std::string::npos) << key << "\n" << r.out;
  }
  const Output help = run_cli("detect --help");
  EXPECT_NE(help.out.find("hybrid"), std::string::npos);
  const Output bad = run_cli("detect --method hybrid:leaf=2 --json");
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.out.find("leaf"), std::string::npos) << bad.out;
}

}  // namespace
}  // namespace crumple

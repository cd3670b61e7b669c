// The `kelvin` executable as users meet it: help, the bundled examples, and every
// way a run can go wrong ending with a message, a non-zero exit and kept outputs.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "engine/csv.hpp"
#include "test_support.hpp"

namespace fs = std::filesystem;

namespace {

using kelvin::test::CliRun;
using kelvin::test::run_kelvin;

/// The output directory of a run, removed but not created: kelvin creates it.
fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("kelvin_test_cli_" + name);
  fs::remove_all(dir);
  return dir;
}

const std::string kData = KELVIN_TEST_DATA "/cli/";
const std::string kExamples = KELVIN_SOURCE_DIR "/yaml/examples/";

}  // namespace

TEST(Cli, HelpListsSubcommands) {
  const CliRun r = run_kelvin("--help");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("simulate"), std::string::npos);
  EXPECT_NE(r.out.find("check-material"), std::string::npos);
  const CliRun s = run_kelvin("simulate --help");
  EXPECT_EQ(s.exit_code, 0);
  EXPECT_NE(s.out.find("--end"), std::string::npos);
}

TEST(Cli, MissingScenarioIsAnInputError) {
  const CliRun r =
      run_kelvin("simulate /nonexistent/scenario.yaml -o " + scratch("missing").string());
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("/nonexistent/scenario.yaml"), std::string::npos) << r.out;
}

TEST(Cli, BadValueNamesFileLineColumnAndKey) {
  const CliRun r =
      run_kelvin("simulate " + kData + "bad-density.yaml -o " + scratch("bad").string());
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("bad-density.yaml:4:12: material.density"), std::string::npos) << r.out;
}

TEST(Cli, CantileverExampleRunsAndSags) {
  const fs::path out = scratch("cantilever");
  const CliRun r = run_kelvin("simulate " + kExamples + "cantilever-gravity.yaml --end 0.2 -q -o " +
                              out.string());
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("completed t = 0.2"), std::string::npos) << r.out;
  ASSERT_TRUE(fs::exists(out / "summary.txt"));
  const auto tracks = kelvin::read_marker_tracks((out / "markers.csv").string());
  ASSERT_EQ(tracks.times.size(), 21u);  // 100 Hz over [0, 0.2]
  EXPECT_DOUBLE_EQ(tracks.times.back(), 0.2);
  // Released from rest under gravity, every marker moves down.
  for (int m = 0; m < static_cast<int>(tracks.names.size()); ++m)
    EXPECT_LT(tracks.xyz(3 * m + 2, 20), tracks.xyz(3 * m + 2, 0)) << tracks.names[m];
  bool has_pvd = false;
  for (const auto& f : fs::directory_iterator(out)) has_pvd |= f.path().extension() == ".pvd";
  EXPECT_TRUE(has_pvd);
}

TEST(Cli, NegativelyOrderedTetrahedraAreReorderedWithOneNote) {
  const fs::path out = scratch("dolfin");
  const CliRun r = run_kelvin("simulate " + kData + "dolfin-mesh.yaml -q -o " + out.string());
  EXPECT_EQ(r.exit_code, 0) << r.out;
  const std::string note = "3 of the 6 tetrahedra were listed in negative orientation";
  const auto at = r.out.find(note);
  ASSERT_NE(at, std::string::npos) << r.out;
  EXPECT_EQ(r.out.find(note, at + 1), std::string::npos) << "said more than once:\n" << r.out;
  EXPECT_NE(r.out.find("cube_dolfin_v22.msh"), std::string::npos) << r.out;
}

TEST(Cli, StepLimitStopsWithTimeReachedAndKeepsFrames) {
  const fs::path out = scratch("steplimit");
  const CliRun r = run_kelvin("simulate " + kData + "step-limit.yaml -q -o " + out.string());
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find("t = "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("step"), std::string::npos) << r.out;
  const auto tracks = kelvin::read_marker_tracks((out / "markers.csv").string());
  EXPECT_GT(tracks.times.size(), 1u);
  EXPECT_LT(tracks.times.back(), 1.0);
  EXPECT_TRUE(fs::exists(out / "summary.txt"));
}

TEST(Cli, CollapsingBodyStopsWithMessageAndKeepsFrames) {
  const fs::path out = scratch("collapse");
  const CliRun r = run_kelvin("simulate " + kData + "collapse.yaml -q -o " + out.string());
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find("FAILED at t = "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("the most compressed element is"), std::string::npos) << r.out;
  const auto tracks = kelvin::read_marker_tracks((out / "markers.csv").string());
  EXPECT_GT(tracks.times.size(), 1u);
  EXPECT_LT(tracks.times.back(), 2.0);
}

TEST(Cli, CheckMaterialListsAndChecksBuiltins) {
  const CliRun list = run_kelvin("check-material --list");
  EXPECT_EQ(list.exit_code, 0) << list.out;
  EXPECT_NE(list.out.find("neo-hookean"), std::string::npos);
  EXPECT_NE(list.out.find("power-law"), std::string::npos);
  const CliRun bad = run_kelvin("check-material no-such-model");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.out.find("no-such-model"), std::string::npos);
  const CliRun badset = run_kelvin("check-material neo-hookean --set mu=abc");
  EXPECT_EQ(badset.exit_code, 1) << badset.out;
}

TEST(Cli, CheckMaterialPassesOnEveryBuiltin) {
  const CliRun list = run_kelvin("check-material --list");
  ASSERT_EQ(list.exit_code, 0);
  std::istringstream lines(list.out);
  int models = 0;
  for (std::string line; std::getline(lines, line);) {
    if (line.empty() || line[0] == ' ') continue;  // parameter rows are indented
    const std::string name = line.substr(0, line.find(' '));
    const CliRun r = run_kelvin("check-material " + name);
    EXPECT_EQ(r.exit_code, 0) << r.out;
    EXPECT_NE(r.out.find(" 0 failed"), std::string::npos) << r.out;
    ++models;
  }
  EXPECT_GE(models, 3);
}

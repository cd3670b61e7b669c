// `mpirun -np 2 kelvin-mpi fit | diagnose` against the serial `kelvin`: the same
// files (but for the clock), printed once; errors printed once and every rank ended.
#include <gtest/gtest.h>

#include <regex>

#include "diagnosis_fixture.hpp"
#include "mpi_fixture.hpp"

namespace kelvin {
namespace {

using test::fs::path;

test::CliRun on_two_ranks(const std::string& args) {
  // (No cross-memory attach: containers that forbid ptrace between processes fail it.)
  return test::run_command(
      fmt::format("OMPI_MCA_btl_vader_single_copy_mechanism=none {} --oversubscribe "
                  "--allow-run-as-root -np 2 {} {}",
                  KELVIN_MPIEXEC, KELVIN_MPI_BINARY, args));
}

size_t count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

/// history.csv without its seconds column (the clock is the one thing that differs).
std::string history_without_clock(const path& file) {
  std::string out, line;
  std::istringstream in(test::read_text(file));
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::string cell;
    std::istringstream row(line);
    while (std::getline(row, cell, ',')) cells.push_back(cell);
    if (cells.size() > 9) cells.erase(cells.begin() + 9);
    for (const auto& c : cells) out += c + ",";
    out += "\n";
  }
  return out;
}

TEST(MpiCli, TwoRanksWriteTheSerialFitsFilesAndPrintOnce) {
  const path dir = test::scratch("mpi-cli");
  const std::string scenario = test::write_three_motion_fit(dir, "  max_evaluations: 6\n");
  const test::CliRun serial =
      test::run_kelvin(fmt::format("fit {} -o {}", scenario, (dir / "serial").string()));
  ASSERT_EQ(serial.exit_code, 0) << serial.out;
  const test::CliRun spread =
      on_two_ranks(fmt::format("fit {} -o {}", scenario, (dir / "mpi").string()));
  ASSERT_EQ(spread.exit_code, 0) << spread.out;
  EXPECT_EQ(count(spread.out, "kelvin fit:"), 1u) << spread.out;
  EXPECT_EQ(count(spread.out, "fitted scenario:"), 1u) << spread.out;
  EXPECT_EQ(test::read_text(dir / "serial" / "fitted.yaml"),
            test::read_text(dir / "mpi" / "fitted.yaml"));
  EXPECT_EQ(history_without_clock(dir / "serial" / "history.csv"),
            history_without_clock(dir / "mpi" / "history.csv"));
  EXPECT_EQ(test::read_text(dir / "serial" / "marker-rms.csv"),
            test::read_text(dir / "mpi" / "marker-rms.csv"));
}

TEST(MpiCli, AnErrorEndsEveryRankAndIsPrintedOnce) {
  const path dir = test::scratch("mpi-cli-error");
  const std::string scenario = test::write_three_motion_fit(dir, "  max_evaluations: 6\n");
  // A fit experiment that does not exist.
  std::string text = test::read_text(scenario);
  text.replace(text.find("motion2.yaml"), 12, "missing.yaml");
  test::write_text(dir / "broken.yaml", text);
  const test::CliRun r = on_two_ranks(
      fmt::format("fit {} -o {}", (dir / "broken.yaml").string(), (dir / "out").string()));
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_EQ(count(r.out, "error:"), 1u) << r.out;
  EXPECT_NE(r.out.find("missing.yaml"), std::string::npos) << r.out;
}

TEST(MpiCli, CommandsThatRunOnOneRankAreRefusedOnTwo) {
  const test::CliRun r = on_two_ranks("simulate nothing.yaml");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_EQ(count(r.out, "error:"), 1u) << r.out;
  EXPECT_NE(r.out.find("runs `fit` and `diagnose` across ranks"), std::string::npos) << r.out;
}

/// A diagnosis output with its clock readings and its directory's name taken out.
std::string without_clock(const path& file, const path& outdir) {
  std::string text = test::read_text(file);
  for (size_t at = text.find(outdir.string()); at != std::string::npos;
       at = text.find(outdir.string()))
    text.replace(at, outdir.string().size(), "OUT");
  text = std::regex_replace(text, std::regex(R"("seconds": \{[^}]*\})"), "");
  text = std::regex_replace(text, std::regex(R"("seconds": [-+.0-9eE]+)"), "");
  return std::regex_replace(text, std::regex(R"(Stage times: [^\n]*)"), "");
}

// Drag in the tracks, drag and a clock lag to refit: the screening's runs, the probes,
// the two refits and the missing force go to both ranks, and every number of the
// diagnosis is the serial one.
TEST(MpiCli, TwoRanksDiagnoseAsOneDoes) {
  const path dir = test::scratch("mpi-cli-diagnose");
  const path scenario = test::diagnosis_case(dir, test::kWithDrag, 7, "drag, sync_lag");
  const test::CliRun serial = test::run_kelvin(
      fmt::format("diagnose {} -o {}", scenario.string(), (dir / "serial").string()));
  ASSERT_EQ(serial.exit_code, 0) << serial.out;
  const test::CliRun spread =
      on_two_ranks(fmt::format("diagnose {} -o {}", scenario.string(), (dir / "mpi").string()));
  ASSERT_EQ(spread.exit_code, 0) << spread.out;
  EXPECT_EQ(count(spread.out, "verdict: drag"), 1u) << spread.out;
  EXPECT_EQ(count(spread.out, "stage 3:"), 1u) << spread.out;
  // Both refits' progress is printed, rank 1's when it is gathered.
  EXPECT_EQ(count(spread.out, "drag: train rms"), 1u) << spread.out;
  EXPECT_EQ(count(spread.out, "sync_lag: train rms"), 1u) << spread.out;
  for (const char* file :
       {"diagnosis.json", "report.md", "where-markers.csv", "fitted.yaml", "state/nominal.csv",
        "state/drag.csv", "state/sync_lag.csv", "refits/drag/fitted.yaml",
        "refits/sync_lag/fitted.yaml", "missing-force/body-force.csv"})
    EXPECT_EQ(without_clock(dir / "serial" / file, dir / "serial"),
              without_clock(dir / "mpi" / file, dir / "mpi"))
        << file;
}

}  // namespace
}  // namespace kelvin

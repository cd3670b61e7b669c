// `mpirun -np 2 kelvin-mpi fit` against the serial `kelvin fit`: the same files
// (but for the clock), printed once; errors printed once and every rank ended.
#include <gtest/gtest.h>

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
  EXPECT_NE(r.out.find("runs `fit` across ranks"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace kelvin

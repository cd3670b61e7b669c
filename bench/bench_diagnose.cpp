// One diagnosis case end to end, per stage: the nominal fit, the screening of every
// candidate at it (one forward-sensitivity solve), the refits of the top ones and
// their held-out checks. Prints each stage's wall time and evaluation counts, and
// the screening's cost against the nominal fit's.
//   build/bin/bench_diagnose [--case yaml/examples/diagnosis/V09-sync-lag]
//                            [--max-evaluations 0]
#include <fmt/format.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>

#include "base/error.hpp"
#include "diagnose/diagnosis.hpp"

namespace fs = std::filesystem;
using namespace kelvin;

int main(int argc, char** argv) {
  std::string dir = std::string(KELVIN_SOURCE_DIR) + "/yaml/examples/diagnosis/V09-sync-lag";
  int max_evaluations = 0;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--case"))
      dir = argv[i + 1];
    else if (!std::strcmp(argv[i], "--max-evaluations"))
      max_evaluations = std::atoi(argv[i + 1]);
    else {
      fmt::print(stderr, "unknown option {}\n", argv[i]);
      return 1;
    }
  }
  const std::string out = (fs::temp_directory_path() / "kelvin-bench-diagnose").string();
  fs::remove_all(out);
  DiagnoseOptions o;
  o.max_evaluations = max_evaluations;
  // Flushed per line: a redirected run that is stopped keeps what it printed.
  o.progress = [](const std::string& line) {
    fmt::print("{}\n", line);
    std::fflush(stdout);
  };
  try {
    const Diagnosis d = run_diagnosis((fs::path(dir) / "train.yaml").string(), out, o);
    int refit_evaluations = 0;
    for (const auto& r : d.refits) refit_evaluations += r.evaluations;
    const bool second = d.second_refit.candidate >= 0;
    if (second) refit_evaluations += d.second_refit.evaluations;
    fmt::print("\n{}: verdict {}{}{}\n", fs::path(dir).filename().string(), d.effect,
               d.verdict_where.empty() ? "" : " (" + d.verdict_where[0] + ")",
               d.second_effect.empty() ? "" : ", second effect " + d.second_effect);
    fmt::print("| stage | wall (s) | evaluations |\n|---|---:|---:|\n");
    fmt::print("| nominal fit | {:.1f} | {} |\n", d.seconds.nominal_fit, d.nominal_evaluations);
    fmt::print("| screening ({} candidates) | {:.1f} | 1 sensitivity solve |\n",
               d.candidates.size(), d.seconds.screening);
    fmt::print("| refits ({}) incl. held-out | {:.1f} | {} |\n", d.refits.size() + second,
               d.seconds.refits, refit_evaluations);
    fmt::print("| held-out checks | {:.1f} | |\n", d.seconds.heldout);
    fmt::print("| missing force | {:.1f} | |\n", d.seconds.missing_force);
    fmt::print("| second screening | {:.1f} | |\n", d.seconds.second_screening);
    fmt::print("| total | {:.1f} | |\n", d.seconds.nominal_fit + d.seconds.screening +
                                             d.seconds.refits + d.seconds.missing_force +
                                             d.seconds.second_screening +
                                             d.seconds.learned_correction);
    fmt::print("screening / nominal fit: {:.2f}\n", d.seconds.screening / d.seconds.nominal_fit);
  } catch (const Error& e) {
    fmt::print(stderr, "error: {}\n", e.what());
    return 1;
  }
  return 0;
}

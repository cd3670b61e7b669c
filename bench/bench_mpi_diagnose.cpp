// A diagnosis case across MPI ranks against the same diagnosis on one rank, in one
// run: rank 0 first diagnoses alone (the other ranks wait), then every rank diagnoses
// with the screening's runs, the probes, the refits and the missing force spread over
// them. Prints both wall times, the speed-up, the stage times of each, and whether
// the two came to the same numbers (they must: every spread run is a serial one).
//   mpirun -np 2 build/bin/bench_mpi_diagnose [--case yaml/examples/diagnosis/V10-marker-offset]
//                                             [--max-evaluations 0]
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "base/error.hpp"
#include "diagnose/diagnosis.hpp"
#include "parallel/mpi_communicator.hpp"

namespace fs = std::filesystem;
using namespace kelvin;

namespace {

struct Timed {
  Diagnosis d;
  double seconds = 0;
};

Timed diagnose(const std::string& scenario, const fs::path& out, int max_evaluations) {
  fs::remove_all(out);
  DiagnoseOptions o;
  o.max_evaluations = max_evaluations;
  if (world().root())
    o.progress = [](const std::string& line) {
      fmt::print("{}\n", line);
      std::fflush(stdout);
    };
  const auto t0 = std::chrono::steady_clock::now();
  Timed t;
  t.d = run_diagnosis(scenario, out.string(), o);
  t.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return t;
}

std::string stage_times(const Diagnosis& d) {
  const StageTimes& s = d.seconds;
  return fmt::format(
      "nominal fit {:.0f}, screening {:.0f}, missing force {:.0f}, refits {:.0f} (held-out "
      "{:.0f}), second screening {:.0f} s",
      s.nominal_fit, s.screening, s.missing_force, s.refits, s.heldout, s.second_screening);
}

/// Every number the verdict rests on, equal to the bit.
bool same(const Diagnosis& a, const Diagnosis& b) {
  bool equal = a.effect == b.effect && a.accepted == b.accepted &&
               a.second_effect == b.second_effect &&
               a.second_refit.train.sum_sq == b.second_refit.train.sum_sq &&
               a.nominal_train.sum_sq == b.nominal_train.sum_sq && a.noise.sigma == b.noise.sigma &&
               a.refits.size() == b.refits.size() &&
               a.missing_force.rms_after == b.missing_force.rms_after &&
               a.ranking.order.size() == b.ranking.order.size();
  for (std::size_t k = 0; equal && k < a.ranking.order.size(); ++k)
    equal = a.ranking.order[k].marginal.statistic == b.ranking.order[k].marginal.statistic;
  for (std::size_t k = 0; equal && k < a.refits.size(); ++k)
    equal = a.refits[k].candidate == b.refits[k].candidate &&
            a.refits[k].train.sum_sq == b.refits[k].train.sum_sq &&
            a.refits[k].p == b.refits[k].p && a.refits[k].heldout_drop == b.refits[k].heldout_drop;
  return equal;
}

}  // namespace

int main(int argc, char** argv) {
  MpiRuntime mpi(argc, argv);
  MpiCommunicator world_comm;
  set_world(&world_comm);
  CLI::App app{"a diagnosis case: one rank against all ranks"};
  std::string dir = std::string(KELVIN_SOURCE_DIR) + "/yaml/examples/diagnosis/V10-marker-offset";
  int max_evaluations = 0;
  app.add_option("--case", dir, "a folder with train.yaml");
  app.add_option("--max-evaluations", max_evaluations, "per fit (0: the scenario's)");
  CLI11_PARSE(app, argc, argv);
  Communicator& comm = world();
  const std::string scenario = (fs::path(dir) / "train.yaml").string();
  const fs::path out = fs::temp_directory_path() / "kelvin-bench-mpi-diagnose";
  try {
    Timed alone;
    if (comm.root()) {
      set_world(&serial_communicator());
      alone = diagnose(scenario, out / "alone", max_evaluations);
      set_world(&world_comm);
    }
    comm.all_gather("");  // the others wait while rank 0 diagnoses alone
    const Timed spread = diagnose(scenario, out / "spread", max_evaluations);
    if (!comm.root()) return 0;
    fmt::print("\n{}: verdict {}\n", fs::path(dir).filename().string(), spread.d.effect);
    fmt::print("1 rank   {:8.1f} s   ({})\n", alone.seconds, stage_times(alone.d));
    fmt::print("{} ranks  {:8.1f} s   ({}; the spread stages' figures sum their runs)\n",
               comm.size(), spread.seconds, stage_times(spread.d));
    fmt::print("speed-up {:.2f}×\n", alone.seconds / spread.seconds);
    const bool equal = same(alone.d, spread.d);
    fmt::print("same numbers (verdict, scores, every refit's parameters and misfit): {}\n",
               equal ? "yes" : "NO");
    return equal ? 0 : 1;
  } catch (const std::exception& e) {
    fmt::print(stderr, "error: {}\n", e.what());
    return 1;
  }
}

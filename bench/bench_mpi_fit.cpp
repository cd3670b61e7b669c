// A joint fit of four captured motions across MPI ranks against the same fit on one
// rank, in one run: rank 0 first fits alone (the other ranks wait), then every rank
// fits with the experiments spread over them. Prints both wall times, the speed-up,
// and whether the two fits took the same path to the same parameters (they must:
// FitProblem::evaluate shares results bit for bit).
// The bench bar (bench_bar.hpp, 120 tets) shaken at 17, 21, 25 and 29 Hz along y,
// tracks simulated at rtol 1e-8; λ, μ, ν fitted from 2×/½× off at rtol 1e-6.
//   mpirun -np 2 build/bin/bench_mpi_fit [--duration 1] [--max-evaluations 40]
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>

#include "adjoint/fit_problem.hpp"
#include "base/error.hpp"
#include "bench/bench_bar.hpp"
#include "fit/fit_loop.hpp"
#include "parallel/mpi_communicator.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

namespace fs = std::filesystem;
using namespace kelvin;

namespace {

constexpr int kMotions = 4;

/// The bar shaken at `hz` along y instead of 17.
std::string motion(const std::string& material, double duration, double rtol, double hz,
                   const std::string& tail) {
  std::string text = bench::bar_scenario(
      material, duration, 180, fmt::format("{{ rtol: {}, atol: {} }}", rtol, rtol * 1e-4), tail);
  text.replace(text.find("frequency: 17"), 13, fmt::format("frequency: {}", hz));
  return text;
}

/// Writes the four motions' truth tracks and fit scenarios to dir; returns the first.
std::string write_fit(const fs::path& dir, double duration, int max_evaluations) {
  fs::create_directories(dir);
  const std::string start = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 1.2e6, mu: 1.5e5 }
  viscous: { model: power-law, nu: 40, h: 0.8 })";
  for (int k = 0; k < kMotions; ++k) {
    const double hz = 17 + 4 * k;
    const fs::path truth = dir / fmt::format("truth{}.yaml", k);
    std::ofstream(truth) << motion(bench::kBarTruthMaterial, duration, 1e-8, hz, "");
    SimulationOptions so;
    so.outdir = (dir / fmt::format("truth{}", k)).string();
    const SimulationResult r = run_simulation(load_scenario(truth.string()), so);
    if (!r.completed) throw kelvin::Error("truth simulation failed: " + r.error);
    std::string tail =
        fmt::format("  observed: {}\n", (dir / fmt::format("truth{}", k) / "markers.csv").string());
    if (k == 0) {
      tail += "fit:\n  parameters: [elastic.lambda, elastic.mu, viscous.nu]\n  experiments: [";
      for (int j = 1; j < kMotions; ++j)
        tail += fmt::format("{}motion{}.yaml", j > 1 ? ", " : "", j);
      tail += fmt::format("]\n  max_evaluations: {}\n", max_evaluations);
    }
    std::ofstream(dir / fmt::format("motion{}.yaml", k)) << motion(start, duration, 1e-6, hz, tail);
  }
  return (dir / "motion0.yaml").string();
}

struct Timed {
  FitOutcome out;
  double seconds = 0;
};

Timed fit(const Scenario& s, Communicator& comm) {
  FitProblem problem(s, s.fit.parameters, comm);
  const auto t0 = std::chrono::steady_clock::now();
  Timed t;
  t.out = run_fit(problem, problem.map().initial(), fit_options_of(s));
  t.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return t;
}

}  // namespace

int main(int argc, char** argv) {
  MpiRuntime mpi(argc, argv);
  MpiCommunicator world_comm;
  set_world(&world_comm);
  CLI::App app{"joint fit of four motions: one rank against all ranks"};
  double duration = 1;
  int max_evaluations = 40;
  app.add_option("--duration", duration, "seconds of each motion");
  app.add_option("--max-evaluations", max_evaluations);
  CLI11_PARSE(app, argc, argv);
  Communicator& comm = world();
  const fs::path dir =
      fs::temp_directory_path() / fmt::format("kelvin-bench-mpi-fit-rank{}", comm.rank());
  const Scenario s = load_scenario(write_fit(dir, duration, max_evaluations));
  Timed alone;
  std::vector<double> cost;  // seconds of each motion's Φ + ∇Φ at the start
  if (comm.root()) {
    FitProblem problem(s, s.fit.parameters, serial_communicator());
    GradientOptions g = fit_options_of(s).gradient;
    const Evaluation ev = problem.evaluate(problem.map().initial(), g);
    for (const ExperimentResult& r : ev.experiments) cost.push_back(r.seconds);
    alone = fit(s, serial_communicator());
  }
  comm.all_gather("");  // the others wait (and spin: MPI polls) while rank 0 fits alone
  const Timed spread = fit(s, comm);
  if (!comm.root()) return 0;
  bool same_path = alone.out.history.size() == spread.out.history.size();
  for (size_t i = 0; same_path && i < alone.out.history.size(); ++i)
    same_path = alone.out.history[i].objective == spread.out.history[i].objective;
  const double dp = (alone.out.p - spread.out.p).cwiseAbs().maxCoeff();
  fmt::print("joint fit of {} motions ({} s each, 120 tets), {} evaluations: rms {:.4f} mm\n",
             kMotions, duration, spread.out.history.size(), spread.out.best.rms * 1e3);
  fmt::print("1 rank   {:8.2f} s\n{} ranks  {:8.2f} s   speed-up {:.2f}×\n", alone.seconds,
             comm.size(), spread.seconds, alone.seconds / spread.seconds);
  // What the motions' unequal costs allow: the busiest rank's share under the
  // costliest-first assignment FitProblem makes.
  std::vector<double> sorted = cost, load(comm.size(), 0.0);
  std::sort(sorted.rbegin(), sorted.rend());
  for (double c : sorted) *std::min_element(load.begin(), load.end()) += c;
  double total = 0;
  for (double c : cost) total += c;
  fmt::print("Φ + ∇Φ per motion at the start (s):");
  for (double c : cost) fmt::print(" {:.2f}", c);
  fmt::print("; the busiest rank's share bounds the speed-up at {:.2f}×\n",
             total / *std::max_element(load.begin(), load.end()));
  fmt::print("same path (every Φ equal): {}; max |Δp| of the fitted parameters: {:g}\n",
             same_path ? "yes" : "NO", dp);
  return same_path && dp == 0 ? 0 : 1;
}

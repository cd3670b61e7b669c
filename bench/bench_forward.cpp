// Forward-simulation cost of the bundled foam cylinder (yaml/examples/foam-cylinder.yaml)
// at three mesh resolutions (about 1k, 8k and 30k tetrahedra), 1 s of simulated motion.
// Prints wall time, steps, time per step and the share of time spent assembling
// Jacobians, factorising (KLU) and solving. Asserts nothing about time.
//
//   build/bin/bench_forward [--repeat N] [--sizes h1,h2,...]
#include <fmt/format.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "bench/foam_cylinder.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

using namespace kelvin;
using kelvin::bench::remeshed;

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

}  // namespace

int main(int argc, char** argv) {
  int repeat = 3;
  std::vector<double> sizes = {0.01, 0.004, 0.0023};  // 1.4k, 8.1k, 25k tetrahedra
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--repeat") && i + 1 < argc)
      repeat = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--sizes") && i + 1 < argc) {
      sizes.clear();
      for (char* tok = std::strtok(argv[++i], ","); tok; tok = std::strtok(nullptr, ","))
        sizes.push_back(std::atof(tok));
    }
  }
  const Scenario base = load_scenario(KELVIN_SOURCE_DIR "/yaml/examples/foam-cylinder.yaml");
  const std::string outdir =
      (std::filesystem::temp_directory_path() / "kelvin-bench-forward").string();
  fmt::print("foam cylinder, {} s simulated, rtol {:g}, median of {} runs\n", 1.0, base.solver.rtol,
             repeat);
  fmt::print("{:>8} {:>7} {:>7} {:>9} {:>7} {:>10} {:>6} {:>8} {:>8} {:>8} {:>8}\n", "h [mm]",
             "tets", "dofs", "wall [s]", "steps", "ms/step", "order", "jac %", "factor %",
             "solve %", "resid %");
  for (double h : sizes) {
    const Scenario s = remeshed(base, h);
    std::vector<double> wall, jac, setup, solve, resid;
    SimulationResult last;
    for (int r = 0; r < repeat; ++r) {
      SimulationOptions opt;
      opt.outdir = outdir;
      last = run_simulation(s, opt);
      if (!last.completed) {
        fmt::print("h = {}: run failed: {}\n", h, last.error);
        return 1;
      }
      wall.push_back(last.wall_seconds);
      jac.push_back(last.stats.jacobian_seconds / last.wall_seconds);
      setup.push_back(last.stats.setup_seconds / last.wall_seconds);
      solve.push_back(last.stats.solve_seconds / last.wall_seconds);
      resid.push_back(last.stats.residual_seconds / last.wall_seconds);
    }
    int clamped_nodes = 0;
    for (const auto& c : s.clamps) clamped_nodes += static_cast<int>(c.nodes.size());
    fmt::print(
        "{:8.2f} {:7d} {:7d} {:9.3f} {:7d} {:10.3f} {:6.2f} {:8.1f} {:8.1f} {:8.1f} {:8.1f}\n",
        1e3 * h, s.mesh.num_tets(), 3 * (s.mesh.num_nodes() - clamped_nodes), median(wall),
        last.stats.steps, 1e3 * median(wall) / last.stats.steps, last.stats.mean_order(),
        100 * median(jac), 100 * median(setup), 100 * median(solve), 100 * median(resid));
  }
  std::filesystem::remove_all(outdir);
  return 0;
}

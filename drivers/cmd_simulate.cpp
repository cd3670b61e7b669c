#include <fmt/format.h>

#include <filesystem>

#include "base/error.hpp"
#include "drivers/commands.hpp"
#include "materials/crash_report.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

namespace kelvin {

void register_simulate(CLI::App& app, int& exit_code) {
  struct Args {
    std::string scenario, outdir;
    bool quiet = false;
    double end = 0;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "simulate",
      "Run a forward simulation of a scenario: marker trajectories (markers.csv), ParaView "
      "frames (.vtu + .pvd) and a run summary (summary.txt) in the output directory.");
  cmd->add_option("scenario", args->scenario, "scenario YAML file")->required();
  cmd->add_option("-o,--output", args->outdir,
                  "output directory (default: <scenario name>-out in the current directory)");
  cmd->add_option("--end", args->end, "simulate up to this time (s) instead of time.end")
      ->check(positive_number());
  cmd->add_flag("-q,--quiet", args->quiet, "print only the summary line");
  cmd->callback([args, &exit_code] {
    Scenario scenario;
    try {
      scenario = load_scenario(args->scenario);
      print_notes(scenario);
      if (args->end > 0) {
        scenario.time.end = args->end;
        if (const std::string why = time_span_problem(scenario.time); !why.empty())
          throw Error(fmt::format("--end {}: {}", args->end, why));
        for (const auto& c : scenario.clamps)
          if (c.motion->end_time() < args->end)
            throw Error(fmt::format("--end {}: the motion of clamp '{}' ends at t = {} s",
                                    args->end, c.name, c.motion->end_time()));
      }
    } catch (const Error& e) {
      fmt::print(stderr, "error: {}\n", e.what());
      exit_code = kExitInputError;
      return;
    }
    const std::string outdir = args->outdir.empty()
                                   ? std::filesystem::path(args->scenario).stem().string() + "-out"
                                   : args->outdir;
    if (const std::string why = prepare_output_dir(outdir); !why.empty()) {
      fmt::print(stderr, "error: {}\n", why);
      exit_code = kExitInputError;
      return;
    }
    if (!args->quiet)
      fmt::print("kelvin simulate: {} ({} nodes, {} tetrahedra) → {}\n", scenario.name,
                 scenario.mesh.num_nodes(), scenario.mesh.num_tets(), outdir);
    report_crashes(fmt::format("the frames written so far are in {}", outdir).c_str());
    SimulationOptions options;
    options.outdir = outdir;
    options.interrupt = &g_interrupted;
    options.progress = !args->quiet;
    try {
      const SimulationResult r = run_simulation(scenario, options);
      fmt::print("{}\n", r.summary());
      std::fflush(stdout);
      if (!r.completed) {
        if (!r.error.empty()) fmt::print(stderr, "error: {}\n", r.error);
        fmt::print(stderr, "outputs up to t = {:.6g} s are in {}\n", r.t_reached, outdir);
        exit_code = r.interrupted ? kExitInterrupted : kExitRunFailed;
      }
    } catch (const Error& e) {
      fmt::print(stderr, "error: {}\n", e.what());
      exit_code = kExitRunFailed;
    }
  });
}

}  // namespace kelvin

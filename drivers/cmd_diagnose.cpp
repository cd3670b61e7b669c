// `kelvin diagnose`: where the sim-to-real gap of a nominal model lies, which
// unmodelled effect causes it, and how far it shrinks once that effect is added.
#include <fmt/format.h>

#include <chrono>
#include <filesystem>

#include "base/communicator.hpp"
#include "base/error.hpp"
#include "diagnose/diagnosis.hpp"
#include "diagnose/diagnosis_outputs.hpp"
#include "drivers/commands.hpp"
#include "materials/crash_report.hpp"

namespace kelvin {
namespace {

struct DiagnoseArgs {
  std::string scenario, outdir;
  int max_evaluations = 0;
  bool resume = false, quiet = false;
};

/// Prints an error every rank met alike once (by rank 0).
void print_error(const std::string& message) {
  if (world().root()) fmt::print(stderr, "error: {}\n", message);
}

int run(const DiagnoseArgs& args) {
  // Under MPI every rank runs the diagnosis; its independent runs (the screening's,
  // the probes, the refits, the missing force) are spread over the ranks and shared,
  // so all take the same path. Rank 0 prints and writes the outputs.
  Communicator& comm = world();
  const std::string outdir =
      args.outdir.empty() ? std::filesystem::path(args.scenario).stem().string() + "-diagnosis"
                          : args.outdir;
  if (const std::string why = first_message(comm, comm.root() ? prepare_output_dir(outdir) : "");
      !why.empty()) {
    print_error(why);
    return kExitInputError;
  }
  // Every rank reads the scenarios; one that cannot ends them all, with its message.
  std::string failed;
  try {
    load_scenario(args.scenario);
    for (const std::string& path : load_diagnose_settings(args.scenario).validate)
      load_scenario(path);
  } catch (const Error& e) {
    failed = e.what();
  }
  if (const std::string why = first_message(comm, failed); !why.empty()) {
    print_error(why);
    return kExitInputError;
  }
  report_crashes(fmt::format("the stages done so far are in {}; continue with: kelvin diagnose "
                             "{} -o {} --resume",
                             outdir, args.scenario, outdir)
                     .c_str());
  DiagnoseOptions o;
  o.resume = args.resume;
  o.max_evaluations = args.max_evaluations;
  o.interrupt = &g_interrupted;
  if (!args.quiet && comm.root())
    // A stage's first line says when it began, so the log shows where the time went.
    o.progress = [start = std::chrono::steady_clock::now()](const std::string& line) {
      if (line.rfind("stage ", 0) == 0)
        fmt::print(
            "[{:.1f} min] ",
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() / 60);
      fmt::print("{}\n", line);
      std::fflush(stdout);
    };
  Diagnosis d;
  try {
    d = run_diagnosis(args.scenario, outdir, o);
  } catch (const Error& e) {
    print_error(e.what());
    return kExitInputError;
  } catch (const std::exception& e) {  // a file that could not be written, say
    print_error(e.what());
    return kExitRunFailed;
  }
  std::string report;
  failed.clear();
  if (comm.root()) try {
      report = write_diagnosis_outputs(d);
    } catch (const std::exception& e) {
      failed = e.what();
    }
  if (const std::string why = first_message(comm, failed); !why.empty()) {
    print_error(why);
    return kExitRunFailed;
  }
  fmt::print("verdict: {}{}{}; report: {}\n", d.effect,
             d.verdict_where.empty() ? "" : " (" + d.verdict_where[0] + ")",
             d.second_effect.empty() ? "" : ", and a second effect: " + d.second_effect, report);
  if (d.interrupted) {
    if (comm.root())
      fmt::print(stderr, "interrupted; continue with: kelvin diagnose {} -o {} --resume\n",
                 args.scenario, outdir);
    return kExitInterrupted;
  }
  return kExitOk;
}

}  // namespace

void register_diagnose(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<DiagnoseArgs>();
  CLI::App* cmd = app.add_subcommand(
      "diagnose",
      "Diagnose the gap between a fitted nominal model and its captured motion: where the "
      "residual lies, which candidate effect explains it (screened at the nominal fit, the top "
      "ones refitted and checked on the held-out motions of diagnose.validate), and how far the "
      "misfit shrinks with it. Writes diagnosis.json, report.md with SVG plots, "
      "where-markers.csv and fitted.yaml of the accepted model.");
  cmd->add_option("scenario", args->scenario, "scenario YAML file with a fit section")->required();
  cmd->add_option("-o,--output", args->outdir,
                  "output directory (default: <scenario stem>-diagnosis)");
  cmd->add_flag("--resume", args->resume,
                "reuse the fits an interrupted diagnosis in the output directory finished");
  cmd->add_option("--max-evaluations", args->max_evaluations,
                  "overrides fit.max_evaluations for every fit of the diagnosis")
      ->check(positive_number());
  cmd->add_flag("-q,--quiet", args->quiet, "print only the verdict");
  cmd->callback([args, &exit_code] {
    try {
      exit_code = run(*args);
    } catch (const std::exception& e) {
      fmt::print(stderr, "error: {}\n", e.what());
      exit_code = kExitRunFailed;
    }
  });
}

}  // namespace kelvin

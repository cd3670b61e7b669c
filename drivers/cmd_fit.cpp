// `kelvin fit`: NLopt parameter estimation from captured marker motion, with the
// history and resume state written as it goes and the outputs written at the end
// (also after SIGINT/SIGTERM, from the best parameters so far).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "base/error.hpp"
#include "drivers/commands.hpp"
#include "fit/fit_loop.hpp"
#include "fit/fit_outputs.hpp"
#include "fit/fit_state.hpp"
#include "fit/stiffness_scan.hpp"
#include "materials/crash_report.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {
namespace {

struct FitArgs {
  std::string scenario, outdir, algorithm, gradient;
  int max_evaluations = 0;
  double max_seconds = -1;
  bool resume = false, quiet = false;
};

std::string progress_line(const FitRecord& r) {
  if (!r.ok)
    return fmt::format("  eval {:4d}  simulation failed, backing off: {}", r.evaluation, r.error);
  return fmt::format(
      "iter {:4d}  eval {:4d}  objective {:.6e}  rms {:8.4f} mm  |grad| {:.3e}  {:7.1f} s",
      r.iteration, r.evaluation, r.objective, r.rms * 1e3, r.gradient_norm, r.seconds);
}

FitOptions fit_options(const Scenario& scenario, const FitArgs& args) {
  FitOptions o = fit_options_of(scenario);
  if (!args.algorithm.empty()) o.algorithm = args.algorithm;
  if (!args.gradient.empty()) o.gradient.method = parse_gradient_method(args.gradient);
  if (o.algorithm == "bobyqa") o.gradient.method = GradientMethod::kNone;
  o.gradient.interrupt = &g_interrupted;
  if (args.max_evaluations > 0) o.max_evaluations = args.max_evaluations;
  if (args.max_seconds >= 0) o.max_seconds = args.max_seconds;
  return o;
}

/// Prints an error every rank met alike once (by rank 0).
void print_error(const std::string& message) {
  if (world().root()) fmt::print(stderr, "error: {}\n", message);
}

int run(const FitArgs& args) {
  // Under MPI every rank runs the fit (FitProblem::evaluate shares the experiments'
  // results, so all take the same path); rank 0 writes the files and prints.
  Communicator& comm = world();
  Scenario scenario;
  std::unique_ptr<FitProblem> problem;
  FitOptions options;
  std::string failed;
  try {
    scenario = load_scenario(args.scenario);
    print_notes(scenario);
    if (!scenario.fit.present)
      fmt::print("note: {} has no fit section; fitting every material parameter, global\n",
                 scenario.path);
    problem = std::make_unique<FitProblem>(scenario, scenario.fit.parameters);
    options = fit_options(scenario, args);
    // A clock offset or marker offsets fitted with log moduli differ in scale by orders
    // of magnitude: unscaled, V09's lag stayed at 2e-7 s while the moduli moved.
    options.gauss_newton_start = !problem->map().observation_blocks().empty() &&
                                 problem->map().size() <= kGaussNewtonStartParameters &&
                                 options.algorithm == "lbfgs";
  } catch (const Error& e) {
    failed = e.what();
  }
  // A rank that could not read a file ends every rank, with its message.
  if (const std::string why = first_message(comm, failed); !why.empty()) {
    print_error(why);
    return kExitInputError;
  }
  const std::string outdir = args.outdir.empty()
                                 ? std::filesystem::path(args.scenario).stem().string() + "-fit"
                                 : args.outdir;
  if (const std::string why = first_message(comm, comm.root() ? prepare_output_dir(outdir) : "");
      !why.empty()) {
    print_error(why);
    return kExitInputError;
  }
  const std::string state_path = (std::filesystem::path(outdir) / "fit-state.yaml").string();
  // --max-evaluations 1 is spent already on resuming: the outputs come from the best.
  report_crashes(fmt::format("the best parameters so far are in {} (saved after every "
                             "evaluation); write fitted.yaml and the report from them with: "
                             "kelvin fit {} -o {} --resume --max-evaluations 1",
                             state_path, args.scenario, outdir)
                     .c_str());
  const ParameterMap& map = problem->map();

  FitState state;
  state.scenario = std::filesystem::absolute(args.scenario).string();
  for (int j = 0; j < map.size(); ++j) state.labels.push_back(map.label(j));
  state.start = map.initial();
  state.best = state.start;
  FitHistoryFile history((std::filesystem::path(outdir) / "history.csv").string(), map);
  Eigen::VectorXd p0 = state.start;
  try {
    if (args.resume) {
      const FitState saved = read_fit_state(state_path);
      if (saved.labels != state.labels)
        throw Error(fmt::format(
            "{}: saved for other parameters ({} entries, first '{}'); the "
            "scenario's fit section changed since — start without --resume",
            state_path, saved.labels.size(), saved.labels.empty() ? "" : saved.labels[0]));
      // An edited or damaged state must not carry the fit outside its bounds.
      const Eigen::VectorXd lo = map.lower(), hi = map.upper();
      for (int j = 0; j < map.size(); ++j)
        if (!std::isfinite(saved.best[j]) || saved.best[j] < lo[j] || saved.best[j] > hi[j] ||
            !(std::abs(map.value(saved.best, j)) < 1e300))
          throw Error(fmt::format(
              "{}: parameters[{}].best: {} = {:g} ({}) is outside its bounds; start without "
              "--resume",
              state_path, j, map.label(j), saved.best[j],
              map.is_log(j) ? "its logarithm" : "model units"));
      if (!std::isfinite(saved.best_objective) || !std::isfinite(saved.best_rms) ||
          saved.evaluations < 0 || saved.iterations < 0 || saved.failures < 0 ||
          !(saved.seconds >= 0) || !std::isfinite(saved.seconds))
        throw Error(
            fmt::format("{}: the saved counters or best values are not finite and "
                        "non-negative; start without --resume",
                        state_path));
      if (comm.root()) history.load_existing(saved.evaluations);
      state = saved;
      p0 = saved.best;
      options.first_evaluation = saved.evaluations;
      options.first_iteration = saved.iterations;
      options.seconds_offset = saved.seconds;
      // A coarse stage goes on as the first stage; tightened tolerances stay.
      options.start_tolerance_scale = std::max(saved.tolerance_scale, 1.0);
      options.gradient.tolerance_scale = std::min(saved.tolerance_scale, 1.0);
    }
  } catch (const Error& e) {
    failed = e.what();
  }
  if (const std::string why = first_message(comm, failed); !why.empty()) {
    print_error(why);
    return kExitInputError;
  }

  if (!args.quiet)
    fmt::print("kelvin fit: {} — {} parameters, {} experiment(s), {} with {} gradients → {}\n",
               scenario.name, map.size(), problem->num_experiments(), options.algorithm,
               to_string(options.gradient.method), outdir);
  if (!args.quiet && args.resume) {
    const double scale = options.gradient.tolerance_scale * options.start_tolerance_scale;
    if (scale != 1)
      fmt::print("resuming at solver tolerances {:g}× the scenario's, where the fit was\n", scale);
  }
  const auto record = [&](const FitRecord& r) {
    history.append(r);
    state.evaluations = r.evaluation;
    state.iterations = r.iteration;
    state.seconds = r.seconds;
    state.tolerance_scale = r.tolerance_scale;
    if (!r.ok) ++state.failures;
    if (r.accepted) {
      state.best = r.p;
      state.best_objective = r.objective;
      state.best_rms = r.rms;
    }
    write_fit_state(state_path, state);
    if (!args.quiet && (r.accepted || !r.ok)) fmt::print("{}\n", progress_line(r));
    std::fflush(stdout);
  };
  options.on_evaluation = [&](const FitRecord& r) {
    if (comm.size() == 1) return record(r);
    // Rank 0 writes; a write that fails there (a full disk) ends every rank.
    std::string failed;
    if (comm.root()) try {
        record(r);
      } catch (const Error& e) {
        failed = e.what();
      }
    if (const std::string why = first_message(comm, failed); !why.empty()) throw Error(why);
  };
  options.on_progress = [&](const std::string& line) {
    if (!args.quiet) fmt::print("{}\n", line);
  };

  if (!args.resume && scenario.fit.start_scan == "stiffness") {
    const StiffnessScan scan = scan_stiffness(*problem, p0, options, options.on_progress);
    if (scan.entries.empty()) {
      if (!args.quiet) fmt::print("fit.start_scan: no elastic modulus is fitted; no scan\n");
    } else {
      if (!args.quiet)
        fmt::print("starting at ×{:.3g} of the scenario's moduli (the scan's best)\n", scan.scale);
      p0 = scan.p;
    }
    if (scan.interrupted) {
      if (comm.root())
        fmt::print(stderr, "interrupted during the stiffness scan; nothing fitted yet\n");
      return kExitInterrupted;
    }
  }

  FitSummary summary;
  summary.outdir = outdir;
  summary.start = state.start;
  summary.algorithm = options.algorithm;
  summary.gradient_method = to_string(options.gradient.method);
  try {
    const FitOutcome out = run_fit(*problem, p0, options);
    summary.best = out.best.evaluation ? out.p : state.best;
    summary.stop_reason = out.stop_reason;
    summary.uncertainty = out.uncertainty;
    // Agreed: a signal after the fit's last evaluation (during its standard errors,
    // say) must skip the L-curve on every rank or on none.
    summary.interrupted =
        out.interrupted || !first_message(comm, g_interrupted ? "interrupted" : "").empty();
    if (!scenario.fit.lcurve.empty() && !summary.interrupted) {
      if (!args.quiet) fmt::print("L-curve over {} values of gamma\n", scenario.fit.lcurve.size());
      summary.lcurve = run_lcurve(*problem, summary.best, scenario.fit.lcurve, options);
    }
    summary.interrupted = summary.interrupted || g_interrupted;
  } catch (const Error& e) {
    // Whatever was accepted so far is in fit-state.yaml and history.csv already.
    print_error(fmt::format("{}\nbest parameters so far are in {}", e.what(), state_path));
    return kExitRunFailed;
  }
  // The other ranks' part is done: rank 0 simulates the outputs' tracks alone (it
  // holds every experiment's plan, so they come out as a serial run's).
  if (!comm.root()) return summary.interrupted ? kExitInterrupted : kExitOk;
  problem->evaluate_alone();
  summary.history = history.records();
  summary.evaluations = state.evaluations;
  summary.failures = state.failures;
  summary.seconds = state.seconds;
  if (!args.quiet)
    fmt::print("{} after {} evaluations ({} failed simulations){}\n", summary.stop_reason,
               state.evaluations, state.failures,
               summary.interrupted ? "; writing the best parameters so far" : "");
  try {
    const std::string report = write_fit_outputs(*problem, summary, &g_interrupted);
    fmt::print("rms {:.4f} mm → {:.4f} mm; fitted scenario: {}; report: {}\n",
               summary.history.empty() ? 0.0 : summary.history.front().rms * 1e3,
               state.best_rms * 1e3, (std::filesystem::path(outdir) / "fitted.yaml").string(),
               report);
  } catch (const Error& e) {
    fmt::print(stderr, "error: {}\n", e.what());
    return kExitRunFailed;
  }
  if (summary.interrupted) {
    fmt::print(stderr, "interrupted; continue with: kelvin fit {} -o {} --resume\n", args.scenario,
               outdir);
    return kExitInterrupted;
  }
  return kExitOk;
}

}  // namespace

void register_fit(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<FitArgs>();
  CLI::App* cmd = app.add_subcommand(
      "fit",
      "Fit the material parameters of a scenario's fit section to its captured marker tracks "
      "(and those of fit.experiments) with NLopt. Writes fitted.yaml (runnable by kelvin "
      "simulate), history.csv, fit-state.yaml, marker-rms.csv, report.md with SVG plots, and "
      "parameter fields as VTU when they vary over the body.");
  cmd->add_option("scenario", args->scenario, "scenario YAML file with observed marker tracks")
      ->required();
  cmd->add_option("-o,--output", args->outdir,
                  "output directory (default: <scenario stem>-fit in the current directory)");
  cmd->add_flag("--resume", args->resume,
                "continue from the output directory's fit-state.yaml (best parameters and "
                "counters of an interrupted or exhausted fit)");
  cmd->add_option("--max-evaluations", args->max_evaluations,
                  "overrides fit.max_evaluations (counted over resumed runs too)")
      ->check(positive_number());
  cmd->add_option("--max-seconds", args->max_seconds, "overrides fit.max_seconds")
      ->check(positive_number(true));
  cmd->add_option("--algorithm", args->algorithm, "overrides fit.algorithm")
      ->check(CLI::IsMember({"lbfgs", "mma", "slsqp", "bobyqa"}));
  cmd->add_option("--gradient", args->gradient, "overrides fit.gradient")
      ->check(CLI::IsMember({"adjoint", "forward", "none"}));
  cmd->add_flag("-q,--quiet", args->quiet, "print only the final line");
  cmd->callback([args, &exit_code] {
    try {
      exit_code = run(*args);
    } catch (const std::exception& e) {
      // Errors are reported where they arise; this is the last line of defence.
      print_error(e.what());
      exit_code = kExitRunFailed;
    }
  });
}

}  // namespace kelvin

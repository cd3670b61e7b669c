// `kelvin gradcheck`: adjoint vs forward sensitivities vs finite differences, and a
// Taylor test, for the parameter map of a scenario's fit section.
#include <fmt/format.h>

#include "adjoint/gradient_check.hpp"
#include "base/error.hpp"
#include "drivers/commands.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

void register_gradcheck(CLI::App& app, int& exit_code) {
  struct Args {
    std::string scenario;
    double end = 0, rtol = 1e-8, atol = 1e-12, tolerance = 1e-5, fd_tolerance = 1e-3;
    double fd_step = GradientCheckOptions{}.fd_step;
    double taylor_h0 = GradientCheckOptions{}.taylor_h0;
    double segment = 0;
    long checkpoint_steps = 0;
    unsigned seed = 1;
    bool no_forward = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "gradcheck",
      "Check dΦ/dp three ways (adjoint, forward sensitivities, central finite differences) "
      "and by a Taylor test along a random direction, for the parameters of the scenario's fit "
      "section (or every material parameter, global). Exits 2 when they disagree.");
  cmd->add_option("scenario", args->scenario, "scenario YAML file with observed marker tracks")
      ->required();
  cmd->add_option("--end", args->end, "simulate up to this time (s) instead of time.end")
      ->check(positive_number());
  cmd->add_option("--rtol", args->rtol, "IDAS relative tolerance for the check")
      ->capture_default_str();
  cmd->add_option("--atol", args->atol, "IDAS absolute position tolerance (m)")
      ->capture_default_str();
  cmd->add_option("--tolerance", args->tolerance, "allowed adjoint vs forward relative error")
      ->capture_default_str();
  cmd->add_option("--fd-tolerance", args->fd_tolerance,
                  "allowed adjoint vs finite-difference relative error")
      ->capture_default_str();
  cmd->add_option("--segment", args->segment, "adjoint segment length (s); 0 = automatic");
  cmd->add_option("--checkpoint-steps", args->checkpoint_steps,
                  "most IDAS steps one adjoint segment stores");
  cmd->add_option("--seed", args->seed, "seed of the random direction")->capture_default_str();
  cmd->add_option("--fd-step", args->fd_step,
                  "central-difference step (relative for log parameters); long oscillatory "
                  "runs need smaller steps, their misfit turning over on a scale of 1/(phase "
                  "sensitivity)")
      ->capture_default_str()
      ->check(positive_number());
  cmd->add_option("--taylor-step", args->taylor_h0,
                  "first step h of the Taylor test along the random direction (halved six "
                  "times); when fewer than three levels rise above Φ's integration noise, "
                  "larger steps (doubling, up to 1) are added")
      ->capture_default_str()
      ->check(positive_number());
  cmd->add_flag("--no-forward", args->no_forward,
                "skip forward sensitivities (their cost grows with the parameter count)");
  cmd->callback([args, &exit_code] {
    Scenario scenario;
    std::unique_ptr<FitProblem> problem;
    try {
      scenario = load_scenario(args->scenario);
      print_notes(scenario);
      if (args->end > 0) scenario.time.end = std::min(scenario.time.end, args->end);
      scenario.solver.rtol = args->rtol;
      scenario.solver.atol = args->atol;
      problem = std::make_unique<FitProblem>(scenario, scenario.fit.parameters);
    } catch (const Error& e) {
      fmt::print(stderr, "error: {}\n", e.what());
      exit_code = kExitInputError;
      return;
    }
    const ParameterMap& map = problem->map();
    GradientCheckOptions o;
    o.seed = args->seed;
    o.fd_step = args->fd_step;
    o.taylor_h0 = args->taylor_h0;
    o.forward = !args->no_forward;
    o.adjoint.segment = args->segment;
    o.adjoint.checkpoint_steps = args->checkpoint_steps;
    o.adjoint.interrupt = &g_interrupted;
    const Eigen::VectorXd p = map.initial();
    fmt::print(
        "kelvin gradcheck: {} — {} parameters, {} experiment(s), t ∈ [0, {:g}] s, rtol {:g}\n",
        scenario.name, map.size(), problem->num_experiments(), scenario.time.end, args->rtol);
    const GradientCheckReport r = check_gradient(*problem, p, o);
    if (!r.ok) {
      fmt::print(stderr, "error: {}\n", r.error);
      exit_code = g_interrupted ? kExitInterrupted : kExitRunFailed;
      return;
    }
    fmt::print("Φ = {:.10g} m²s, RMS = {:.4g} mm\n", r.phi, 1e3 * r.rms);
    fmt::print("{:<32} {:>10} {:>16} {:>16} {:>16} {:>10} {:>10}\n", "parameter", "value",
               "adjoint", "forward", "central FD", "adj/fwd", "adj/FD");
    for (int j = 0; j < map.size(); ++j) {
      const bool has_fd = j < static_cast<int>(r.finite_difference.size());
      if (!has_fd && j >= 12) {
        fmt::print("… {} more parameters (directional check below covers them)\n", map.size() - j);
        break;
      }
      const double a = r.adjoint[j];
      auto rel = [&](double b) {
        return std::abs(a - b) / std::max({std::abs(a), std::abs(b), 1e-300});
      };
      fmt::print("{:<32} {:>10.4g} {:>16.9g} {:>16} {:>16} {:>10} {:>10}\n", map.label(j),
                 map.value(p, j), a, r.forward.size() ? fmt::format("{:.9g}", r.forward[j]) : "-",
                 has_fd ? fmt::format("{:.9g}", r.finite_difference[j]) : "-",
                 r.forward.size() ? fmt::format("{:.1e}", rel(r.forward[j])) : "-",
                 has_fd ? fmt::format("{:.1e}", rel(r.finite_difference[j])) : "-");
    }
    fmt::print("direction δ (seed {}): adjoint {:.9g}, forward {}, central FD {:.9g}\n", args->seed,
               r.directional_adjoint,
               r.forward.size() ? fmt::format("{:.9g}", r.directional_forward) : "-",
               r.directional_fd);
    fmt::print(
        "Taylor test r(h) = Φ(p+hδ) − Φ(p) − h∇Φ·δ, and 8 r(h/2) − r(h) (its h³ term "
        "cancelled):\n");
    for (size_t k = 0; k < r.h.size(); ++k) {
      fmt::print("  h = 2^{:<3.0f} |r| {:.4e}", std::log2(r.h[k]), r.remainder[k]);
      if (k < r.corrected.size()) fmt::print("  |8 r(h/2) − r(h)| {:.4e}", r.corrected[k]);
      if (k > 0 && k < r.corrected.size() && r.corrected[k] > 0 && r.corrected[k - 1] > 0)
        fmt::print("  rate {:.3f}", std::log2(r.corrected[k - 1] / r.corrected[k]));
      if (k < r.corrected.size() && static_cast<int>(k) >= r.resolved_levels)
        fmt::print("  (within 100× of Φ's integration noise)");
      fmt::print("\n");
    }
    fmt::print(
        "median rate {:.3f} over the {} levels above 100× Φ's integration noise {:.3e} (2 for "
        "an exact gradient)\n",
        r.slope, r.resolved_levels, r.noise);
    if (r.added_levels)
      fmt::print(
          "(the sequence began at 2^{:.0f} and grew by {} larger step{}: fewer than three levels "
          "cleared the noise)\n",
          std::log2(args->taylor_h0), r.added_levels, r.added_levels > 1 ? "s" : "");
    fmt::print(
        "wall time: Φ alone {:.3g} s, Φ + adjoint gradient {:.3g} s ({:.2f}×){}\n",
        r.seconds_forward_only, r.seconds_adjoint, r.seconds_adjoint / r.seconds_forward_only,
        r.forward.size() ? fmt::format(", forward sensitivities {:.3g} s ({:.2f}×)",
                                       r.seconds_forward_sensitivities,
                                       r.seconds_forward_sensitivities / r.seconds_forward_only)
                         : "");
    fmt::print(
        "steps: Φ alone {}; with the adjoint {} forward and {} backward ({} Newton matrices)\n",
        r.phi_stats.steps, r.adjoint_forward_stats.steps, r.adjoint_backward_stats.steps,
        r.adjoint_backward_stats.jacobian_evals);
    std::vector<std::string> failures;
    if (r.forward.size() && !(r.adjoint_vs_forward <= args->tolerance))
      failures.push_back(fmt::format("adjoint and forward differ by {:.2e} > {:.1e}",
                                     r.adjoint_vs_forward, args->tolerance));
    if (!(r.adjoint_vs_fd <= args->fd_tolerance))
      failures.push_back(fmt::format("adjoint and finite differences differ by {:.2e} > {:.1e}",
                                     r.adjoint_vs_fd, args->fd_tolerance));
    if (!(r.slope >= 1.8 && r.slope <= 2.2))
      failures.push_back(fmt::format("Taylor rate {:.3f} is not 2", r.slope));
    if (failures.empty()) {
      fmt::print("PASS: the gradient methods agree\n");
    } else {
      for (const auto& f : failures) fmt::print("FAIL: {}\n", f);
      exit_code = kExitRunFailed;
    }
  });
}

}  // namespace kelvin

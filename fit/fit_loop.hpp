#pragma once
/// \file
/// The NLopt outer loop of `kelvin fit`: minimises the total misfit of a FitProblem
/// plus a smoothness penalty on per-element fields over the optimiser-space
/// parameters p (log-transformed where the map says so), with bounds.
/// A trial whose simulation fails (inversion, solver failure) returns a huge
/// objective so that the line search backs off, and is logged; it never ends the fit.
#include <Eigen/Core>
#include <atomic>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "adjoint/fit_problem.hpp"
#include "adjoint/parameter_terms.hpp"
#include "adjoint/uncertainty.hpp"

namespace kelvin {

/// One objective evaluation as the optimiser saw it.
struct FitRecord {
  int evaluation = 0;  // 1-based count of simulations (with gradient) so far
  int iteration = 0;   // accepted iterates so far (evaluations that improved the best)
  bool accepted = false;
  bool ok = true;  // false: the simulation failed (error says why)
  std::string error;
  double objective = 0;  // misfit + penalty (what the optimiser minimises)
  double misfit = 0;     // Φ summed over experiments
  double penalty = 0;    // γ Σ (p_a − p_b)²
  double rms = 0;        // marker RMS (m)
  double gradient_norm = 0;
  double seconds = 0;  // elapsed since the fit started (s)
  /// Solver tolerances of this trial relative to the scenario's (above 1 in the
  /// coarse stages, see FitOptions::start_tolerance_scale; a resumed fit goes on
  /// at the saved scale).
  double tolerance_scale = 1;
  Eigen::VectorXd p;  // optimiser-space parameters of this trial
};

/// The most parameters a Gauss–Newton-scaled start is taken for (FitOptions::
/// gauss_newton_start): its sensitivity solve carries one vector per parameter, and
/// the missing force's hundreds go without.
constexpr int kGaussNewtonStartParameters = 30;

struct FitOptions {
  std::string algorithm = "lbfgs";  // lbfgs | mma | slsqp | bobyqa
  GradientOptions gradient;         // method, checkpoints, segments, interrupt
  int max_evaluations = 200;
  double ftol_rel = 1e-10, xtol_rel = 1e-8;
  double max_seconds = 0;
  /// Solver tolerances of the first stage relative to the scenario's (≥ 1): the fit
  /// runs to convergence there, then tightens them 10× per stage down to the
  /// scenario's. Far from the minimum the misfit dwarfs the integration error of
  /// loose tolerances, and a simulation with its gradient costs a fraction.
  double start_tolerance_scale = 1;
  double smoothness = 0;            // γ
  double spline_slope_penalty = 0;  // w of SplineSlopeTerm (m² s per Pa² of fall); 0 = off
  /// Relative change of Φ the caller needs resolved (0: none given): a gain below it
  /// over the plateau window, or from a restart, is no gain (the diagnosis sets it from
  /// its χ² thresholds; a single-stage fit has no measured accuracy to stop at).
  double precision = 0;
  /// Φ at p0 at the scenario's tolerances, when the caller measured it (NaN: not).
  /// With a precision, a coarse stage whose best, re-measured at the scenario's
  /// tolerances, gains less than that on it ends the fit there: what the stage gained
  /// was its own integration error (V01's missing force: 0.4700 mm at rtol 1e-3,
  /// 0.4755 re-measured, 0.4703 with no field; the last stage spent 4 evaluations,
  /// 400 s, to reach 0.4697).
  double start_objective = NAN;
  /// Start in Gauss–Newton-scaled parameters: after the start point's evaluation, one
  /// sensitivity solve there gives JᵀJ and the fit goes on as after a Gauss–Newton
  /// restart (L-BFGS only). For a start in a curved valley of correlated parameters
  /// (V09's clock lag refitted with the viscosity that had absorbed it), where plain
  /// L-BFGS crawled for 16 evaluations at 0.04 % per step.
  bool gauss_newton_start = false;
  /// Called after every evaluation (the driver prints accepted ones and failures,
  /// appends history, saves the resume state).
  std::function<void(const FitRecord&)> on_evaluation;
  /// Called with a line for the user when the loop changes course (e.g. tightens
  /// the solver tolerances).
  std::function<void(const std::string&)> on_progress;
  /// Numbering continues from here on --resume.
  int first_evaluation = 0, first_iteration = 0;
  double seconds_offset = 0;
};

struct FitOutcome {
  Eigen::VectorXd p;  // best parameters found (optimiser space)
  FitRecord best;
  std::vector<FitRecord> history;  // this run's evaluations
  int evaluations = 0, failures = 0;
  bool interrupted = false;
  std::string stop_reason;  // NLopt's result in words
  /// The Gauss–Newton standard errors a preconditioned restart last computed (at the
  /// scenario's tolerances); the report reuses them when they are at the final best.
  UncertaintyAtPoint uncertainty;
};

/// Objective value reported for failed trials: finite (NLopt refuses infinities in
/// some algorithms) and far above any real misfit.
constexpr double kFailedObjective = 1e30;

/// The options a scenario's `fit:` section asks for (algorithm, gradient method,
/// checkpoints, stopping rules, smoothness, the first stage's tolerances).
FitOptions fit_options_of(const Scenario& scenario);

FitOutcome run_fit(FitProblem& problem, const Eigen::VectorXd& p0, const FitOptions& options);

/// A trial far out in parameter space can make the DAE so stiff that one simulation
/// takes an hour. With a reference run's step count (the best point's; 0: none yet)
/// and no limit of the caller's, a trial that needs 4× its steps, at any point at
/// more than 4× its pace, fails instead.
void limit_trial_steps(GradientOptions& options, long reference_steps);

/// One point of an L-curve sweep over the smoothness weight γ.
struct LcurvePoint {
  double gamma = 0;
  double misfit = 0;     // Φ at the fit for this γ
  double roughness = 0;  // Σ (p_a − p_b)² over neighbour pairs
  double rms = 0;        // m
  int evaluations = 0;
  Eigen::VectorXd p;  // the fit for this γ
};

/// Fits once per γ (ascending order, each warm-started from the previous fit,
/// the first from p0) and records misfit against roughness: the L-curve whose
/// corner balances data fit and smoothness. `options.on_evaluation` sees every
/// evaluation of every γ.
std::vector<LcurvePoint> run_lcurve(FitProblem& problem, const Eigen::VectorXd& p0,
                                    std::vector<double> gammas, const FitOptions& options);

}  // namespace kelvin

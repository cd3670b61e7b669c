#pragma once
/// \file
/// Internal to fit/: the state one run_fit shares between its stage-and-restart
/// loop (fit_loop.cpp), the NLopt objective that decides which trials are simulated
/// and which are accepted (trial_evaluation.cpp), and the Gauss–Newton restart
/// (gauss_newton_restart.cpp), with the constants of those rules.
#include <Eigen/Core>
#include <chrono>
#include <cmath>
#include <exception>
#include <memory>
#include <nlopt.hpp>
#include <vector>

#include "adjoint/parameter_terms.hpp"
#include "fit/fit_loop.hpp"

namespace kelvin::fit_detail {

/// First-step length of a fresh L-BFGS run (see objective_scale); a restart near a
/// minimum takes at most twice the last accepted move instead (see run_fit).
constexpr double kFirstStep = 0.5;

/// A line-search trial this close to the best point (relative, or in log space)
/// is not simulated: see the stall test in objective().
constexpr double kStallStep = 1e-6;

/// After this many trials in a row that did not improve on the best, a line search
/// counts as stalled (see objective()) in a coarse stage, and in any stage whose
/// Φ accuracy is known (after a hand-over, or from probe_accuracy). With correct adjoint gradients
/// the bench bar's first stage (rtol 1e-3) reached 0.0255 mm in 24 simulations and then spent 10
/// more, all rejected, at 0.6 s each; its last stage spent 5 on gains of 0.2 % in Φ, whose accuracy
/// there was 6 %, one trial taking 9 s. Backtracking from one overshoot took 3 trials.
constexpr int kMaxRejections = 4;

/// A line-search trial farther from the best point than kLongStep (in log units, a
/// factor e²; relative for plain parameters) and than kLongStepGrowth× the last
/// accepted move is refused unsimulated, and the line search backs off as from a
/// failed simulation. Near a minimum NLopt's L-BFGS, after a run of moves 1e-2
/// long, once extrapolated λ 400× and μ, ν 2× on the noise-free bar: two trials
/// abandoned at the step limit, each costing several evaluations' time.
constexpr double kLongStep = 2, kLongStepGrowth = 10;

/// A stop within Φ's accuracy says so when that accuracy is coarser than this
/// (relative): the fit may be far from the minimum at tighter tolerances.
constexpr double kCoarseAccuracy = 0.1;

/// Each stage's tolerances are this much tighter than the previous one's.
constexpr double kStageRatio = 10;

/// A stage is converged when its best Φ gained less than its accuracy (known after a
/// hand-over) over the last kPlateauWindow accepted moves, and a coarse stage, whose
/// accuracy is only measured at the hand-over, when it gained less than
/// kCoarsePlateauGain (the RMS then moves in its fourth digit). The bundled cylinder
/// fit spent 6 evaluations on 0.2 % in Φ at 100× the scenario's tolerances, 4 on
/// 0.03 % at 10× (accuracy 0.02 %), and ran into its 30-evaluation cap. Rejected
/// trials are the stall rule's (kMaxRejections): counted here, one three-trial
/// backtrack read as convergence (V05's nominal fit stopped after 8 evaluations).
constexpr int kPlateauWindow = 3;
constexpr double kCoarsePlateauGain = 1e-3;

struct Context {
  Context(FitProblem& pr, const FitOptions& o) : problem(pr), options(o) {}
  FitProblem& problem;
  const FitOptions& options;
  nlopt::opt* opt = nullptr;
  std::vector<std::unique_ptr<ParameterTerm>> terms;  // Φ's terms in p alone
  std::chrono::steady_clock::time_point start;
  FitOutcome outcome;
  std::exception_ptr error;  // a kelvin::Error from the callback, rethrown after optimize
  int iteration = 0;
  double scale = 0;  // see objective_scale
  double first_step = kFirstStep;
  double last_move = kFirstStep;      // optimiser-space length of the last accepted move
  double last_distance = kFirstStep;  // the same in distance_to_best's units
  int budget = 0;
  bool budget_spent = false;
  bool time_spent = false;  // the budget spent was max_seconds (budget_spent is set too)
  Eigen::VectorXd lo, hi;
  // Without a Gauss–Newton basis the optimiser's x is p ./ unit (ParameterMap::units).
  Eigen::VectorXd unit;
  double start_gradient = 0, best_gradient = 0;  // projected gradient norms
  double tolerance_scale = 1;                    // of the current stage (see run_fit)
  long best_steps = 0;  // most forward steps of one experiment at the best point
  // After a Gauss–Newton restart (see precondition) the optimiser's x is z with
  // p = clamp(origin + basis·z); before, x is p itself (basis empty).
  Eigen::VectorXd origin;
  Eigen::MatrixXd basis;
  Eigen::VectorXd best_g;  // the best point's gradient in p
  bool remeasure = false;
  double remeasured = NAN;  // the best's objective at the new tolerances
  bool stalled = false;     // a line-search trial came within kStallStep of the best
  int rejected_in_row = 0;  // evaluations since the best last improved
  // Φ's relative accuracy at the current stage, 0 while unknown: the change the last
  // hand-over's re-measurement found over kStageRatio (the tolerances are that much
  // tighter); handover_objective is the best's value at the coarser stage.
  double accuracy = 0, handover_objective = NAN;
  bool probed = false;  // see probe_accuracy
  /// FitOptions::gauss_newton_start: the start point is evaluated; restart from it in
  /// Gauss–Newton-scaled parameters.
  bool gauss_newton_start_pending = false;
  std::vector<double> stage_best;  // the best objective after each accepted move of the stage
  bool plateau = false;            // see kPlateauWindow
  bool coarse_gain_lost = false;   // see FitOptions::start_objective
  /// At the last stage in Gauss–Newton-scaled parameters: the relative gain the
  /// Gauss–Newton model predicts from the best point, once it fell within Φ's
  /// accuracy (the fit has converged; NaN before).
  double gain_within_accuracy = NAN;
};

/// The scale the optimiser sees the objective at (see trial_evaluation.cpp).
double objective_scale(bool ok, double objective, const Eigen::VectorXd& gradient,
                       double first_step);
/// Distance of p from the best point (relative for linear entries, log units for
/// log ones).
double distance_to_best(const Context& c, const Eigen::VectorXd& p);
/// The gradient's norm without the components that push against an active bound.
double projected_norm(const Eigen::VectorXd& g, const Eigen::Ref<const Eigen::VectorXd>& p,
                      const Eigen::VectorXd& lo, const Eigen::VectorXd& hi);
/// The NLopt objective: one trial of the line search (data is the Context).
double objective(const std::vector<double>& x, std::vector<double>& grad, void* data);
/// Continues in Gauss–Newton-scaled parameters about `best` (sets c.basis); false
/// when JᵀJ is not available there.
bool precondition(Context& c, const Eigen::VectorXd& best, const Eigen::VectorXd& gradient);
/// The decrease of Φ, relative to the best's, that a Gauss–Newton step from the best
/// point with this gradient predicts (with the JᵀJ of the last preconditioning);
/// NaN without one, or with terms in p alone in the objective (a regulariser).
double predicted_gain(const Context& c, const Eigen::VectorXd& gradient);

}  // namespace kelvin::fit_detail

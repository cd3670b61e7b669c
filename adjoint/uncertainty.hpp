#pragma once
/// \file
/// Gauss–Newton (Fisher information) standard errors of fitted parameters, treating
/// the observed marker coordinates at the capture frames as independent samples
/// with one unknown noise level σ: Cov(p) = σ̂² (JᵀJ)⁻¹, σ̂² = ‖r‖² / (N − n).
#include <Eigen/Core>
#include <atomic>
#include <string>
#include <vector>

#include "adjoint/fit_problem.hpp"

namespace kelvin {

struct ParameterUncertainty {
  bool ok = false;
  std::string error;
  int observations = 0;         // N: observed coordinates used (weight > 0, in window)
  double sigma = 0;             // σ̂ (m)
  Eigen::MatrixXd covariance;   // optimiser space (n × n)
  Eigen::VectorXd std_error_p;  // optimiser space
  Eigen::VectorXd std_error;    // model units (q·σ_p for log entries)
  /// B with B Bᵀ = (JᵀJ)⁻¹ in optimiser space, singular values below the
  /// sensitivities' accuracy raised to it: set whenever J was computed, also when the
  /// covariance is refused as singular (ok false). Zero rows for the parameters that
  /// move no marker and for the unresolved ones, whose J columns are left out.
  Eigen::MatrixXd root_inverse;
  /// Parameters that move markers, but too little for the data to place them (see
  /// unresolved_entries, at σ̂).
  std::vector<int> unresolved;
  /// JᵀJ of the entries that move markers and are resolved is regular on its own:
  /// root_inverse then gives their errors with the others held.
  bool resolved_regular = false;
};

/// Standard errors computed once at a point and reused there: the fit's Gauss–Newton
/// restart and the report both need them at the final best point, and each
/// computation is a sensitivity solve.
struct UncertaintyAtPoint {
  Eigen::VectorXd p;  // empty: none computed
  ParameterUncertainty value;
  bool holds(const Eigen::VectorXd& q) const { return p.size() == q.size() && p == q; }
};

/// Where a residual entry comes from.
struct ResidualSample {
  int experiment = 0;  // −1 − k for the static measurement k (FitProblem::static_term)
  int marker = 0;      // in the experiment's MarkerObjective::names()
  int axis = 0;
  double t = 0;            // capture frame (s)
  double sqrt_weight = 1;  // the residual entry is √wᵢ times the distance
};

/// The weighted residuals r (simulated − observed, observation parameters applied,
/// per observed coordinate of every experiment, at the capture frames in the
/// objective's window, each against the model at t − τ: simulate_markers) and
/// their Jacobian J = dr/dp from one forward-sensitivity solve per experiment
/// (observation entries from the objective's own derivatives); then every static
/// measurement's coordinates, weighted as Φ weighs them against the first motion's
/// frames, with J from the linearised equilibrium. Refused (error) for experiments
/// with shape targets.
struct GaussNewtonSystem {
  bool ok = false;
  std::string error;
  Eigen::VectorXd residual;             // N (m)
  Eigen::MatrixXd jacobian;             // N × p.size()
  std::vector<ResidualSample> samples;  // N, in residual order
  double rtol = 0;                      // loosest solver rtol: the accuracy of J
};
/// Without `with_jacobian` only r (one plain run per experiment); with
/// `sensitivity_entries`, J's columns of the other model entries are zero (see
/// simulate_markers).
GaussNewtonSystem gauss_newton_system(FitProblem& problem, const Eigen::VectorXd& p,
                                      const std::atomic<bool>* interrupt = nullptr,
                                      bool with_jacobian = true,
                                      const std::vector<int>* sensitivity_entries = nullptr);

/// How far a parameter's value is taken to range when judging whether the data place
/// it: a factor e (log entries, whose p is ln q) or max(|p_j|, its unit) (plain ones).
double parameter_span(const ParameterMap& map, const Eigen::VectorXd& p, int j);

/// A parameter is unresolved when its conditional standard error exceeds this many
/// spans (see unresolved_entries).
constexpr double kUnresolvedSpan = 2;

/// The entries of p among `entries` that move markers (r, J as gauss_newton_system
/// gives them, σ the noise level) too little for the data to place them even with
/// every other entry held: σ/‖∂r/∂p_j‖, the conditional standard error, spans more
/// than a factor e² (a log entry) or twice max(|p_j|, its unit) (a plain one).
/// Moving one across that span changes ‖r‖² by less than σ².
std::vector<int> unresolved_entries(const ParameterMap& map, const Eigen::VectorXd& p,
                                    const Eigen::MatrixXd& jacobian, double sigma,
                                    const std::vector<int>& entries);

ParameterUncertainty gauss_newton_uncertainty(FitProblem& problem, const Eigen::VectorXd& p,
                                              const std::atomic<bool>* interrupt = nullptr);
/// The same from a system already solved, whose J columns are the first J.cols()
/// entries of `map` (a larger model's system serves its leading entries).
ParameterUncertainty gauss_newton_uncertainty(const ParameterMap& map, const Eigen::VectorXd& p,
                                              const GaussNewtonSystem& system);

/// Model-unit standard errors of u's resolved entries with its unresolved ones held
/// where they are (NaN for those and for entries that move no marker), from
/// root_inverse (its entries: the first rows of `map`): what is left to say when an
/// unresolved entry made JᵀJ singular.
Eigen::VectorXd standard_errors_with_unresolved_held(const ParameterUncertainty& u,
                                                     const ParameterMap& map,
                                                     const Eigen::VectorXd& p);

}  // namespace kelvin

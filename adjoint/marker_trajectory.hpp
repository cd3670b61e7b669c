#pragma once
/// \file
/// Simulated marker positions of one experiment at chosen times, optionally with
/// their sensitivities d x*/dp (IDAS forward sensitivities): what plots, per-marker
/// residuals and Gauss–Newton uncertainties need beyond Φ.
#include <Eigen/Core>
#include <atomic>
#include <string>
#include <vector>

#include "adjoint/experiment.hpp"
#include "adjoint/fit_problem.hpp"
#include "adjoint/parameter_map.hpp"

namespace kelvin {

struct MarkerTrajectory {
  bool ok = false;
  std::string error;          // why the simulation failed (names the time)
  std::vector<double> times;  // in the capture's clock
  /// Per time t: the embedded markers (3 × markers) of the model at t − τ, τ the
  /// clock offset (held at the run's ends), where the capture's frame at t is compared.
  std::vector<Eigen::Matrix3Xd> positions;
  /// Per time: the residuals rᵢ = x*ᵢ(t − τ) − x̄'ᵢ(t) of the objective's markers
  /// (observation parameters applied, the capture never read between its frames;
  /// 3 × objective markers, NaN where marker i does not count at t) and, with
  /// sensitivities, dr/dp ((3·objective markers) × p.size(), row 3i+c; observation
  /// entries included).
  std::vector<Eigen::Matrix3Xd> residuals;
  std::vector<Eigen::MatrixXd> residual_sensitivities;
  IntegratorStats stats;  // of the run that made the samples
};

/// Simulates experiment `index` of `problem` at parameters p of its map (applied
/// first), integrated as the problem's evaluations are (FitProblem::plan), and
/// samples the embedded markers at `times` (ascending, within the run). With
/// `sensitivity_entries`, only those model entries' columns are integrated (the other
/// model entries' are zero; observation entries' are always there).
MarkerTrajectory simulate_markers(FitProblem& problem, int index, const Eigen::VectorXd& p,
                                  const std::vector<double>& times, bool with_sensitivities,
                                  const std::atomic<bool>* interrupt = nullptr,
                                  const std::vector<int>* sensitivity_entries = nullptr);

}  // namespace kelvin

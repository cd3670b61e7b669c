#pragma once
/// \file
/// Everything `kelvin fit` writes once the optimiser stops (the history and the
/// resume state are written during the fit): fitted.yaml, per-marker RMS before
/// and after, the parameter fields as VTU, standard errors, and the report.
#include <Eigen/Core>
#include <atomic>
#include <string>
#include <vector>

#include "adjoint/fit_problem.hpp"
#include "fit/fit_loop.hpp"

namespace kelvin {

/// What a fit found and how it got there: what the outputs are written from.
struct FitSummary {
  std::string outdir;
  Eigen::VectorXd start, best;     // optimiser space
  std::vector<FitRecord> history;  // every evaluation, resumed runs included
  std::string algorithm, gradient_method, stop_reason;
  int evaluations = 0, failures = 0;
  double seconds = 0;
  bool interrupted = false;
  std::vector<LcurvePoint> lcurve;
  UncertaintyAtPoint uncertainty;  // see FitOutcome::uncertainty
};

/// Writes the outputs into summary.outdir and returns the path of report.md.
/// After an interrupt only what needs no further simulation is written
/// (fitted.yaml, parameter fields, the report of the history).
std::string write_fit_outputs(FitProblem& problem, const FitSummary& summary,
                              const std::atomic<bool>* interrupt);

}  // namespace kelvin

#pragma once
/// \file
/// Where the nominal model falls short, as a force: the gentlest body-force field
/// (Wang/Kry's control forces) that makes the fitted nominal model follow the
/// capture, in a reduced basis — boxes along the body's axis in space, hats in time
/// (engine/body_force.hpp) — with the nominal parameters held at their fit. Its
/// gradient is the adjoint's (∂Φ/∂f is the adjoint velocity), so the cost is that
/// of a few fit evaluations whatever the basis size. "Gentlest" is a Gaussian prior
/// of size g on every coefficient against the estimated noise: a MAP estimate.
#include <Eigen/Core>
#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "adjoint/fit_problem.hpp"
#include "diagnose/candidates.hpp"
#include "diagnose/diagnose_settings.hpp"

namespace kelvin {

struct MissingForceRegion {
  std::string name;      // clamp zone, middle, free end (thirds along the body)
  double rms_force = 0;  // force density, RMS over the region's volume and the knots (N/m³)
  double share = 0;      // of the field's ∫∫ |f|² dV dt
};

struct MissingForce {
  bool ok = false;
  std::string error;
  int knots = 0, segments = 0, evaluations = 0;
  double seconds = 0;
  double rms_before = 0, rms_after = 0;  // training misfit RMS (m) without and with the field
  /// N (rms_before² − rms_after²)/σ̂² against the χ² quantile for as many degrees of
  /// freedom as the field has values: below it, the field fits noise.
  double statistic = 0, threshold = 0;
  int dof = 0;
  double peak_time = 0;  // the knot where ∫ |f|² dV is largest (s)
  std::string where;     // the region with the largest share
  std::vector<MissingForceRegion> regions;
  std::vector<std::string> files;  // in the output directory
};

/// What the field's statistic is judged against.
struct MissingForceNoise {
  double sigma = 0;  // estimated noise per coordinate (m)
  int samples = 0;   // N: residual entries of the training capture
  double alpha = 0;  // significance level of the threshold
};

/// Fits the field to `nominal` (the training scenario) at its fitted parameters
/// p_nominal of `problem` and judges it; writes the scenarios it fits and the
/// field's files (body-force.csv, body-force.pvd) into `dir`. `problem` only lends its
/// map and model (it is not evaluated); the field's fit runs on `comm` (its one
/// experiment on rank 0).
MissingForce fit_missing_force(FitProblem& problem, const Scenario& nominal,
                               const Eigen::VectorXd& p_nominal, const BodyAxis& axis,
                               const MissingForceNoise& noise, const MissingForceSettings& settings,
                               const std::string& dir, const std::atomic<bool>* interrupt,
                               const std::function<void(const std::string&)>& progress,
                               Communicator& comm = world());

}  // namespace kelvin

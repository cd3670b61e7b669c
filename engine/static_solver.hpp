#pragma once
/// \file
/// Elastostatic equilibrium r(x, 0) = f_ext with the clamps at their pose at time t
/// (Real2Sim §3.4: the initial state of a fit). Newton's method on the free dofs
/// with the assembled tangent K, a backtracking line search that also backs off
/// from inverted elements, and load stepping when the full load is too much at once.
#include <Eigen/Core>
#include <string>

#include "engine/fem_model.hpp"

namespace kelvin {

struct StaticOptions {
  double tolerance = 1e-10;  // ‖r − f_ext‖ relative to the load scale
  int max_iterations = 50;   // per load step
  int max_load_steps = 64;
  /// The share of the external load (gravity, loads) to carry: incremental loading
  /// (Bächer 2008, §6.1) solves a sequence of these.
  double load_fraction = 1.0;
};

struct StaticResult {
  bool converged = false;
  int iterations = 0;  // Newton iterations over all load steps
  int load_steps = 0;
  double residual = 0;  // final relative residual
  std::string message;  // why it failed, when it did
};

/// x_free: initial guess in, equilibrium out. Ramped clamps (pressed probes) are
/// part of the load: the equilibrium holds them at load_fraction of their
/// translation (expand with ramp = load_fraction).
StaticResult solve_static(const FemModel& model, double t, Eigen::VectorXd& x_free,
                          const StaticOptions& options = {});

/// A starting guess for the free dofs at time t: rest positions moved rigidly with
/// the first clamp that is not ramped (so a clamp that starts displaced does not
/// tear the mesh).
Eigen::VectorXd rigid_initial_guess(const FemModel& model, double t);

}  // namespace kelvin

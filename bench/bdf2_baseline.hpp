#pragma once
/// \file
/// The Real2Sim paper's time integration, as a yardstick for kelvin's (bench only):
/// fixed-step BDF2 (Hahn et al. 2019, Eq. 2/6; backward Euler for the first step)
/// with a full Newton iteration per step (a new Newton matrix every iteration), and
/// its discrete adjoint with every state stored (the paper's gradient, Eq. 13).
/// Built from kelvin's own residual, Newton matrix, KLU Schur solver, objective and
/// parameter derivatives, so the comparison measures the method, not the code.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "adjoint/experiment_run.hpp"

namespace kelvin::bench {

struct Bdf2Result {
  bool ok = false;
  std::string error;
  long steps = 0, newton_iterations = 0;
  std::vector<Eigen::Matrix3Xd> markers;  // embedded marker positions at the sample times
  double phi = 0;
  Eigen::VectorXd gradient;  // dΦ/dp, with the adjoint only
  double stored_mib = 0;     // states kept for the adjoint
  double seconds = 0;
};

/// Integrates run's experiment from its initial state to its end with step h
/// (the duration must be a whole number of steps within 1e-9) and samples the
/// markers at `times` (each a whole number of steps). Φ is the trapezoid sum of the
/// marker misfit at the steps. With `adjoint`, also dΦ/dp by the discrete adjoint.
/// Newton stops when the largest position correction is below `newton_tol` (m).
Bdf2Result bdf2_run(ExperimentRun& run, double h, const std::vector<double>& times, bool adjoint,
                    double newton_tol = 1e-10, int max_newton = 25);

}  // namespace kelvin::bench

#pragma once
/// \file
/// Three-way check of dΦ/dp: adjoint, forward sensitivities and central finite
/// differences, plus a Taylor test along a random direction δ:
///   r(h) = Φ(p + hδ) − Φ(p) − h ∇Φ·δ = c₂h² + c₃h³ + …,
/// for h halved from level to level. The rate of |8 r(h/2) − r(h)| = |c₂|h² + O(h⁴)
/// (the h³ term cancels) must be ≈ 2 when the gradient is right; a gradient error e
/// adds 3eh to it, and the rate falls to ≈ 1. Only levels above Φ's integration
/// noise count; when fewer than three do, the sequence grows to larger steps.
#include <Eigen/Core>
#include <vector>

#include "adjoint/fit_problem.hpp"

namespace kelvin {

struct GradientCheckOptions {
  unsigned seed = 1;
  double fd_step = 1e-3;        // central-difference step in p (relative for log entries)
  int max_parameters = 12;      // per-parameter differences only for this many entries
  bool forward = true;          // also run forward sensitivities
  double taylor_h0 = 1.0 / 32;  // first Taylor step; halved taylor_levels − 1 times
  int taylor_levels = 7;
  GradientOptions adjoint;  // method is forced to adjoint
};

struct GradientCheckReport {
  bool ok = false;
  std::string error;
  double phi = 0, rms = 0;
  Eigen::VectorXd adjoint, forward, finite_difference;  // forward/fd may be empty
  std::vector<int> checked;                             // entries with finite differences
  Eigen::VectorXd direction;
  double directional_adjoint = 0, directional_forward = 0, directional_fd = 0;
  std::vector<double> h, remainder;  // |r(h)|
  std::vector<double> corrected;     // |8 r(h/2) − r(h)| per h but the last
  /// |Φ − Φ at 10× tighter tolerances|: corrected remainders within 100× of it are
  /// integration noise, not Taylor terms.
  double noise = 0;
  int resolved_levels = 0;  // leading entries of `corrected` above that noise
  /// Steps added above taylor_h0 (doubling, up to 1) because fewer than three
  /// levels cleared the noise.
  int added_levels = 0;
  double slope = 0;  // median rate of those entries between consecutive h (NaN: < 2)
  double adjoint_vs_forward = 0, adjoint_vs_fd = 0;  // relative errors (∞-norms)
  double seconds_forward_only = 0, seconds_adjoint = 0, seconds_forward_sensitivities = 0;
  /// Integrator counters of Φ alone, and of the adjoint evaluation's forward and
  /// backward passes (summed over experiments): where the gradient's time goes.
  IntegratorStats phi_stats, adjoint_forward_stats, adjoint_backward_stats;
};

GradientCheckReport check_gradient(FitProblem& problem, const Eigen::VectorXd& p,
                                   const GradientCheckOptions& options);

}  // namespace kelvin

#pragma once
/// \file
/// IDAS's highest BDF order for a run, chosen by a short probe when the scenario
/// leaves it open (`solver.max_order: auto`, the default).
///
/// Why a choice is needed: BDF1–2 are A-stable, BDF3–5 are not. A mode with
/// frequency ω and damping ratio ζ below cos α (the A(α) angle: 0.07 for BDF3,
/// 0.29 for BDF4, 0.62 for BDF5) grows at step h when hω falls in a band near 1
/// (BDF3: 0.36–1.9 at ζ = 0.01, BDF5: 0.78–9.3), by up to 4 % (BDF3) and 37 %
/// (BDF5) per step. A lightly damped soft body has such modes at every
/// frequency from its visible motion up to kHz, so IDAS at orders 3–5 is held to
/// steps that follow modes carrying no visible motion: on the 1512-tet diagnosis
/// bar (Newtonian ν 2 Pa s, μ 120 kPa) order 3 takes 16.5k steps for 2.2 s at any
/// rtol from 1e-3 to 1e-5, order 2 1.5k–5k. A strongly damped body (the 120-tet
/// bench bar) runs stably at order 3 with fewer steps than at order 2. Which kind a
/// model is depends on its materials, parameters and motion, so it is measured.
#include <Eigen/Core>
#include <array>
#include <string>

#include "engine/fem_model.hpp"
#include "engine/idas_integrator.hpp"

namespace kelvin {

struct OrderChoice {
  int max_order = 5;
  double window = 0;  // simulated seconds each candidate was probed over
  /// Steps each candidate cap took over the window (index = cap; 0 = not probed,
  /// negative = abandoned after that many steps, more than a lower cap needed).
  std::array<long, 6> steps{};
  std::string summary() const;  // one line for people
};

/// The candidates in the order they are probed, and the share of the run probed.
inline constexpr std::array<int, 3> kOrderCandidates{2, 3, 5};
inline constexpr double kOrderProbeShare = 0.05;

/// Integrates the first kOrderProbeShare of [t0, t_end] from (x0, v0) at each
/// candidate cap with `options` (whatever its max_order) and returns the cap that
/// took the fewest steps; a higher cap wins ties, being more accurate at the same
/// tolerances. A candidate is abandoned as soon as it needs more steps than the
/// best so far, and caps above one that lost are not tried (their unstable bands
/// reach further). A probe that fails counts as lost.
OrderChoice choose_max_order(const FemModel& model, const IntegratorOptions& options, double t0,
                             double t_end, const Eigen::VectorXd& x0, const Eigen::VectorXd& v0);

}  // namespace kelvin

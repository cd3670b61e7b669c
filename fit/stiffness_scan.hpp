#pragma once
/// \file
/// A global start for the local fit of a dynamic capture. Under periodic clamp
/// motion Φ is multimodal in the moduli: every resonance the simulated bar passes
/// through on the way to the truth is a ridge (on diagnosis case V05, Φ over a
/// common scale s of λ and μ has a basin ×1.25 wide at s = 0.4 and minima at
/// s = 0.55 and 1.67 that L-BFGS from s = 1 falls into). The scan evaluates Φ,
/// forward only, at the fit's first-stage tolerances, on a log grid of one common
/// scale of every fitted elastic modulus (the bar's frequencies move as √s), then
/// at half steps either side of the best, and hands the best point to the fit.
/// Each point is independent of the others, so a basin narrower than the range is
/// found wherever it lies; an optimiser's trisection of the range would first look
/// where the grid's coarsest points do.
#include <Eigen/Core>
#include <functional>
#include <string>
#include <vector>

#include "fit/fit_loop.hpp"

namespace kelvin {

struct ScanPoint {
  double scale = 1;  // of the start's moduli
  bool ok = false;   // false: the simulation failed (error says why)
  double rms = 0;    // marker RMS (m)
  double phi = 0;
  std::string error;
};

struct StiffnessScan {
  std::vector<int> entries;  // the entries of p that were scaled (empty: no modulus fitted)
  std::vector<ScanPoint> points;
  double scale = 1;          // of the best point
  Eigen::VectorXd p;         // the best point (p0 when nothing beat it)
  bool interrupted = false;  // the scan stopped early on the interrupt (every rank alike)
};

/// The entries of p that hold elastic moduli (value blocks of `elastic.*` targets in
/// Pa): those a common stiffness scale multiplies.
std::vector<int> modulus_entries(FitProblem& problem);

/// Scans s = 1.25^k, k = −7…7 (×0.21 to ×4.8) and the two half steps beside the best,
/// within the parameters' bounds. `options` gives the first stage's tolerances and
/// the interrupt; `progress` hears one line per point.
StiffnessScan scan_stiffness(FitProblem& problem, const Eigen::VectorXd& p0,
                             const FitOptions& options,
                             const std::function<void(const std::string&)>& progress = {});

}  // namespace kelvin

#include "fit/stiffness_scan.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace kelvin {

namespace {

constexpr double kRatio = 1.25;  // a basin ×1.25 wide holds a grid point or its edge
constexpr int kHalfWidth = 7;    // ×0.21 … ×4.8: resonances ×0.46 … ×2.2

}  // namespace

std::vector<int> modulus_entries(FitProblem& problem) {
  const ParameterMap& map = problem.map();
  const FemModel& model = problem.model();
  std::vector<int> out;
  for (int j : map.model_entries()) {
    const ParameterBlock& b = map.block_of_entry(j);
    if (b.is_multiplier() || !b.slot.is_material() || b.target.rfind("elastic.", 0) != 0) continue;
    const auto& info = model.terms()[b.slot.term].model->params()[b.slot.index];
    if (info.unit == "Pa") out.push_back(j);
  }
  return out;
}

StiffnessScan scan_stiffness(FitProblem& problem, const Eigen::VectorXd& p0,
                             const FitOptions& options,
                             const std::function<void(const std::string&)>& progress) {
  const ParameterMap& map = problem.map();
  StiffnessScan scan;
  scan.p = p0;
  scan.entries = modulus_entries(problem);
  if (scan.entries.empty()) return scan;
  const Eigen::VectorXd lo = map.lower(), hi = map.upper();

  const auto scaled = [&](double s, Eigen::VectorXd& p) {
    p = p0;
    for (int j : scan.entries) {
      p[j] = map.is_log(j) ? p0[j] + std::log(s) : p0[j] * s;
      if (!(p[j] >= lo[j] && p[j] <= hi[j])) return false;
    }
    return true;
  };
  GradientOptions g = options.gradient;
  g.method = GradientMethod::kNone;
  g.tolerance_scale *= std::max(1.0, options.start_tolerance_scale);
  double best = HUGE_VAL;
  const auto run = [&](double s) {
    Eigen::VectorXd p;
    if (!scaled(s, p)) return;
    // The evaluation's agreed flag, not the signal's: every rank stops at one point.
    if (scan.interrupted) return;
    const Evaluation ev = problem.evaluate(p, g);
    scan.interrupted = ev.interrupted;
    ScanPoint pt;
    pt.scale = s;
    pt.ok = ev.ok && std::isfinite(ev.phi);
    pt.phi = ev.phi;
    pt.rms = ev.rms;
    pt.error = ev.error;
    if (s == 1 && pt.ok) {  // the others may not stall the scan (as the fit's trials)
      long steps = 0;
      for (const auto& e : ev.experiments) steps = std::max(steps, e.forward_stats.steps);
      limit_trial_steps(g, steps);
    }
    // The start wins ties: it is the user's guess.
    if (pt.ok && pt.phi < best) {
      best = pt.phi;
      scan.scale = s;
      scan.p = p;
    }
    if (progress)
      progress(pt.ok ? fmt::format("  stiffness ×{:<6.3g} rms {:8.4f} mm", s, pt.rms * 1e3)
                     : fmt::format("  stiffness ×{:<6.3g} failed: {}", s, pt.error));
    scan.points.push_back(pt);
  };
  run(1.0);
  for (int k = 1; k <= kHalfWidth; ++k) {
    run(std::pow(kRatio, -k));
    run(std::pow(kRatio, k));
  }
  const double centre = scan.scale, half = std::sqrt(kRatio);
  run(centre / half);
  run(centre * half);
  std::sort(scan.points.begin(), scan.points.end(),
            [](const ScanPoint& a, const ScanPoint& b) { return a.scale < b.scale; });
  return scan;
}

}  // namespace kelvin

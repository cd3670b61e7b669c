#include "adjoint/gradient_check.hpp"

#include <algorithm>
#include <cmath>
#include <random>

#include "base/error.hpp"

namespace kelvin {
namespace {

double relative_error(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  const double scale = std::max(a.lpNorm<Eigen::Infinity>(), b.lpNorm<Eigen::Infinity>());
  return scale > 0 ? (a - b).lpNorm<Eigen::Infinity>() / scale : 0.0;
}

/// The median of the rates log(r_k/r_{k+1}) / log(h_k/h_{k+1}) between consecutive
/// steps. A least-squares line through all levels is pulled off 2 by the
/// integration noise of Φ at the smallest steps (check_gradient leaves out the
/// levels within its noise floor; the median resists what noise is left), and a
/// wrong gradient still gives ≈ 1 at every level. The raw remainders'
/// rates were pulled down by the h³ term at the largest steps too: 1.66, 1.85, 1.96,
/// 1.94, 1.98, 1.82 on the occluded test bar, median 1.896 for an adjoint that agreed
/// with forward sensitivities to 3e-8; with that term cancelled (see the header)
/// 1.99, 2.05, 1.92, 2.02, 1.68, median 1.99.
/// r may be shorter than h (the corrected remainders have one entry fewer).
double median_rate(const std::vector<double>& h, const std::vector<double>& r) {
  std::vector<double> rates;
  for (size_t i = 0; i + 1 < std::min(h.size(), r.size()); ++i)
    if (r[i] > 0 && r[i + 1] > 0)
      rates.push_back(std::log(r[i] / r[i + 1]) / std::log(h[i] / h[i + 1]));
  if (rates.empty()) return NAN;
  std::sort(rates.begin(), rates.end());
  const size_t m = rates.size();
  return m % 2 ? rates[m / 2] : 0.5 * (rates[m / 2 - 1] + rates[m / 2]);
}

/// See the noise floor in check_gradient.
constexpr double kNoiseMargin = 100;
/// Levels above the noise needed for a rate (two rates, their median), and the
/// largest step the Taylor sequence grows to when they are missing (a unit step
/// changes each entry by about its own size).
constexpr int kMinResolvedLevels = 3;
constexpr double kLargestTaylorStep = 1.0;

}  // namespace

GradientCheckReport check_gradient(FitProblem& problem, const Eigen::VectorXd& p,
                                   const GradientCheckOptions& o) {
  GradientCheckReport rep;
  GradientOptions none = o.adjoint, adj = o.adjoint, fwd = o.adjoint;
  none.method = GradientMethod::kNone;
  adj.method = GradientMethod::kAdjoint;
  fwd.method = GradientMethod::kForward;
  auto phi = [&](const Eigen::VectorXd& q) {
    const Evaluation e = problem.evaluate(q, none);
    if (!e.ok) throw Error(e.error);
    return e.phi;
  };
  try {
    const Evaluation base = problem.evaluate(p, none);
    if (!base.ok) throw Error(base.error);
    rep.seconds_forward_only = base.seconds;
    rep.phi = base.phi;
    rep.rms = base.rms;
    const Evaluation a = problem.evaluate(p, adj);
    if (!a.ok) throw Error(a.error);
    rep.seconds_adjoint = a.seconds;
    for (const auto& e : base.experiments) rep.phi_stats += e.forward_stats;
    for (const auto& e : a.experiments) {
      rep.adjoint_forward_stats += e.forward_stats;
      rep.adjoint_backward_stats += e.backward_stats;
    }
    rep.adjoint = a.gradient;
    if (o.forward) {
      const Evaluation f = problem.evaluate(p, fwd);
      if (!f.ok) throw Error(f.error);
      rep.seconds_forward_sensitivities = f.seconds;
      rep.forward = f.gradient;
      rep.adjoint_vs_forward = relative_error(rep.adjoint, rep.forward);
    }

    const int np = static_cast<int>(p.size());
    const int checked = std::min(np, o.max_parameters);
    rep.finite_difference.resize(checked);
    // Log entries are relative already; linear ones get a step relative to their value
    // or, at 0, to their unit (a Legendre coefficient or offset at its nominal 0 took a
    // step of 1e-15 and differenced integration noise).
    const Eigen::VectorXd units = problem.map().units();
    const auto size = [&](int j) {
      return problem.map().is_log(j) ? 1.0 : std::max(std::abs(p[j]), units[j]);
    };
    for (int j = 0; j < checked; ++j) {
      Eigen::VectorXd qp = p, qm = p;
      const double h = o.fd_step * size(j);
      qp[j] += h;
      qm[j] -= h;
      rep.finite_difference[j] = (phi(qp) - phi(qm)) / (2 * h);
      rep.checked.push_back(j);
    }

    std::mt19937 rng(o.seed);
    std::normal_distribution<double> normal;
    rep.direction.resize(np);
    for (int j = 0; j < np; ++j) rep.direction[j] = normal(rng);
    // Scale so that a unit step changes each entry by about its own size (log
    // entries: a factor e), keeping the Taylor steps meaningful in every unit.
    for (int j = 0; j < np; ++j) rep.direction[j] *= size(j);
    rep.direction /= std::sqrt(static_cast<double>(np));
    rep.directional_adjoint = rep.adjoint.dot(rep.direction);
    if (o.forward) rep.directional_forward = rep.forward.dot(rep.direction);
    const double hd = o.fd_step;
    rep.directional_fd = (phi(p + hd * rep.direction) - phi(p - hd * rep.direction)) / (2 * hd);

    Eigen::VectorXd fd_all(checked), adj_checked(checked);
    for (int j = 0; j < checked; ++j) adj_checked[j] = rep.adjoint[j];
    fd_all = rep.finite_difference;
    Eigen::VectorXd d1(1), d2(1);
    d1 << rep.directional_adjoint;
    d2 << rep.directional_fd;
    rep.adjoint_vs_fd = std::max(relative_error(adj_checked, fd_all), relative_error(d1, d2));

    // Φ's integration error, from Φ at 10× tighter tolerances. Each corrected
    // remainder combines three values of Φ with weights 8, 7 and 1, so its noise
    // can reach 16× that error; levels below kNoiseMargin× it are left out of the rate.
    // On a per-element field (rtol 1e-6) the three smallest of seven levels fell
    // 1.5×, 2×, 36× faster than h² there: their median read 2.12 for a gradient
    // that agreed with forward sensitivities to 1e-6.
    GradientOptions tight = none;
    tight.tolerance_scale *= 0.1;
    const Evaluation t = problem.evaluate(p, tight);
    if (!t.ok) throw Error(t.error);
    rep.noise = std::abs(t.phi - rep.phi);

    std::vector<double> signed_remainder;
    auto remainder = [&](double h) {
      return phi(p + h * rep.direction) - rep.phi - h * rep.directional_adjoint;
    };
    auto measure = [&] {
      rep.remainder.clear();
      rep.corrected.clear();
      for (double r : signed_remainder) rep.remainder.push_back(std::abs(r));
      for (size_t k = 0; k + 1 < signed_remainder.size(); ++k)
        rep.corrected.push_back(std::abs(8 * signed_remainder[k + 1] - signed_remainder[k]));
      size_t resolved = 0;
      while (resolved < rep.corrected.size() && rep.corrected[resolved] > kNoiseMargin * rep.noise)
        ++resolved;
      rep.resolved_levels = static_cast<int>(resolved);
    };
    double h = o.taylor_h0;
    for (int k = 0; k < o.taylor_levels; ++k, h /= 2) {
      rep.h.push_back(h);
      signed_remainder.push_back(remainder(h));
    }
    measure();
    // A rate needs three resolved levels. Where the Taylor terms sink into the
    // integration noise already at the first step (a weakly curved Φ, loose
    // tolerances), the sequence grows upwards by doubling, up to a unit step.
    while (rep.resolved_levels < kMinResolvedLevels && 2 * rep.h.front() <= kLargestTaylorStep) {
      rep.h.insert(rep.h.begin(), 2 * rep.h.front());
      signed_remainder.insert(signed_remainder.begin(), remainder(rep.h.front()));
      ++rep.added_levels;
      measure();
    }
    rep.slope = median_rate(
        rep.h,
        std::vector<double>(rep.corrected.begin(), rep.corrected.begin() + rep.resolved_levels));
    rep.ok = true;
  } catch (const Error& e) {
    rep.error = e.what();
  }
  return rep;
}

}  // namespace kelvin

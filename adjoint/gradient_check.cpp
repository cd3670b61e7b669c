#include "adjoint/gradient_check.hpp"

#include <cmath>
#include <random>

#include "engine/error.hpp"

namespace kelvin {
namespace {

double relative_error(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  const double scale = std::max(a.lpNorm<Eigen::Infinity>(), b.lpNorm<Eigen::Infinity>());
  return scale > 0 ? (a - b).lpNorm<Eigen::Infinity>() / scale : 0.0;
}

/// Least-squares slope of log r against log h.
double loglog_slope(const std::vector<double>& h, const std::vector<double>& r) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int m = 0;
  for (size_t i = 0; i < h.size(); ++i) {
    if (!(r[i] > 0)) continue;
    const double x = std::log(h[i]), y = std::log(r[i]);
    sx += x, sy += y, sxx += x * x, sxy += x * y, ++m;
  }
  return m >= 2 ? (m * sxy - sx * sy) / (m * sxx - sx * sx) : NAN;
}

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
    for (int j = 0; j < checked; ++j) {
      Eigen::VectorXd qp = p, qm = p;
      // Log entries are relative already; linear ones get a step relative to their value.
      const double h =
          o.fd_step * (problem.map().is_log(j) ? 1.0 : std::max(std::abs(p[j]), 1e-12));
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
    for (int j = 0; j < np; ++j)
      rep.direction[j] *= problem.map().is_log(j) ? 1.0 : std::max(std::abs(p[j]), 1e-12);
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

    double h = o.taylor_h0;
    for (int k = 0; k < o.taylor_levels; ++k, h /= 2) {
      rep.h.push_back(h);
      rep.remainder.push_back(
          std::abs(phi(p + h * rep.direction) - rep.phi - h * rep.directional_adjoint));
    }
    rep.slope = loglog_slope(rep.h, rep.remainder);
    rep.ok = true;
  } catch (const Error& e) {
    rep.error = e.what();
  }
  return rep;
}

}  // namespace kelvin

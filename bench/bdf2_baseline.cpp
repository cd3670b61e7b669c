#include "bench/bdf2_baseline.hpp"

#include <fmt/format.h>

#include <chrono>
#include <cmath>

#include "engine/markers.hpp"
#include "engine/schur_solver.hpp"

namespace kelvin::bench {
namespace {

/// ẏ_n = (α₀ y_n + α₁ y_{n−1} + α₂ y_{n−2}) / h: backward Euler at n = 1, BDF2 after.
struct Coefficients {
  double a0, a1, a2;
};
Coefficients coefficients(long n) {
  return n <= 1 ? Coefficients{1.0, -1.0, 0.0} : Coefficients{1.5, -2.0, 0.5};
}

}  // namespace

Bdf2Result bdf2_run(ExperimentRun& run, double h, const std::vector<double>& times, bool adjoint,
                    double newton_tol, int max_newton) {
  const auto start = std::chrono::steady_clock::now();
  Bdf2Result out;
  const int n = run.n;
  const int N2 = 2 * n;
  FemModel& model = run.model;
  const double duration = run.t_end - run.t0;
  const long steps = std::lround(duration / h);
  if (std::abs(steps * h - duration) > 1e-9 * duration) {
    out.error =
        fmt::format("the duration {} s is not a whole number of steps of {} s", duration, h);
    return out;
  }
  SchurSolver schur(run.dae);
  const auto& embedded = run.ex.scenario().markers.embedded;
  const int nm = run.objective.num_markers();

  std::vector<Eigen::VectorXd> y(steps + 1, Eigen::VectorXd(N2));
  y[0] << run.x0, run.v0;
  Eigen::VectorXd yp(N2), r(N2), delta(N2), beta(N2), g(nm);
  Eigen::Matrix3Xd X, V;
  size_t next_sample = 0;
  auto observe = [&](long k) {
    const double t = run.t0 + k * h;
    model.expand(t, y[k].data(), y[k].data() + n, X, V);
    run.objective.integrand(t, model, X, g.data());
    out.phi += (k == 0 || k == steps ? 0.5 * h : h) * g.sum();
    while (next_sample < times.size() && std::abs(times[next_sample] - t) <= 1e-9 * h) {
      out.markers.push_back(marker_positions(model.mesh(), embedded, X));
      ++next_sample;
    }
  };
  observe(0);
  for (long k = 1; k <= steps; ++k) {
    const double t = run.t0 + k * h;
    const Coefficients c = coefficients(k);
    beta = c.a1 * y[k - 1];
    if (k >= 2) beta += c.a2 * y[k - 2];
    y[k] = k >= 2 ? Eigen::VectorXd(2 * y[k - 1] - y[k - 2]) : y[k - 1];
    bool converged = false;
    for (int it = 0; it < max_newton && !converged; ++it) {
      yp = (c.a0 * y[k] + beta) / h;
      if (!run.dae.residual(t, y[k].data(), yp.data(), r.data()) ||
          !schur.assemble(t, c.a0 / h, y[k].data()) || !schur.factorize()) {
        out.error = fmt::format(
            "an element is inadmissible or the Newton matrix singular at t = "
            "{:.6g} s",
            t);
        return out;
      }
      schur.solve(r.data(), delta.data());
      y[k] -= delta;
      ++out.newton_iterations;
      converged = delta.head(n).lpNorm<Eigen::Infinity>() <= newton_tol;
    }
    if (!converged) {
      out.error =
          fmt::format("Newton did not converge in {} iterations at t = {:.6g} s", max_newton, t);
      return out;
    }
    ++out.steps;
    observe(k);
  }
  out.stored_mib = static_cast<double>(steps + 1) * N2 * sizeof(double) / (1 << 20);
  if (!adjoint) {
    out.ok = true;
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return out;
  }

  // λ_k solves J_kᵀ λ_k = c_k ∂g/∂y_k − Σ_{j=1,2} (α_{k+j, j}/h) E λ_{k+j}, E = diag(I, M)
  // (= ∂F/∂ẏ), J_k = ∂F/∂y + (α_{k,0}/h) E; dΦ/dq = −Σ_k λ_{k,v}ᵀ ∂R/∂q at y_k, plus the
  // initial state's share through x₀(q) for a static start.
  Eigen::VectorXd dphi_dp = Eigen::VectorXd::Zero(run.map.size());
  std::vector<Eigen::VectorXd> lambda(steps + 3, Eigen::VectorXd::Zero(N2));
  Eigen::VectorXd rhs(N2), Elam(N2);
  auto right_side = [&](long k) {
    rhs.setZero();
    const double t = run.t0 + k * h;
    model.expand(t, y[k].data(), y[k].data() + n, X, V);
    run.objective.add_gradient(t, model, X, rhs.data());
    rhs *= (k == 0 || k == steps) ? 0.5 * h : h;
    for (int j = 1; j <= 2; ++j) {
      if (k + j > steps) break;
      const Coefficients c = coefficients(k + j);
      const double a = (j == 1 ? c.a1 : c.a2) / h;
      if (a == 0) continue;
      const Eigen::VectorXd& l = lambda[k + j];
      Elam.head(n) = l.head(n);
      Elam.tail(n).setZero();
      model.mass_multiply(l.data() + n, Elam.data() + n);
      rhs -= a * Elam;
    }
  };
  for (long k = steps; k >= 1; --k) {
    const double t = run.t0 + k * h;
    const Coefficients c = coefficients(k);
    right_side(k);
    if (!schur.assemble(t, c.a0 / h, y[k].data()) || !schur.factorize()) {
      out.error = fmt::format("the adjoint's Newton matrix failed at t = {:.6g} s", t);
      return out;
    }
    rhs = -rhs;  // Jᵀ = −J_B (SchurSolver::solve_adjoint)
    schur.solve_adjoint(rhs.data(), lambda[k].data());
    yp = c.a0 * y[k] + c.a1 * y[k - 1];
    if (k >= 2) yp += c.a2 * y[k - 2];
    yp /= h;
    run.expand(t, y[k].data(), yp.data());
    if (!run.contract(lambda[k].data() + n, -1.0, dphi_dp.data())) {
      out.error = fmt::format("an element is inadmissible at t = {:.6g} s", t);
      return out;
    }
  }
  if (run.static_initial()) {
    right_side(0);
    run.factor_static_stiffness();
    const Eigen::VectorXd mu = run.K0->transpose().solve(Eigen::VectorXd(rhs.head(n)));
    if (!run.contract(mu.data(), -1.0, dphi_dp.data())) {
      out.error = "an element is inadmissible at the static state";
      return out;
    }
  }
  out.stored_mib *= 2;  // and λ
  out.gradient = dphi_dp;
  out.ok = true;
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

}  // namespace kelvin::bench

#include "adjoint/uncertainty.hpp"

#include <fmt/format.h>

#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <vector>

#include "adjoint/marker_trajectory.hpp"

namespace kelvin {
namespace {

/// One sensitivity per parameter makes the cost grow with n; beyond this a
/// per-element field would take hours and its (JᵀJ)⁻¹ is dominated by the
/// unidentifiable interior anyway.
constexpr int kMaxParameters = 200;

/// An observed marker of one experiment: its track column, its embedding and √w.
struct UsedMarker {
  int column = -1, embedded = -1;
  double sqrt_weight = 1;
};

std::vector<UsedMarker> used_markers(Experiment& ex, const ObjectiveSpec& spec) {
  const Scenario& s = ex.scenario();
  std::vector<UsedMarker> used;
  for (const auto& name : ex.objective().names()) {
    const auto w = spec.weights.find(name);
    const double weight = w == spec.weights.end() ? 1.0 : w->second;
    if (!(weight > 0)) continue;
    UsedMarker m;
    m.sqrt_weight = std::sqrt(weight);
    const auto& obs = s.markers.observed.names;
    m.column = static_cast<int>(std::find(obs.begin(), obs.end(), name) - obs.begin());
    for (size_t i = 0; i < s.markers.embedded.size(); ++i)
      if (s.markers.embedded[i].name == name) m.embedded = static_cast<int>(i);
    used.push_back(m);
  }
  return used;
}

std::string parameter_name(const ParameterMap& map, int j) {
  return map.is_log(j) ? "ln " + map.label(j) : map.label(j);
}

/// "+1·ln elastic.mu −0.98·ln density …" for a direction in p (largest entry 1).
std::string combination(const ParameterMap& map, Eigen::VectorXd dp) {
  Eigen::Index big = 0;
  dp.cwiseAbs().maxCoeff(&big);
  dp /= dp[big];
  std::string s;
  for (int j = 0; j < dp.size(); ++j)
    if (std::abs(dp[j]) >= 1e-2)
      s += fmt::format("{}{:+.3g}·{}", s.empty() ? "" : " ", dp[j], parameter_name(map, j));
  return s;
}

}  // namespace

GaussNewtonSystem gauss_newton_system(FitProblem& problem, const Eigen::VectorXd& p,
                                      const std::atomic<bool>* interrupt) {
  GaussNewtonSystem g;
  // FitProblem gives every experiment the main scenario's objective.
  const ObjectiveSpec& spec = problem.experiment(0).scenario().fit.objective;
  const ParameterMap& map = problem.map();
  std::vector<double> residual;
  std::vector<Eigen::RowVectorXd> rows;
  for (int e = 0; e < problem.num_experiments(); ++e) {
    Experiment& ex = problem.experiment(e);
    const Scenario& s = ex.scenario();
    g.rtol = std::max(g.rtol, s.solver.rtol);
    const MarkerTracks& obs = s.markers.observed;
    const std::vector<UsedMarker> used = used_markers(ex, spec);
    // Runs start at t = 0 (static or rest); frames before that cannot be simulated.
    const double begin = std::max(0.0, ex.objective().window_begin());
    const double end = ex.objective().window_end();
    std::vector<int> frames;
    std::vector<double> times;
    for (size_t k = 0; k < obs.times.size(); ++k) {
      if (obs.times[k] < begin || obs.times[k] > end) continue;
      bool seen = false;
      for (const auto& m : used)
        if (obs.xyz.col(k).segment(3 * m.column, 3).array().isFinite().any()) seen = true;
      if (!seen) continue;
      frames.push_back(static_cast<int>(k));
      times.push_back(obs.times[k]);
    }
    if (frames.empty()) continue;
    const MarkerTrajectory traj = simulate_markers(ex, map, p, times, true, interrupt);
    if (!traj.ok) {
      g.error = fmt::format("{}: {}", s.path, traj.error);
      return g;
    }
    for (size_t f = 0; f < frames.size(); ++f)
      for (const auto& m : used)
        for (int c = 0; c < 3; ++c) {
          // Coordinates, not markers, are the samples: a NaN hides just its own.
          const double observed = obs.xyz(3 * m.column + c, frames[f]);
          if (!std::isfinite(observed)) continue;
          residual.push_back(m.sqrt_weight * (traj.positions[f](c, m.embedded) - observed));
          rows.push_back(m.sqrt_weight * traj.sensitivities[f].row(3 * m.embedded + c));
        }
  }
  const int N = static_cast<int>(residual.size());
  g.residual = Eigen::Map<const Eigen::VectorXd>(residual.data(), N);
  g.jacobian.resize(N, map.size());
  for (int i = 0; i < N; ++i) g.jacobian.row(i) = rows[i];
  g.ok = true;
  return g;
}

ParameterUncertainty gauss_newton_uncertainty(FitProblem& problem, const Eigen::VectorXd& p,
                                              const std::atomic<bool>* interrupt) {
  ParameterUncertainty u;
  const ParameterMap& map = problem.map();
  const int n = map.size();
  if (n > kMaxParameters) {
    u.error = fmt::format(
        "parameter uncertainties are not computed for {} parameters (limit {}): they need one "
        "sensitivity solve per parameter; fit fewer parameters (global or per region) to get them",
        n, kMaxParameters);
    return u;
  }
  const GaussNewtonSystem sys = gauss_newton_system(problem, p, interrupt);
  if (!sys.ok) {
    u.error = sys.error;
    return u;
  }
  const double rtol = sys.rtol;
  const int N = static_cast<int>(sys.residual.size());
  u.observations = N;
  if (N <= n) {
    u.error = fmt::format(
        "{} observed marker coordinates cannot determine {} parameters and the noise level: "
        "more observations than parameters are needed",
        N, n);
    return u;
  }
  const Eigen::MatrixXd& J = sys.jacobian;
  const Eigen::VectorXd& r = sys.residual;
  u.sigma = std::sqrt(r.squaredNorm() / (N - n));

  // Unit columns make the rank decision independent of parameter units (log or not).
  const Eigen::VectorXd norms = J.colwise().norm().transpose();
  for (int j = 0; j < n; ++j)
    if (!(norms[j] > 1e-14 * norms.maxCoeff())) {
      u.error = fmt::format(
          "{} does not move any observed marker: it is not identifiable from these observations",
          parameter_name(map, j));
      return u;
    }
  const Eigen::MatrixXd Js = J * norms.cwiseInverse().asDiagonal();
  // SVD of R (Js = QR) has the accuracy of an SVD of Js at the cost of an n × n one;
  // forming JᵀJ would square the condition number.
  const Eigen::MatrixXd R = Eigen::HouseholderQR<Eigen::MatrixXd>(Js)
                                .matrixQR()
                                .topRows(n)
                                .triangularView<Eigen::Upper>();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(R, Eigen::ComputeFullV);
  const Eigen::VectorXd sv = svd.singularValues();
  // The sensitivities are accurate to about the solver's relative tolerance (more
  // with global error growth): singular values below that are indistinguishable
  // from zero.
  const double threshold = std::max(100 * rtol, 1e-12) * sv[0];
  if (!(sv[n - 1] > threshold)) {
    const Eigen::VectorXd dp = norms.cwiseInverse().asDiagonal() * svd.matrixV().col(n - 1);
    u.error = fmt::format(
        "JᵀJ is singular: the parameter combination {} is not identifiable from the observed "
        "markers (relative singular value {:.2g}, below the sensitivities' accuracy {:.2g} at "
        "solver rtol {:g})",
        combination(map, dp), sv[n - 1] / sv[0], threshold / sv[0], rtol);
    return u;
  }
  const Eigen::MatrixXd W =
      norms.cwiseInverse().asDiagonal() * svd.matrixV() * sv.cwiseInverse().asDiagonal();
  u.covariance = u.sigma * u.sigma * W * W.transpose();
  u.std_error_p = u.covariance.diagonal().cwiseSqrt();
  u.std_error.resize(n);
  for (int j = 0; j < n; ++j) u.std_error[j] = map.derivative(p, j) * u.std_error_p[j];
  u.ok = true;
  return u;
}

}  // namespace kelvin

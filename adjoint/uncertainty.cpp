#include "adjoint/uncertainty.hpp"

#include <fmt/format.h>

#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <vector>

#include "adjoint/marker_trajectory.hpp"
#include "adjoint/result_exchange.hpp"

namespace kelvin {
namespace {

/// One sensitivity per parameter makes the cost grow with n; beyond this a
/// per-element field would take hours and its (JᵀJ)⁻¹ is dominated by the
/// unidentifiable interior anyway.
constexpr int kMaxParameters = 200;

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

/// The SVD of J's columns `cols`, each scaled to unit norm (unit columns make the rank
/// decision independent of parameter units): J_cols diag(1/norms) = U diag(sv) Vᵀ,
/// and the sensitivities' accuracy as a singular value.
struct ColumnFactors {
  Eigen::VectorXd norms, sv;
  Eigen::MatrixXd V;
  double threshold = 0;
};

ColumnFactors factor_columns(const Eigen::MatrixXd& J, const std::vector<int>& cols,
                             const Eigen::VectorXd& column_norms, double rtol) {
  const int m = static_cast<int>(cols.size());
  ColumnFactors f;
  f.norms.resize(m);
  if (m == 0) return f;
  Eigen::MatrixXd Js(J.rows(), m);
  for (int k = 0; k < m; ++k) {
    f.norms[k] = column_norms[cols[k]];
    Js.col(k) = J.col(cols[k]) / f.norms[k];
  }
  // SVD of R (Js = QR) has the accuracy of an SVD of Js at the cost of an m × m one;
  // forming JᵀJ would square the condition number.
  const Eigen::MatrixXd R = Eigen::HouseholderQR<Eigen::MatrixXd>(Js)
                                .matrixQR()
                                .topRows(m)
                                .triangularView<Eigen::Upper>();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(R, Eigen::ComputeFullV);
  f.sv = svd.singularValues();
  f.V = svd.matrixV();
  // The sensitivities are accurate to about the solver's relative tolerance (more
  // with global error growth): singular values below that are indistinguishable
  // from zero.
  f.threshold = std::max(100 * rtol, 1e-12) * f.sv[0];
  return f;
}

/// One experiment's share of the Gauss–Newton system (gauss_newton_system).
struct ExperimentRows {
  std::string error;
  double rtol = 0;
  std::vector<double> residual;
  std::vector<Eigen::RowVectorXd> rows;
  std::vector<ResidualSample> samples;
};

ExperimentRows experiment_rows(FitProblem& problem, int e, const Eigen::VectorXd& p,
                               const std::atomic<bool>* interrupt, bool with_jacobian,
                               const std::vector<int>* sensitivity_entries) {
  ExperimentRows b;
  Experiment& ex = problem.experiment(e);
  const Scenario& s = ex.scenario();
  const MarkerObjective& objective = ex.objective();
  b.rtol = s.solver.rtol;
  const MarkerTracks& obs = s.markers.observed;
  // Runs start at t = 0 (static or rest); frames before that cannot be simulated.
  const double begin = std::max(0.0, objective.window_begin());
  const double end = objective.window_end();
  std::vector<double> times;
  for (double t : obs.times)
    if (t >= begin && t <= end) times.push_back(t);
  if (times.empty()) return b;
  const MarkerTrajectory traj =
      simulate_markers(problem, e, p, times, with_jacobian, interrupt, sensitivity_entries);
  if (!traj.ok) {
    b.error = fmt::format("{}: {}", s.path, traj.error);
    return b;
  }
  for (size_t f = 0; f < times.size(); ++f)
    for (int i = 0; i < objective.num_markers(); ++i) {
      const double w = objective.weight(i);
      if (!(w > 0)) continue;
      for (int c = 0; c < 3; ++c) {
        // Coordinates, not markers, are the samples: a NaN hides just its own.
        const double r = traj.residuals[f](c, i);
        if (!std::isfinite(r)) continue;
        b.residual.push_back(std::sqrt(w) * r);
        if (with_jacobian)
          b.rows.push_back(std::sqrt(w) * traj.residual_sensitivities[f].row(3 * i + c));
        b.samples.push_back({e, i, c, times[f], std::sqrt(w)});
      }
    }
  return b;
}

/// Every rank receives the rows of the experiments it does not own, and their plans
/// as the sensitivity solves left them (as FitProblem::evaluate shares its results).
void share_rows(FitProblem& problem, std::vector<ExperimentRows>& blocks) {
  Communicator& comm = problem.communicator();
  if (comm.size() == 1) return;
  ByteWriter out;
  for (int e = 0; e < problem.num_experiments(); ++e)
    if (problem.owns(e)) {
      const ExperimentRows& b = blocks[e];
      out.put(b.error);
      out.put(b.rtol);
      out.put(Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(
          b.residual.data(), static_cast<long>(b.residual.size()))));
      Eigen::MatrixXd rows(b.rows.size(), b.rows.empty() ? 0 : b.rows[0].size());
      for (size_t i = 0; i < b.rows.size(); ++i) rows.row(static_cast<long>(i)) = b.rows[i];
      out.put(rows);
      each_of(out, b.samples, [](ByteWriter& bytes, const ResidualSample& x) { bytes(x); });
      put(out, problem.plan(e));
    }
  const std::vector<std::string> shares = comm.all_gather(out.bytes());
  for (int r = 0; r < comm.size(); ++r) {
    ByteReader in(shares[r]);
    for (int e = 0; e < problem.num_experiments(); ++e) {
      if (problem.owner(e) != r) continue;
      ExperimentRows& b = blocks[e];
      in.get(b.error);
      in.get(b.rtol);
      Eigen::VectorXd residual;
      in.get(residual);
      b.residual.assign(residual.data(), residual.data() + residual.size());
      Eigen::MatrixXd rows;
      in.get(rows);
      b.rows.resize(rows.rows());
      for (long i = 0; i < rows.rows(); ++i) b.rows[i] = rows.row(i);
      each_of(in, b.samples, [](ByteReader& bytes, ResidualSample& x) { bytes(x); });
      get(in, problem.plan(e));
    }
    if (!in.done()) throw Error("internal: a rank's Gauss–Newton rows were not read to their end");
  }
}

}  // namespace

GaussNewtonSystem gauss_newton_system(FitProblem& problem, const Eigen::VectorXd& p,
                                      const std::atomic<bool>* interrupt, bool with_jacobian,
                                      const std::vector<int>* sensitivity_entries) {
  GaussNewtonSystem g;
  const ParameterMap& map = problem.map();
  std::vector<double> residual;
  std::vector<Eigen::RowVectorXd> rows;
  for (int e = 0; e < problem.num_experiments(); ++e)
    if (!problem.experiment(e).targets().empty()) {
      g.error = fmt::format(
          "{}: fit.objective.targets: a shape target is a goal, not a measurement with noise; "
          "standard errors and Gauss–Newton steps are computed for fits to captured markers and "
          "static measurements only",
          problem.experiment(e).scenario().path);
      return g;
    }
  std::vector<ExperimentRows> blocks(problem.num_experiments());
  // A rank stops at its first failure: an earlier experiment's failure is reported.
  for (int e = 0; e < problem.num_experiments(); ++e)
    if (problem.owns(e)) {
      try {
        blocks[e] = experiment_rows(problem, e, p, interrupt, with_jacobian, sensitivity_entries);
      } catch (const std::exception& x) {
        // Thrown on one rank, it would leave the others waiting in share_rows.
        if (problem.communicator().size() == 1) throw;
        blocks[e].error = fmt::format("{}: {}", problem.experiment(e).scenario().path, x.what());
      }
      if (!blocks[e].error.empty()) break;
    }
  share_rows(problem, blocks);
  for (int e = 0; e < problem.num_experiments(); ++e) {
    const ExperimentRows& b = blocks[e];
    if (!b.error.empty()) {
      g.error = b.error;
      return g;
    }
    g.rtol = std::max(g.rtol, b.rtol);
    residual.insert(residual.end(), b.residual.begin(), b.residual.end());
    for (const Eigen::RowVectorXd& row : b.rows) rows.push_back(row);
    g.samples.insert(g.samples.end(), b.samples.begin(), b.samples.end());
  }
  // Static measurements: a row per observed coordinate, weighted like w seconds of
  // frames of the first captured motion (as Φ weighs them against its tracks).
  double frame = 1;
  if (problem.num_experiments() > 0) {
    const auto& t = problem.experiment(0).scenario().markers.observed.times;
    if (t.size() >= 2) frame = (t.back() - t.front()) / static_cast<double>(t.size() - 1);
  }
  for (int k = 0; k < problem.num_static_terms(); ++k) {
    StaticTerm& st = problem.static_term(k);
    Eigen::VectorXd r;
    Eigen::MatrixXd J;
    std::vector<std::pair<int, int>> where;
    if (!st.residuals(map, p, with_jacobian, r, J, where, g.error)) return g;
    const double sw = std::sqrt(st.weight() / frame);
    for (int i = 0; i < r.size(); ++i) {
      residual.push_back(sw * r[i]);
      if (with_jacobian) rows.push_back(sw * J.row(i));
      g.samples.push_back({-1 - k, where[i].first, where[i].second, 0.0, sw});
    }
  }
  const int N = static_cast<int>(residual.size());
  g.residual = Eigen::Map<const Eigen::VectorXd>(residual.data(), N);
  g.jacobian.resize(with_jacobian ? N : 0, map.size());
  for (int i = 0; i < g.jacobian.rows(); ++i) g.jacobian.row(i) = rows[i];
  g.ok = true;
  return g;
}

double parameter_span(const ParameterMap& map, const Eigen::VectorXd& p, int j) {
  return map.is_log(j) ? 1.0 : std::max(std::abs(p[j]), map.units()[j]);
}

std::vector<int> unresolved_entries(const ParameterMap& map, const Eigen::VectorXd& p,
                                    const Eigen::MatrixXd& J, double sigma,
                                    const std::vector<int>& entries) {
  std::vector<int> out;
  for (int j : entries)
    if (sigma > kUnresolvedSpan * parameter_span(map, p, j) * J.col(j).norm()) out.push_back(j);
  return out;
}

namespace {

/// Why the standard errors of n entries of `map` are not computed ("" when they are).
std::string refused(const ParameterMap& map, int n) {
  // A body force's priors shape the fit (not the Gauss–Newton covariance), and it
  // has one sensitivity per knot and entry.
  if (map.has_body_force())
    return "parameter uncertainties are not computed for a fit with a body-force field";
  if (n > kMaxParameters)
    return fmt::format(
        "parameter uncertainties are not computed for {} parameters (limit {}): they need one "
        "sensitivity solve per parameter; fit fewer parameters (global or per region) to get them",
        n, kMaxParameters);
  return "";
}

}  // namespace

ParameterUncertainty gauss_newton_uncertainty(FitProblem& problem, const Eigen::VectorXd& p,
                                              const std::atomic<bool>* interrupt) {
  ParameterUncertainty u;
  const ParameterMap& map = problem.map();
  if (std::string why = refused(map, map.size()); !why.empty()) {
    u.error = why;
    return u;
  }
  const GaussNewtonSystem sys = gauss_newton_system(problem, p, interrupt);
  if (!sys.ok) {
    u.error = sys.error;
    return u;
  }
  return gauss_newton_uncertainty(map, p, sys);
}

ParameterUncertainty gauss_newton_uncertainty(const ParameterMap& map, const Eigen::VectorXd& p,
                                              const GaussNewtonSystem& sys) {
  ParameterUncertainty u;
  const int n = static_cast<int>(sys.jacobian.cols());
  if (std::string why = refused(map, n); !why.empty()) {
    u.error = why;
    return u;
  }
  const double rtol = sys.rtol;
  const int N = static_cast<int>(sys.residual.size());
  u.observations = N;
  if (N <= n) {
    u.error = fmt::format(
        "{} observations (marker coordinates, measured force components) cannot determine {} "
        "parameters and the noise level: more observations than parameters are needed",
        N, n);
    return u;
  }
  const Eigen::MatrixXd& J = sys.jacobian;
  const Eigen::VectorXd& r = sys.residual;
  u.sigma = std::sqrt(r.squaredNorm() / (N - n));

  // A parameter that moves no marker here (a fibre's angles, a branch's relaxation
  // time while its modulus is at its nested 0) is left out of the factorisation: its
  // row of root_inverse is zero, so a scaled fit holds it until a later restart.
  const Eigen::VectorXd all_norms = J.colwise().norm().transpose();
  std::vector<int> moving, still;
  for (int j = 0; j < n; ++j)
    (all_norms[j] > 1e-14 * all_norms.maxCoeff() ? moving : still).push_back(j);
  const int m = static_cast<int>(moving.size());
  if (m == 0) {
    u.error = "no fitted parameter moves any observed marker";
    return u;
  }
  // So is one the data cannot place (unresolved_entries). V07's λ, fitted down to
  // 0.0036 Pa beside μ at 1.4e5 Pa, moved the markers by 1e-8 of μ's effect per unit
  // of ln λ: scaled by it, every refit's first step moved ln λ by 4.8e6 and the line
  // search failed on refused trials.
  u.unresolved = unresolved_entries(map, p, J, u.sigma, moving);
  std::vector<int> resolved;
  for (int j : moving)
    if (std::find(u.unresolved.begin(), u.unresolved.end(), j) == u.unresolved.end())
      resolved.push_back(j);
  const ColumnFactors all = factor_columns(J, moving, all_norms, rtol);
  const ColumnFactors& scaling =
      resolved.size() == moving.size() ? all : factor_columns(J, resolved, all_norms, rtol);
  // A square root of (JᵀJ)⁻¹ whose unresolved directions are held at the threshold:
  // what a Gauss–Newton scaling of the fit needs even where the covariance is refused.
  const Eigen::MatrixXd root = scaling.norms.cwiseInverse().asDiagonal() * scaling.V *
                               scaling.sv.cwiseMax(scaling.threshold).cwiseInverse().asDiagonal();
  u.resolved_regular = scaling.sv.size() > 0 && scaling.sv.minCoeff() > scaling.threshold;
  u.root_inverse = Eigen::MatrixXd::Zero(n, n);
  for (std::size_t k = 0; k < resolved.size(); ++k)
    u.root_inverse.row(resolved[k]).head(root.cols()) = root.row(static_cast<long>(k));
  if (!still.empty()) {
    u.error = fmt::format(
        "{} does not move any observed marker: it is not identifiable from these observations",
        parameter_name(map, still[0]));
    return u;
  }
  const Eigen::VectorXd& sv = all.sv;
  const Eigen::VectorXd& norms = all.norms;
  const double threshold = all.threshold;
  if (!(sv[n - 1] > threshold)) {
    const Eigen::VectorXd dp = norms.cwiseInverse().asDiagonal() * all.V.col(n - 1);
    u.error = fmt::format(
        "JᵀJ is singular: the parameter combination {} is not identifiable from the observed "
        "markers (relative singular value {:.2g}, below the sensitivities' accuracy {:.2g} at "
        "solver rtol {:g})",
        combination(map, dp), sv[n - 1] / sv[0], threshold / sv[0], rtol);
    return u;
  }
  const Eigen::MatrixXd W =
      norms.cwiseInverse().asDiagonal() * all.V * sv.cwiseInverse().asDiagonal();
  u.covariance = u.sigma * u.sigma * W * W.transpose();
  u.std_error_p = u.covariance.diagonal().cwiseSqrt();
  u.std_error.resize(n);
  for (int j = 0; j < n; ++j) u.std_error[j] = map.derivative(p, j) * u.std_error_p[j];
  u.ok = true;
  return u;
}

Eigen::VectorXd standard_errors_with_unresolved_held(const ParameterUncertainty& u,
                                                     const ParameterMap& map,
                                                     const Eigen::VectorXd& p) {
  const long n = std::min<long>(u.root_inverse.rows(), map.size());
  Eigen::VectorXd se = Eigen::VectorXd::Constant(n, NAN);
  for (int j = 0; j < n; ++j)
    if (u.root_inverse.row(j).squaredNorm() > 0)
      se[j] = map.derivative(p, j) * u.sigma * u.root_inverse.row(j).norm();
  return se;
}

}  // namespace kelvin

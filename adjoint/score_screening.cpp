#include "adjoint/score_screening.hpp"

#include <fmt/format.h>

#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>

namespace kelvin {
namespace {

/// Columns `cols` of J, each scaled to unit length (the statistic does not depend on
/// the scaling; the rank decisions do).
Eigen::MatrixXd columns(const Eigen::MatrixXd& J, const std::vector<int>& cols) {
  Eigen::MatrixXd out(J.rows(), static_cast<long>(cols.size()));
  for (size_t k = 0; k < cols.size(); ++k) {
    out.col(static_cast<long>(k)) = J.col(cols[k]);
    const double n = out.col(static_cast<long>(k)).norm();
    if (n > 0) out.col(static_cast<long>(k)) /= n;
  }
  return out;
}

}  // namespace

double chi_square_survival(double x, int k) {
  if (!(x > 0)) return 1;
  const double a = 0.5 * k, z = 0.5 * x;
  const double log_prefactor = a * std::log(z) - z - std::lgamma(a);
  if (z < a + 1) {
    // Series for the lower function P(a, z).
    double term = 1 / a, sum = term;
    for (int n = 1; n < 1000 && std::abs(term) > 1e-16 * std::abs(sum); ++n) {
      term *= z / (a + n);
      sum += term;
    }
    return std::max(0.0, 1 - std::exp(log_prefactor) * sum);
  }
  // Continued fraction for Q(a, z) (modified Lentz).
  const double tiny = 1e-300;
  double b = z + 1 - a, c = 1 / tiny, d = 1 / b, h = d;
  for (int i = 1; i < 1000; ++i) {
    const double an = -i * (i - a);
    b += 2;
    d = an * d + b;
    if (std::abs(d) < tiny) d = tiny;
    c = b + an / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1 / d;
    const double step = d * c;
    h *= step;
    if (std::abs(step - 1) < 1e-15) break;
  }
  return std::exp(log_prefactor) * h;
}

double chi_square_quantile(double p, int k) {
  double lo = 0, hi = std::max(1.0, 2.0 * k);
  while (chi_square_survival(hi, k) > p) hi *= 2;
  for (int i = 0; i < 200 && hi - lo > 1e-12 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (chi_square_survival(mid, k) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

namespace {

/// P = I − J_θ J_θ⁺ applied through a QR of the fitted columns.
class Projector {
 public:
  Projector(const Eigen::MatrixXd& J, const std::vector<int>& fitted)
      : nt_(static_cast<int>(fitted.size())), qr_(columns(J, fitted)) {}
  /// The least-squares x of (scaled) J_θ x ≈ b.
  Eigen::VectorXd solve(const Eigen::VectorXd& b) const {
    if (nt_ == 0) return {};
    return qr_.solve(b);
  }
  Eigen::MatrixXd operator()(const Eigen::MatrixXd& A) const {
    if (nt_ == 0) return A;
    Eigen::MatrixXd QtA = qr_.householderQ().adjoint() * A;
    QtA.topRows(nt_).setZero();
    return qr_.householderQ() * QtA;
  }

 private:
  int nt_;
  Eigen::HouseholderQR<Eigen::MatrixXd> qr_;
};

}  // namespace

std::vector<CandidateScore> score_candidates(
    const Eigen::VectorXd& r, const Eigen::MatrixXd& J, const std::vector<int>& fitted,
    const std::vector<std::pair<std::string, std::vector<int>>>& candidates,
    const ScreeningOptions& options) {
  const long N = r.size();
  const int nt = static_cast<int>(fitted.size());
  const Projector project(J, fitted);
  const Eigen::VectorXd Pr = project(r);
  // The fitted entries a step moves, and their least-squares solver. A held entry's
  // unit column is a direction like any other, and dividing its coefficient by its
  // vanishing norm made V07's linearised starts move ln λ by millions.
  std::vector<int> moved;
  for (int j : fitted)
    if (std::find(options.held.begin(), options.held.end(), j) == options.held.end())
      moved.push_back(j);
  const Projector move(J, moved);
  const double sigma2 = options.noise_variance > 0
                            ? options.noise_variance
                            : r.squaredNorm() / static_cast<double>(std::max<long>(1, N - nt));
  const double rms = std::sqrt(r.squaredNorm() / static_cast<double>(std::max<long>(1, N)));
  const auto bounded = [&](int j) {
    return std::find(options.nonnegative.begin(), options.nonnegative.end(), j) !=
           options.nonnegative.end();
  };

  std::vector<CandidateScore> out;
  for (const auto& [name, entries] : candidates) {
    CandidateScore s;
    s.name = name;
    s.entries = entries;
    s.active = entries;
    s.rms_before = rms;
    s.predicted_rms = rms;
    // Active set: an entry at its lower bound whose step would go below it stays there.
    for (;;) {
      s.dof = static_cast<int>(s.active.size());
      s.predicted_drop = 0;
      s.step.resize(0);
      if (s.active.empty()) break;
      const Eigen::MatrixXd Jc = columns(J, s.active);
      const Eigen::MatrixXd PJ = project(Jc);
      // A candidate whose sensitivities lie in the span of the fitted ones (or are
      // zero) cannot be told apart from a change of the fitted parameters.
      const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> cq(PJ);
      if (cq.rank() < s.dof || !(PJ.norm() > 1e-8 * std::max(Jc.norm(), 1e-300))) {
        s.error = fmt::format("{} moves the markers only as the fitted parameters do", name);
        break;
      }
      const Eigen::VectorXd g = PJ.transpose() * Pr;
      const Eigen::VectorXd unit_step = cq.solve(Pr);  // least squares: PJ step ≈ P r
      s.predicted_drop = g.dot(unit_step);
      // Δp = −step / ‖J column‖ (r + J Δp is the linearised residual).
      s.step.resize(s.dof);
      int worst = -1;
      for (int k = 0; k < s.dof; ++k) {
        s.step[k] = -unit_step[k] / J.col(s.active[k]).norm();
        if (bounded(s.active[k]) && s.step[k] < 0 && (worst < 0 || s.step[k] < s.step[worst]))
          worst = k;
      }
      if (worst < 0) {
        // The fitted parameters move with it: J_θ Δθ ≈ −(r + J_φ Δφ).
        Eigen::VectorXd rhs = -r;
        for (int k = 0; k < s.dof; ++k) rhs -= J.col(s.active[k]) * s.step[k];
        const Eigen::VectorXd x = move.solve(rhs);
        s.fitted_step = Eigen::VectorXd::Zero(nt);
        for (std::size_t k = 0, m = 0; k < fitted.size(); ++k)
          if (m < moved.size() && moved[m] == fitted[k])
            s.fitted_step[static_cast<long>(k)] =
                x[static_cast<long>(m++)] / J.col(fitted[k]).norm();
        break;
      }
      s.active.erase(s.active.begin() + worst);
    }
    if (!s.error.empty() || s.active.empty()) {
      s.dof = static_cast<int>(entries.size());
      s.predicted_drop = 0;
      s.step.resize(0);
      out.push_back(s);
      continue;
    }
    s.statistic = s.predicted_drop / sigma2;
    s.p_value = chi_square_survival(s.statistic, s.dof);
    s.predicted_rms =
        std::sqrt(std::max(0.0, r.squaredNorm() - s.predicted_drop) / static_cast<double>(N));
    out.push_back(s);
  }
  return out;
}

double confounding(const Eigen::MatrixXd& J, const std::vector<int>& fitted,
                   const std::vector<int>& a, const std::vector<int>& b) {
  const Projector project(J, fitted);
  const auto basis = [&](const std::vector<int>& cols) -> Eigen::MatrixXd {
    const Eigen::MatrixXd PJ = project(columns(J, cols));
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(PJ);
    const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(PJ.rows(), PJ.cols());
    return Q.leftCols(qr.rank());
  };
  const Eigen::MatrixXd Qa = basis(a), Qb = basis(b);
  if (Qa.cols() == 0 || Qb.cols() == 0) return 0;
  const Eigen::MatrixXd C = Qa.transpose() * Qb;
  return std::min(1.0, Eigen::JacobiSVD<Eigen::MatrixXd>(C).singularValues()[0]);
}

}  // namespace kelvin

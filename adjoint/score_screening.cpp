#include "adjoint/score_screening.hpp"

#include <fmt/format.h>

#include <Eigen/QR>
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

std::vector<CandidateScore> score_candidates(
    const Eigen::VectorXd& r, const Eigen::MatrixXd& J, const std::vector<int>& fitted,
    const std::vector<std::pair<std::string, std::vector<int>>>& candidates) {
  const long N = r.size();
  const int nt = static_cast<int>(fitted.size());
  // P applied through a QR of the fitted columns.
  const Eigen::MatrixXd Jt = columns(J, fitted);
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(Jt);
  const auto project = [&](const Eigen::MatrixXd& A) -> Eigen::MatrixXd {
    if (nt == 0) return A;
    Eigen::MatrixXd QtA = qr.householderQ().adjoint() * A;
    QtA.topRows(nt).setZero();
    return qr.householderQ() * QtA;
  };
  const Eigen::VectorXd Pr = project(r);
  const double sigma2 = r.squaredNorm() / static_cast<double>(std::max<long>(1, N - nt));
  const double rms = std::sqrt(r.squaredNorm() / static_cast<double>(std::max<long>(1, N)));

  std::vector<CandidateScore> out;
  for (const auto& [name, entries] : candidates) {
    CandidateScore s;
    s.name = name;
    s.entries = entries;
    s.dof = static_cast<int>(entries.size());
    s.rms_before = rms;
    s.predicted_rms = rms;
    const Eigen::MatrixXd PJ = project(columns(J, entries));
    // A candidate whose sensitivities lie in the span of the fitted ones (or are zero)
    // cannot be told apart from a change of the fitted parameters.
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> cq(PJ);
    const double scale = columns(J, entries).norm();
    if (cq.rank() < s.dof || !(PJ.norm() > 1e-8 * std::max(scale, 1e-300))) {
      s.error = fmt::format("{} moves the markers only as the fitted parameters do", name);
      out.push_back(s);
      continue;
    }
    const Eigen::VectorXd g = PJ.transpose() * Pr;
    const Eigen::VectorXd step = cq.solve(Pr);  // least squares: PJ step ≈ P r
    s.predicted_drop = g.dot(step);
    s.statistic = s.predicted_drop / sigma2;
    s.p_value = chi_square_survival(s.statistic, s.dof);
    s.predicted_rms =
        std::sqrt(std::max(0.0, r.squaredNorm() - s.predicted_drop) / static_cast<double>(N));
    out.push_back(s);
  }
  return out;
}

}  // namespace kelvin

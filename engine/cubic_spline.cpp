#include "engine/cubic_spline.hpp"

#include <Eigen/SparseLU>
#include <vector>

#include "base/error.hpp"

namespace kelvin {

Eigen::MatrixXd cubic_spline_slopes(const std::vector<double>& t,
                                    const Eigen::Ref<const Eigen::MatrixXd>& y, SplineEnds ends) {
  const int n = static_cast<int>(t.size());
  if (n < 2 || y.cols() != n)
    throw Error("cubic_spline_slopes: needs at least 2 knots, one per column");
  std::vector<double> h(n - 1);
  Eigen::MatrixXd delta(y.rows(), n - 1);  // secant slopes
  for (int k = 0; k + 1 < n; ++k) {
    h[k] = t[k + 1] - t[k];
    delta.col(k) = (y.col(k + 1) - y.col(k)) / h[k];
  }
  Eigen::MatrixXd m(y.rows(), n);
  if (n == 2) {
    m.col(0) = m.col(1) = delta.col(0);
    return m;
  }
  if (n == 3 && ends == SplineEnds::kNotAKnot) {
    // The parabola through the three knots (its end conditions coincide).
    const double c = (h[0] + h[1]);
    const Eigen::VectorXd curvature = (delta.col(1) - delta.col(0)) / c;  // half y''
    m.col(0) = delta.col(0) - curvature * h[0];
    m.col(1) = delta.col(0) + curvature * h[0];
    m.col(2) = delta.col(1) + curvature * h[1];
    return m;
  }
  // Continuity of the second derivative at every interior knot k:
  //   h_k m_{k−1} + 2(h_{k−1} + h_k) m_k + h_{k−1} m_{k+1} = 3(h_k δ_{k−1} + h_{k−1} δ_k),
  // closed by two end rows (de Boor, A Practical Guide to Splines, ch. IV). The
  // not-a-knot rows are not diagonally dominant, hence a pivoting LU.
  std::vector<Eigen::Triplet<double>> a;
  a.reserve(3 * n);
  Eigen::MatrixXd rhs(n, y.rows());
  for (int k = 1; k + 1 < n; ++k) {
    a.emplace_back(k, k - 1, h[k]);
    a.emplace_back(k, k, 2 * (h[k - 1] + h[k]));
    a.emplace_back(k, k + 1, h[k - 1]);
    rhs.row(k) = (3 * (h[k] * delta.col(k - 1) + h[k - 1] * delta.col(k))).transpose();
  }
  const int e = n - 2;  // last interval
  if (ends == SplineEnds::kNatural) {
    a.emplace_back(0, 0, 2);
    a.emplace_back(0, 1, 1);
    rhs.row(0) = 3 * delta.col(0).transpose();
    a.emplace_back(n - 1, n - 2, 1);
    a.emplace_back(n - 1, n - 1, 2);
    rhs.row(n - 1) = 3 * delta.col(e).transpose();
  } else {
    const double s0 = h[0] + h[1], s1 = h[e - 1] + h[e];
    a.emplace_back(0, 0, h[1]);
    a.emplace_back(0, 1, s0);
    rhs.row(0) =
        (((h[0] + 2 * s0) * h[1] * delta.col(0) + h[0] * h[0] * delta.col(1)) / s0).transpose();
    a.emplace_back(n - 1, n - 2, s1);
    a.emplace_back(n - 1, n - 1, h[e - 1]);
    rhs.row(n - 1) =
        ((h[e] * h[e] * delta.col(e - 1) + (2 * s1 + h[e]) * h[e - 1] * delta.col(e)) / s1)
            .transpose();
  }
  Eigen::SparseMatrix<double> A(n, n);
  A.setFromTriplets(a.begin(), a.end());
  Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::NaturalOrdering<int>> lu(A);
  if (lu.info() != Eigen::Success) throw Error("cubic_spline_slopes: singular spline system");
  m = lu.solve(rhs).transpose();
  return m;
}

std::array<double, 4> hermite_weights(double s, double h, int derivative) {
  const double s2 = s * s, s3 = s2 * s;
  switch (derivative) {
    case 0:
      return {2 * s3 - 3 * s2 + 1, h * (s3 - 2 * s2 + s), -2 * s3 + 3 * s2, h * (s3 - s2)};
    case 1:
      return {(6 * s2 - 6 * s) / h, 3 * s2 - 4 * s + 1, (6 * s - 6 * s2) / h, 3 * s2 - 2 * s};
    default:
      return {(12 * s - 6) / (h * h), (6 * s - 4) / h, (6 - 12 * s) / (h * h), (6 * s - 2) / h};
  }
}

}  // namespace kelvin

#include "materials/svd_utils.hpp"

#include <Eigen/LU>
#include <Eigen/SVD>

namespace kelvin {

SignedSvd signed_svd(const Mat3& F) {
  Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  SignedSvd s{svd.matrixU(), svd.matrixV(), svd.singularValues()};
  // Flipping a column of U (or V) together with σ₃ leaves U Σ Vᵀ unchanged; the
  // smallest value is the one whose sign change perturbs Ψ least.
  if (s.U.determinant() < 0) {
    s.U.col(2) *= -1;
    s.sigma[2] *= -1;
  }
  if (s.V.determinant() < 0) {
    s.V.col(2) *= -1;
    s.sigma[2] *= -1;
  }
  return s;
}

Mat3 principal_stress(const SignedSvd& svd, const Eigen::Vector3d& p) {
  return svd.U * p.asDiagonal() * svd.V.transpose();
}

Mat9 principal_tangent(const SignedSvd& svd, const Eigen::Vector3d& p, const Mat3& H,
                       const Eigen::Vector3d& divided) {
  // Tangent in the rotated frame, vec index i + 3 j for entry (i, j).
  Mat9 A = Mat9::Zero();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) A(4 * i, 4 * j) = H(i, j);
  for (int k = 0; k < 3; ++k) {
    const int i = kSvdPairs[k][0], j = kSvdPairs[k][1];
    const double s = (p[i] + p[j]) / (svd.sigma[i] + svd.sigma[j]);
    const double a = 0.5 * (divided[k] + s), b = 0.5 * (divided[k] - s);
    const int ij = i + 3 * j, ji = j + 3 * i;
    A(ij, ij) = A(ji, ji) = a;
    A(ij, ji) = A(ji, ij) = b;
  }
  // vec(U X Vᵀ) = (V ⊗ U) vec X, so dP/dF = K A Kᵀ with K = V ⊗ U.
  Mat9 K;
  for (int l = 0; l < 3; ++l)
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) K(i + 3 * j, k + 3 * l) = svd.V(j, l) * svd.U(i, k);
  return K * A * K.transpose();
}

}  // namespace kelvin

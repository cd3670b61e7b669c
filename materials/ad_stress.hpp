#pragma once
/// \file
/// Exact dP/dF and dP/dq of a closed-form stress P(F; q) by forward-mode automatic
/// differentiation (Eigen's AutoDiffScalar, as in power_law.cpp): one sweep over the
/// 9 entries of F and the NQ parameters. Models whose stress is a short formula but
/// whose hand-derived tangent would be long and error-prone (stable neo-Hookean,
/// Mooney–Rivlin, St Venant–Kirchhoff) share this instead of each deriving it.
#include <unsupported/Eigen/AutoDiff>

#include "materials/material.hpp"

namespace kelvin {

/// `stress` is a generic callable (F, q) → 3×3 matrix, templated on the scalar type
/// of F (double or AutoDiffScalar) with q an NQ-vector of the same scalar. Fills
/// kStress, kTangent, kParamDerivative and (zero, elastic) kRateTangent.
template <int NQ, class StressFn>
void ad_stress_response(const MaterialPoint& in, unsigned request, MaterialResponse& out,
                        StressFn&& stress) {
  if (request & kRateTangent) out.dPdFdot.setZero();
  if (!(request & (kTangent | kParamDerivative))) {
    if (request & kStress) {
      const Eigen::Matrix<double, NQ, 1> q = Eigen::Map<const Eigen::Matrix<double, NQ, 1>>(in.q);
      out.P = stress(in.F, q);
    }
    return;
  }
  constexpr int N = 9 + NQ;
  using Deriv = Eigen::Matrix<double, N, 1>;
  using AD = Eigen::AutoDiffScalar<Deriv>;
  Eigen::Matrix<AD, 3, 3> F;
  Eigen::Matrix<AD, NQ, 1> q;
  for (int k = 0; k < 9; ++k) F(k % 3, k / 3) = AD(in.F(k % 3, k / 3), N, k);
  for (int k = 0; k < NQ; ++k) q[k] = AD(in.q[k], N, 9 + k);
  const Eigen::Matrix<AD, 3, 3> P = stress(F, q);
  if (request & kParamDerivative) out.dPdq.resize(9, NQ);
  for (int a = 0; a < 9; ++a) {
    const AD& Pa = P(a % 3, a / 3);
    if (request & kStress) out.P(a % 3, a / 3) = Pa.value();
    if (request & kTangent) out.dPdF.row(a) = Pa.derivatives().template segment<9>(0).transpose();
    if (request & kParamDerivative)
      out.dPdq.row(a) = Pa.derivatives().template segment<NQ>(9).transpose();
  }
}

/// Cofactor matrix cof F = ∂(det F)/∂F, well defined for singular and inverted F.
template <class S>
Eigen::Matrix<S, 3, 3> cofactor(const Eigen::Matrix<S, 3, 3>& F) {
  Eigen::Matrix<S, 3, 3> C;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
      C(i, j) = F(i1, j1) * F(i2, j2) - F(i1, j2) * F(i2, j1);
    }
  return C;
}

}  // namespace kelvin

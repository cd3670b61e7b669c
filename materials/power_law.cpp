#include "materials/power_law.hpp"

#include <Eigen/LU>
#include <cfloat>
#include <cmath>

namespace kelvin {
namespace {

/// The kinematics every viscous stress and derivative below shares:
/// P = J c d F⁻ᵀ with L = Ḟ F⁻¹, d = L + Lᵀ, γ̇ = √(½ d:d), c = ν γ̇^(h−1).
struct Kinematics {
  Kinematics(const Mat3& F, const Mat3& Fdot, double nu, double h, bool power_law)
      : J(F.determinant()), FinvT(F.inverse().transpose()) {
    L = Fdot * FinvT.transpose();
    d = L + L.transpose();
    gamma = std::sqrt(0.5 * d.squaredNorm());
    // h ≡ 1 skips pow, so Newtonian viscosity stays exact and cheap.
    c = power_law ? nu * std::pow(gamma, h - 1) : nu;
    P = (J * c) * d * FinvT;
  }
  double J;
  Mat3 FinvT, L, d, P;
  double gamma = 0, c = 0;
};

/// P and, on request, its closed-form derivatives. With A = F⁻¹, M = d Aᵀ (so
/// P = J c M), S = A Aᵀ and w = (h−1)/γ̇², for the unit change of entry (i, j):
///   dP/dḞᵢⱼ = J c [wMᵢⱼ M + eᵢ Sⱼᵀ + aⱼ Aᵢᵀ],
///   dP/dFᵢⱼ = J c [(Aⱼᵢ − w (A d L)ⱼᵢ) M − Lᵢ Sⱼᵀ − aⱼ (A L)ᵢᵀ − Mⱼ Aᵢᵀ],
/// where Xᵢ is column i of X and aⱼ row j of A (from dL = dḞ A, dA = −A dF A,
/// dJ = J Aⱼᵢ and dc = c w d:dL). Each entry is a few outer products of 3-vectors:
/// these run for every element at every backward adjoint step.
bool evaluate_viscous(const MaterialPoint& in, unsigned request, MaterialResponse& out,
                      bool power_law) {
  const int nq = power_law ? 2 : 1;
  const double nu = in.q[0], h = power_law ? in.q[1] : 1.0;
  // One determinant and one inverse per call: this runs per element per residual.
  const Kinematics k(in.F, in.Fdot, nu, h, power_law);
  if (!(k.J > 0)) return false;
  if (request & kEnergy) out.energy = 0;
  if (!(k.L.norm() > DBL_MIN)) {
    // At rest the power law contributes nothing (DESIGN.md), including its derivatives.
    if (request & kStress) out.P.setZero();
    if (request & kTangent) out.dPdF.setZero();
    if (request & kRateTangent) out.dPdFdot.setZero();
    if (request & kParamDerivative) out.dPdq.setZero(9, nq);
    return true;
  }
  if (request & kStress) out.P = k.P;
  if (request & kParamDerivative) {
    out.dPdq.resize(9, nq);
    out.dPdq.col(0) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>((k.P / nu).eval().data());
    if (power_law)
      out.dPdq.col(1) =
          Eigen::Map<const Eigen::Matrix<double, 9, 1>>((k.P * std::log(k.gamma)).eval().data());
  }
  if (!(request & (kTangent | kRateTangent))) return true;
  const Mat3 A = k.FinvT.transpose();
  const Mat3 M = k.d * k.FinvT;
  const Mat3 S = A * A.transpose();
  const double Jc = k.J * k.c;
  const double w = power_law ? (h - 1) / (k.gamma * k.gamma) : 0.0;
  const Mat3 AL = A * k.L, Q = A * k.d * k.L;
  // Entry (k + 3l, i + 3j) of each 9×9 tangent, straight from the formulas above:
  // forming each column as a sum of 3×3 outer products cost 3× as much, and this
  // runs for every element at every backward step.
  const bool rate = request & kRateTangent, tangent = request & kTangent;
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) {
      const int col = i + 3 * j;
      const double wm = w * M(i, j), c0 = A(j, i) - w * Q(j, i);
      for (int l = 0; l < 3; ++l)
        for (int kk = 0; kk < 3; ++kk) {
          const int row = kk + 3 * l;
          if (rate)
            out.dPdFdot(row, col) =
                Jc * (wm * M(kk, l) + (kk == i ? S(l, j) : 0.0) + A(j, kk) * A(l, i));
          if (tangent)
            out.dPdF(row, col) = Jc * (c0 * M(kk, l) - k.L(kk, i) * S(l, j) - A(j, kk) * AL(l, i) -
                                       M(kk, j) * A(l, i));
        }
    }
  return true;
}

}  // namespace

const std::vector<ParamInfo>& PowerLawViscosity::params() const {
  static const std::vector<ParamInfo> p = {
      {"nu", "Pa s^h", "viscosity coefficient", 1.0, 0, 1e300, true},
      {"h", "1", "flow index (1 = Newtonian, < 1 shear-thinning)", 1.0, 0, 1e300, true},
  };
  return p;
}

bool PowerLawViscosity::evaluate(const MaterialPoint& in, unsigned request,
                                 MaterialResponse& out) const {
  return evaluate_viscous(in, request, out, true);
}

const std::vector<ParamInfo>& NewtonianViscosity::params() const {
  static const std::vector<ParamInfo> p = {
      {"nu", "Pa s", "dynamic viscosity", 1.0, 0, 1e300, true},
  };
  return p;
}

bool NewtonianViscosity::evaluate(const MaterialPoint& in, unsigned request,
                                  MaterialResponse& out) const {
  return evaluate_viscous(in, request, out, false);
}

}  // namespace kelvin

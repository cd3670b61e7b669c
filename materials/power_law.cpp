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
  /// dP for a change dL of the velocity gradient, dJ of J and dF⁻ᵀ of F⁻ᵀ.
  Mat3 differential(const Mat3& dL, double dJ, const Mat3& dFinvT, double h, bool power_law) const {
    const Mat3 dd = dL + dL.transpose();
    // dγ̇/γ̇ = d:dL / γ̇² (d symmetric), so dc = c (h−1) d:dL / γ̇².
    const double dc = power_law ? c * (h - 1) * d.cwiseProduct(dL).sum() / (gamma * gamma) : 0.0;
    return (dJ * c + J * dc) * d * FinvT + (J * c) * (dd * FinvT + d * dFinvT);
  }
  double J;
  Mat3 FinvT, L, d, P;
  double gamma = 0, c = 0;
};

/// P and, on request, its closed-form derivatives: one 3×3 differential per
/// entry of F and of Ḟ (a fraction of the cost of automatic differentiation,
/// and these run once per element per residual in every backward adjoint step).
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
  const Mat3 Finv = k.FinvT.transpose();
  for (int e = 0; e < 9; ++e) {
    Mat3 E = Mat3::Zero();
    E(e % 3, e / 3) = 1;
    if (request & kRateTangent) {
      const Mat3 dP = k.differential(E * Finv, 0, Mat3::Zero(), h, power_law);
      out.dPdFdot.col(e) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dP.data());
    }
    if (request & kTangent) {
      // dJ = J F⁻ᵀ:dF, dL = −L dF F⁻¹, dF⁻ᵀ = −F⁻ᵀ dFᵀ F⁻ᵀ.
      const Mat3 dP = k.differential(-k.L * E * Finv, k.J * k.FinvT(e % 3, e / 3),
                                     -k.FinvT * E.transpose() * k.FinvT, h, power_law);
      out.dPdF.col(e) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dP.data());
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

#include "materials/rayleigh.hpp"

namespace kelvin {
namespace {

using Vec9 = Eigen::Matrix<double, 9, 1>;

Vec9 vec(const Mat3& A) {
  return Eigen::Map<const Vec9>(A.data());
}
Mat3 mat(const Vec9& a) {
  return Eigen::Map<const Mat3>(a.data());
}

/// ∂P/∂F at rest of an isotropic solid with λ = μ = 1: C₀:ε = tr(ε) I + ε + εᵀ.
Mat9 unit_isotropic_tangent() {
  Mat9 C = Mat9::Zero();
  for (int b = 0; b < 9; ++b) {
    Mat3 E = Mat3::Zero();
    E(b % 3, b / 3) = 1;
    C.col(b) = vec(E.trace() * Mat3::Identity() + E + E.transpose());
  }
  return C;
}

}  // namespace

const std::vector<ParamInfo>& RayleighDamping::params() const {
  static const std::vector<ParamInfo> p = {
      {"alpha0", "1/s", "mass-proportional coefficient (damps slow modes)", 0.0, 0, 1e300, false},
      {"alpha1", "s", "stiffness-proportional coefficient (damps fast modes)", 0.0, 0, 1e300,
       false},
  };
  return p;
}

bool RayleighDamping::evaluate(const MaterialPoint& in, unsigned request,
                               MaterialResponse& out) const {
  static const Mat9 fallback = unit_isotropic_tangent();
  const Mat9& C0 = in.rest_tangent ? *in.rest_tangent : fallback;
  const double a1 = in.q[1];
  const Mat3& F = in.F;
  const Mat3 FtFd = F.transpose() * in.Fdot;
  const Mat3 S = mat(C0 * vec(0.5 * (FtFd + FtFd.transpose())));  // C₀:Ė, per unit α₁
  if (request & kEnergy) out.energy = 0;
  if (request & kStress) out.P = a1 * F * S;
  if (request & kParamDerivative) {
    out.dPdq.resize(9, 2);
    out.dPdq.col(0).setZero();
    out.dPdq.col(1) = vec(F * S);
  }
  if (request & (kTangent | kRateTangent)) {
    for (int b = 0; b < 9; ++b) {
      Mat3 E = Mat3::Zero();
      E(b % 3, b / 3) = 1;
      if (request & kTangent) {
        const Mat3 dEdot = E.transpose() * in.Fdot;
        const Mat3 dS = mat(C0 * vec(0.5 * (dEdot + dEdot.transpose())));
        out.dPdF.col(b) = a1 * vec(E * S + F * dS);
      }
      if (request & kRateTangent) {
        const Mat3 dEdot = F.transpose() * E;
        out.dPdFdot.col(b) = a1 * vec(F * mat(C0 * vec(0.5 * (dEdot + dEdot.transpose()))));
      }
    }
  }
  return true;
}

}  // namespace kelvin
